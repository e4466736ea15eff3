import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from app.core.plant import FixedWingState, VehicleEnvelope, step

LIMITS = VehicleEnvelope(
    cruise_speed_m_s=20.0,
    min_speed_m_s=13.0,
    max_speed_m_s=25.0,
    max_accel_m_s2=2.0,
    max_course_rate_rad_s=0.2,
)


def test_straight_flight_moves_along_course():
    state = FixedWingState(east_m=0.0, north_m=0.0, course_rad=math.pi / 2, speed_m_s=20.0)
    for _ in range(100):
        state = step(state, math.pi / 2, 20.0, LIMITS, 0.01)
    assert math.isclose(state.east_m, 20.0, rel_tol=1e-9)
    assert math.isclose(state.north_m, 0.0, abs_tol=1e-9)


def test_saturated_turn_flies_the_minimum_radius_circle():
    state = FixedWingState(east_m=0.0, north_m=0.0, course_rad=0.0, speed_m_s=20.0)
    # commanding a course just under pi to the right saturates the turn at 0.2 rad/s
    period = 2.0 * math.pi / 0.2
    steps = round(period / 0.01)
    max_east = 0.0
    for _ in range(steps):
        state = step(state, state.course_rad + 3.0, 20.0, LIMITS, 0.01)
        assert state.course_rate_rad_s == pytest.approx(0.2)
        max_east = max(max_east, state.east_m)
    # a circle of radius s / rate = 100 m about (100, 0), clockwise (to the east first)
    assert max_east == pytest.approx(200.0, rel=1e-4)
    swept = 0.2 * steps * 0.01
    assert state.east_m == pytest.approx(100.0 - 100.0 * math.cos(swept), abs=1e-6)
    assert state.north_m == pytest.approx(100.0 * math.sin(swept), abs=1e-6)


def test_eq2_proportional_course_response():
    state = FixedWingState(east_m=0.0, north_m=0.0, course_rad=0.0, speed_m_s=20.0)
    state = step(state, 0.1, 20.0, LIMITS, 0.01)
    assert state.course_rate_rad_s == pytest.approx(0.1)  # k = 1, below the limit


@given(
    st.floats(min_value=-50.0, max_value=50.0),
    st.floats(min_value=-100.0, max_value=100.0),
    st.floats(min_value=13.0, max_value=25.0),
)
def test_limits_always_hold(course_cmd, speed_cmd, speed0):
    state = FixedWingState(east_m=0.0, north_m=0.0, course_rad=0.3, speed_m_s=speed0)
    for _ in range(20):
        new = step(state, course_cmd, speed_cmd, LIMITS, 0.05)
        assert abs(new.course_rate_rad_s) <= 0.2 + 1e-12
        assert 13.0 <= new.speed_m_s <= 25.0
        assert abs(new.speed_m_s - state.speed_m_s) <= 2.0 * 0.05 + 1e-12
        state = new


def test_bad_commands_are_refused():
    state = FixedWingState(east_m=0.0, north_m=0.0, course_rad=0.0, speed_m_s=20.0)
    with pytest.raises(ValueError, match="non-finite"):
        step(state, math.nan, 20.0, LIMITS, 0.01)
    with pytest.raises(ValueError, match="dt_s"):
        step(state, 0.0, 20.0, LIMITS, 0.0)
    with pytest.raises(ValueError, match="min_speed_m_s"):
        VehicleEnvelope(
            cruise_speed_m_s=28.0,
            min_speed_m_s=30.0,
            max_speed_m_s=25.0,
            max_accel_m_s2=2.0,
            max_course_rate_rad_s=0.2,
        )
