import math

from hypothesis import given
from hypothesis import strategies as st

from app.core import frames

angles = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False)


@given(angles)
def test_wrap_pi_is_in_range_and_equivalent(angle):
    wrapped = frames.wrap_pi(angle)
    assert -math.pi <= wrapped < math.pi
    assert math.isclose(math.sin(wrapped), math.sin(angle), abs_tol=1e-9)
    assert math.isclose(math.cos(wrapped), math.cos(angle), abs_tol=1e-9)


def test_paper_frame_examples_from_design():
    # Simulation B: psi = 1.5 pi (counter-clockwise from east) is due south
    assert math.isclose(frames.course_from_paper_angle(1.5 * math.pi), -math.pi, abs_tol=1e-12)
    # Simulation A: psi = 1.25 pi is south-west: course 225 degrees clockwise from north
    course = frames.course_from_paper_angle(1.25 * math.pi)
    assert math.isclose(frames.wrap_2pi(course), math.radians(225.0), abs_tol=1e-12)
    v_east, v_north = frames.velocity_from_course(course, 18.0)
    assert v_east < 0.0
    assert v_north < 0.0


@given(angles)
def test_paper_angle_round_trip(psi):
    back = frames.paper_angle_from_course(frames.course_from_paper_angle(psi))
    assert math.isclose(frames.wrap_pi(back - psi), 0.0, abs_tol=1e-9)


@given(angles, st.floats(min_value=0.1, max_value=100.0))
def test_course_velocity_round_trip(course, speed):
    v_east, v_north = frames.velocity_from_course(course, speed)
    assert math.isclose(math.hypot(v_east, v_north), speed, rel_tol=1e-12)
    back = frames.course_from_velocity(v_east, v_north)
    assert abs(frames.wrap_pi(back - course)) < 1e-9


def test_polar_angle_is_counter_clockwise_from_east():
    assert frames.polar_angle(1.0, 0.0) == 0.0
    assert math.isclose(frames.polar_angle(0.0, 1.0), math.pi / 2)
