"""Angle conventions and conversions between the paper's frame and the project's (MAVLink) frame.

The project works in a local east/north frame (metres) about a mission origin. Courses follow
MAVLink: radians clockwise from north. The paper's angles (psi, theta) are counter-clockwise from
east (x = east, y = north). A *polar angle* (the paper's theta, eq. 1) is the bearing of the vehicle
seen from the target, counter-clockwise from east; it is what phase keeping works on.
"""

import math

TAU = 2.0 * math.pi


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % TAU - math.pi


def wrap_2pi(angle_rad: float) -> float:
    """Wrap an angle to [0, 2 pi)."""
    return angle_rad % TAU


def course_from_paper_angle(psi_rad: float) -> float:
    """Course (clockwise from north) from the paper's heading psi (counter-clockwise from east)."""
    return wrap_pi(0.5 * math.pi - psi_rad)


def paper_angle_from_course(course_rad: float) -> float:
    """The paper's heading psi (CCW from east) from a course (clockwise from north)."""
    return wrap_pi(0.5 * math.pi - course_rad)


def course_from_velocity(v_east_m_s: float, v_north_m_s: float) -> float:
    """Course of a velocity vector, radians clockwise from north, in [-pi, pi]."""
    return math.atan2(v_east_m_s, v_north_m_s)


def velocity_from_course(course_rad: float, speed_m_s: float) -> tuple[float, float]:
    """(v_east, v_north) in m/s of a course (clockwise from north) flown at ``speed_m_s``."""
    return speed_m_s * math.sin(course_rad), speed_m_s * math.cos(course_rad)


def polar_angle(east_m: float, north_m: float) -> float:
    """The paper's theta (eq. 1): bearing of a point seen from the origin, CCW from east."""
    return math.atan2(north_m, east_m)
