"""The best steady orbit of benchmarks/bench_steady_orbit.py: it keeps the airframe's limits,
closes, holds the circle where the circle can be flown, and does no better with less turn rate."""

import math

import numpy as np
import pytest

from app.config import load_config
from app.config.mission import MissionConfig
from app.config.schema import WaypointTargetConfig
from benchmarks.bench_steady_orbit import steady_optimum, straight_leg

LIMITS = (10.0, 18.0, 2.0, 0.2)  # speed band, acceleration, course rate (Table 2)


def test_around_a_slow_target_the_team_holds_the_circle_evenly_spaced():
    # at 3 m/s the circle needs (10 + 3)^2 / (90 * 10) = 0.188 rad/s against the target: flyable
    orbit = steady_optimum(90.0, 3.0, 3, *LIMITS)
    assert orbit is not None
    assert orbit.dist_rms_m < 0.5
    assert orbit.spacing_rms_deg < 0.5


@pytest.fixture(scope="module")
def fast_orbits():
    return {
        share: steady_optimum(90.0, 7.0, 3, 10.0, 18.0, 2.0, share * 0.2) for share in (1.0, 0.9)
    }


def test_around_a_fast_target_the_flight_closes_within_the_limits(fast_orbits):
    orbit = fast_orbits[1.0]
    assert orbit is not None
    assert orbit.speeds.min() >= 10.0 - 1e-3
    assert orbit.speeds.max() <= 18.0 + 1e-3
    assert np.abs(orbit.rates).max() <= 0.2 + 1e-9
    # it goes round the target once, counter-clockwise, never back
    polar = np.unwrap(np.arctan2(orbit.path[:, 1], orbit.path[:, 0]))
    assert np.all(np.diff(polar) > 0.0)
    assert polar[-1] - polar[0] == pytest.approx(2.0 * math.pi, abs=0.3)
    # at 7 m/s the circle cannot be flown: (10 + 7)^2 / (90 * 10) = 0.32 rad/s against it
    assert orbit.dist_rms_m > 5.0


def test_less_turn_rate_never_flies_a_better_orbit(fast_orbits):
    full, reserved = fast_orbits[1.0], fast_orbits[0.9]
    assert full is not None
    assert reserved is not None
    assert reserved.cost > full.cost
    assert np.abs(reserved.rates).max() <= 0.9 * 0.2 + 1e-9


def test_the_straight_leg_replaces_the_target_with_one_leg_at_the_speed():
    config = load_config("hil", MissionConfig)
    leg = straight_leg(config, 6.0, 300.0)
    assert isinstance(leg.target, WaypointTargetConfig)
    assert len(leg.target.legs) == 1
    (only,) = leg.target.legs
    assert only.speed_m_s == 6.0
    assert only.to_north_m - leg.target.start_north_m == pytest.approx(1800.0)
