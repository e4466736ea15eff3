"""The wind from ground velocity and airspeed (``guidance.wind``), on synthetic orbits."""

import math

import numpy as np
import pytest

from app.core.guidance import wind

PARAMS = wind.WindParams()


def orbit(state, wind_e, wind_n, seconds, rate=0.15, airspeed=14.0, t0=0.0, rng=None, noise=0.0):
    """Frames of an aircraft turning at ``rate`` rad/s at ``airspeed`` in the wind, 10 Hz."""
    t = t0
    for k in range(round(seconds * 10)):
        t = t0 + 0.1 * (k + 1)
        heading = rate * t
        g_e = airspeed * math.sin(heading) + wind_e
        g_n = airspeed * math.cos(heading) + wind_n
        a = airspeed
        if rng is not None:
            g_e, g_n, a = (
                g_e + rng.normal(0, noise),
                g_n + rng.normal(0, noise),
                a + rng.normal(0, noise),
            )
        state = wind.update(state, t, g_e, g_n, a, PARAMS)
    return state, t


@pytest.mark.parametrize(("wind_e", "wind_n"), [(3.0, 0.0), (-2.0, 2.0), (0.0, 0.0), (5.0, -4.0)])
def test_an_orbit_gives_the_wind(wind_e, wind_n):
    state, _ = orbit(wind.WindState(), wind_e, wind_n, 30.0)
    est = state.estimate(PARAMS)
    assert est is not None
    assert est == pytest.approx((wind_e, wind_n), abs=1e-6)


def test_noisy_frames_give_it_within_a_few_tenths():
    rng = np.random.default_rng(3)
    state, _ = orbit(wind.WindState(), 3.0, -1.0, 60.0, rng=rng, noise=0.3)
    est = state.estimate(PARAMS)
    assert est is not None
    assert math.hypot(est[0] - 3.0, est[1] + 1.0) < 0.3


def test_a_straight_line_does_not_determine_it():
    state = wind.WindState()
    for k in range(300):
        state = wind.update(state, 0.1 * (k + 1), 3.0, 14.0, 14.0, PARAMS)
    assert state.estimate(PARAMS) is None
    # a few degrees of turn neither: the fit waits for the course to spread
    state, _ = orbit(wind.WindState(), 3.0, 0.0, 2.0, rate=0.05)
    assert state.estimate(PARAMS) is None


def test_it_follows_a_change_of_wind_within_its_memory():
    state, t = orbit(wind.WindState(), 3.0, 0.0, 60.0)
    state, _ = orbit(state, 0.0, 3.0, 120.0, t0=t)
    est = state.estimate(PARAMS)
    assert est is not None
    assert math.hypot(est[0], est[1] - 3.0) < 0.2


def test_bad_frames_are_left_out():
    state, t = orbit(wind.WindState(), 3.0, 0.0, 30.0)
    before = state.estimate(PARAMS)
    bad = [(t + 1, math.nan, 1.0, 14.0), (t + 1, 1.0, 1.0, None), (t + 1, 1.0, 1.0, -3.0)]
    bad.append((t - 5, 1.0, 1.0, 14.0))  # older than the newest frame
    for at, east, north, air in bad:
        assert wind.update(state, at, east, north, air, PARAMS) is state
    assert state.estimate(PARAMS) == before


def test_an_absurd_fit_is_not_believed():
    state = wind.WindState()
    for k in range(300):  # airspeed 40 m/s under a 14 m/s ground speed: a 26+ m/s "wind"
        h = 0.2 * k * 0.1
        state = wind.update(state, 0.1 * (k + 1), 14 * math.sin(h), 14 * math.cos(h), 40.0, PARAMS)
    assert state.estimate(PARAMS) is None


def test_the_airspeed_for_a_ground_velocity_is_held_to_the_limits():
    # 14 m/s north over the ground in 3 m/s from the north (blowing south): 17 m/s through the air
    assert wind.airspeed_for(0.0, 14.0, (0.0, -3.0), 10.0, 18.0) == pytest.approx(17.0)
    assert wind.airspeed_for(0.0, 14.0, (0.0, 3.0), 10.0, 18.0) == pytest.approx(11.0)
    assert wind.airspeed_for(0.0, 17.0, (0.0, -3.0), 10.0, 18.0) == 18.0
    assert wind.airspeed_for(0.0, 10.0, (0.0, 3.0), 10.0, 18.0) == 10.0
    # a cross wind: the air velocity is the hypotenuse
    assert wind.airspeed_for(0.0, 12.0, (5.0, 0.0), 10.0, 18.0) == pytest.approx(13.0)
