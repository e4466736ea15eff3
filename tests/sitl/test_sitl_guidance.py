"""The simulated autopilot's guidance: closed-form cases, the singular centre, and convergence
onto the loiter circle from anywhere (property)."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.core.frames import wrap_pi
from app.core.plant import FixedWingState, step
from sitl.config import default_limits
from sitl.guidance import (
    LINE_LOOKAHEAD_M,
    LineCommand,
    LoiterCommand,
    VelocityCommand,
    guide,
)

GAIN = 1.0


def _state(east, north, course=0.0, speed=18.0):
    return FixedWingState(east_m=east, north_m=north, course_rad=course, speed_m_s=speed)


def test_velocity_is_flown_as_given():
    assert guide(_state(5, 5), VelocityCommand(1.0, 20.0), GAIN) == (1.0, 20.0)


def test_line_on_it_and_beside_it():
    line = LineCommand(east_m=100.0, north_m=0.0, course_rad=0.0, speed_m_s=16.0)  # due north
    assert guide(_state(100.0, 50.0), line, GAIN) == (0.0, 16.0)
    course, _ = guide(_state(100.0 + LINE_LOOKAHEAD_M, 0.0), line, GAIN)  # right of it
    assert course == pytest.approx(-math.pi / 4)


@pytest.mark.parametrize("clockwise", [True, False])
def test_loiter_on_the_circle_flies_the_tangent_with_the_turn_rate_fed_forward(clockwise):
    radius = 150.0
    loiter = LoiterCommand(0.0, 0.0, radius, clockwise, 18.0)
    bearing = math.radians(30.0)
    state = _state(radius * math.sin(bearing), radius * math.cos(bearing))
    course, speed = guide(state, loiter, GAIN)
    sense = 1.0 if clockwise else -1.0
    tangent = bearing + sense * math.pi / 2
    assert wrap_pi(course - tangent) == pytest.approx(sense * 18.0 / radius / GAIN)
    assert speed == 18.0


def test_loiter_far_away_heads_for_the_centre_and_the_centre_is_handled():
    loiter = LoiterCommand(0.0, 0.0, 150.0, True, 18.0)
    course, _ = guide(_state(0.0, 100_000.0), loiter, GAIN)  # far north
    assert abs(wrap_pi(course - math.pi)) < 0.01  # fly south, toward it
    assert guide(_state(0.0, 0.0, course=1.2), loiter, GAIN) == (1.2, 18.0)  # r -> 0


@settings(max_examples=12, deadline=None)
@given(
    east=st.floats(-2000, 2000),
    north=st.floats(-2000, 2000),
    course=st.floats(-math.pi, math.pi),
    clockwise=st.booleans(),
)
def test_loiter_converges_onto_the_circle_from_anywhere(east, north, course, clockwise):
    limits = default_limits()
    radius = 135.0
    loiter = LoiterCommand(100.0, -50.0, radius, clockwise, 18.0)
    state = _state(east, north, course)
    for _ in range(int(400.0 / 0.05)):
        state = step(state, *guide(state, loiter, GAIN), limits, 0.05)
    worst = 0.0
    for _ in range(int(60.0 / 0.05)):
        state = step(state, *guide(state, loiter, GAIN), limits, 0.05)
        d = math.hypot(state.east_m - 100.0, state.north_m + 50.0)
        worst = max(worst, abs(d - radius))
    assert worst < 1.0
    # and it circulates the way it was asked to
    assert math.copysign(1.0, state.course_rate_rad_s) == (1.0 if clockwise else -1.0)
