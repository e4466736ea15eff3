"""Guidance of the simulated autopilot: what (course, speed) flies a velocity, loiter or line.

Pure functions of the vehicle state; courses in radians clockwise from north, positions in
metres east/north of the simulator's origin.
"""

import math
from dataclasses import dataclass
from typing import Final

from app.core.plant import FixedWingState

LINE_LOOKAHEAD_M: Final = 50.0


@dataclass(frozen=True, slots=True)
class VelocityCommand:
    """Fly a course at a speed (offboard velocity setpoint)."""

    course_rad: float
    speed_m_s: float


@dataclass(frozen=True, slots=True)
class LoiterCommand:
    """Fly to a point and circle it (hold, return, a position setpoint)."""

    center_east_m: float
    center_north_m: float
    radius_m: float
    clockwise: bool
    speed_m_s: float


@dataclass(frozen=True, slots=True)
class LineCommand:
    """Fly the line through a point along a course (position + velocity setpoint, as PX4 does),
    with a path curvature fed forward (1/m, > 0 turning clockwise; PX4's offboard acceleration).
    """

    east_m: float
    north_m: float
    course_rad: float
    speed_m_s: float
    curvature_per_m: float = 0.0


@dataclass(frozen=True, slots=True)
class CourseCommand:
    """Fly a course over ground at an airspeed, turning with at most a lateral acceleration
    (ArduPlane GUIDED after MAV_CMD_GUIDED_CHANGE_HEADING). ``guide`` returns the course as
    given; the vehicle turns it into the heading that holds it in the wind."""

    course_rad: float
    speed_m_s: float
    max_lateral_accel_m_s2: float


Command = VelocityCommand | LoiterCommand | LineCommand | CourseCommand


def guide(state: FixedWingState, cmd: Command, course_gain_per_s: float) -> tuple[float, float]:
    """The (course, speed) command that flies ``cmd`` from ``state``.

    Loiter: a circulating vector field (course to the tangent, bent toward the circle by
    atan(d / R), d the distance off the circle), plus the circle's own turn rate fed forward
    through the course loop's gain so the P loop of eq. (2) settles on the circle, not off it.
    At the centre (r -> 0) the bearing is undefined: fly the current course outward.
    Line: the course to the line through a look-ahead point, plus the path's curvature as the
    turn rate V * curvature, fed forward the same way.
    """
    if isinstance(cmd, VelocityCommand | CourseCommand):
        return cmd.course_rad, cmd.speed_m_s
    if isinstance(cmd, LineCommand):
        right_e, right_n = math.cos(cmd.course_rad), -math.sin(cmd.course_rad)
        cross_m = (state.east_m - cmd.east_m) * right_e + (state.north_m - cmd.north_m) * right_n
        course = cmd.course_rad - math.atan(cross_m / LINE_LOOKAHEAD_M)
        feed_forward = state.speed_m_s * cmd.curvature_per_m / course_gain_per_s
        return course + feed_forward, cmd.speed_m_s
    d_east = state.east_m - cmd.center_east_m
    d_north = state.north_m - cmd.center_north_m
    r = math.hypot(d_east, d_north)
    if r < 1e-3:
        return state.course_rad, cmd.speed_m_s
    sense = 1.0 if cmd.clockwise else -1.0
    bearing = math.atan2(d_east, d_north)  # from the centre to the vehicle, clockwise from north
    off = (r - cmd.radius_m) / cmd.radius_m
    course = bearing + sense * (0.5 * math.pi + math.atan(2.0 * off))
    feed_forward = sense * (state.speed_m_s / cmd.radius_m) * max(0.0, 1.0 - abs(off))
    return course + feed_forward / course_gain_per_s, cmd.speed_m_s
