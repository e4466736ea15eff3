"""The vehicle model: the point-mass fixed-wing of the paper's eq. (2) and its envelope (Table 1).

One model for the simulator, the agent's prediction of its own motion and the guidance's
prediction of the closed loop. Course is in radians clockwise from north (MAVLink); position in
metres east/north. Pure: ``step`` returns a new state and never reads a clock.
"""

import math
from dataclasses import dataclass

from app.core.frames import wrap_pi


def require_positive(owner: str, **values: float) -> None:
    """Raise ``ValueError`` naming the first value that is not finite and > 0."""
    for name, value in values.items():
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{owner}.{name} must be finite and > 0, got {value!r}")


@dataclass(frozen=True, slots=True)
class VehicleEnvelope:
    """The vehicle's envelope (Table 1) and its autopilot's inner loops: speeds m/s,
    acceleration m/s^2, course rate rad/s.

    ``course_gain_per_s`` is k of eq. (2) (1/s): course rate = k (desired - actual), saturated
    at ``max_course_rate_rad_s``; the guidance's lag compensation assumes it.
    ``speed_gain_per_s`` is the speed loop: acceleration = speed_gain (desired - actual),
    saturated at ``max_accel_m_s2``. ``cruise_speed_m_s`` is what the guidance flies without
    phase keeping.
    """

    cruise_speed_m_s: float
    min_speed_m_s: float
    max_speed_m_s: float
    max_accel_m_s2: float
    max_course_rate_rad_s: float
    course_gain_per_s: float = 1.0
    speed_gain_per_s: float = 1.0

    def __post_init__(self) -> None:
        require_positive(
            "VehicleEnvelope",
            speed_gain_per_s=self.speed_gain_per_s,
            cruise_speed_m_s=self.cruise_speed_m_s,
            min_speed_m_s=self.min_speed_m_s,
            max_speed_m_s=self.max_speed_m_s,
            max_accel_m_s2=self.max_accel_m_s2,
            max_course_rate_rad_s=self.max_course_rate_rad_s,
            course_gain_per_s=self.course_gain_per_s,
        )
        if not self.min_speed_m_s <= self.cruise_speed_m_s <= self.max_speed_m_s:
            raise ValueError(
                "VehicleEnvelope needs min_speed_m_s <= cruise_speed_m_s <= max_speed_m_s, got "
                f"{self.min_speed_m_s}, {self.cruise_speed_m_s}, {self.max_speed_m_s}"
            )

    def clamp_speed(self, speed_m_s: float) -> float:
        """The speed within [min_speed_m_s, max_speed_m_s]."""
        return min(max(speed_m_s, self.min_speed_m_s), self.max_speed_m_s)


@dataclass(frozen=True, slots=True)
class FixedWingState:
    """Kinematic state; ``course_rate_rad_s`` and ``accel_m_s2`` are those of the last step."""

    east_m: float
    north_m: float
    course_rad: float
    speed_m_s: float
    course_rate_rad_s: float = 0.0
    accel_m_s2: float = 0.0

    @property
    def v_east_m_s(self) -> float:
        return self.speed_m_s * math.sin(self.course_rad)

    @property
    def v_north_m_s(self) -> float:
        return self.speed_m_s * math.cos(self.course_rad)


def step(
    state: FixedWingState,
    course_cmd_rad: float,
    speed_cmd_m_s: float,
    envelope: VehicleEnvelope,
    dt_s: float,
    wind_east_m_s: float = 0.0,
    wind_north_m_s: float = 0.0,
    hold_envelope: bool = True,
    exact_arc: bool = True,
) -> FixedWingState:
    """Advance eq. (2) by ``dt_s`` under a (course, speed) command.

    The course rate k * wrap(course_cmd - course) is saturated at the course-rate limit and held
    over the step; position integrates the resulting arc exactly (with the step's mean speed),
    or with ``exact_arc=False`` along the chord at the mid-step course (the midpoint rule, which
    the guidance's coarse 0.1 s prediction of the closed loop uses).
    The speed command is clamped to the speed limits and approached at most at the acceleration
    limit, never past it. With ``hold_envelope`` the speed is also kept within the limits
    (physics: the airframe cannot fly outside them); without it a speed that starts outside them
    (a measured ground speed, for a prediction) approaches the command from there. With wind,
    ``course_rad`` is the heading through the air and the ground track drifts with the wind.

    Raises ``ValueError`` on a non-finite command or a non-positive step.
    """
    if not (math.isfinite(course_cmd_rad) and math.isfinite(speed_cmd_m_s)):
        raise ValueError(f"non-finite command: course {course_cmd_rad!r}, speed {speed_cmd_m_s!r}")
    if not (dt_s > 0.0 and math.isfinite(dt_s)):
        raise ValueError(f"dt_s must be finite and > 0, got {dt_s!r}")
    return FixedWingState(
        *advance(
            state.east_m,
            state.north_m,
            state.course_rad,
            state.speed_m_s,
            course_cmd_rad,
            speed_cmd_m_s,
            envelope,
            dt_s,
            wind_east_m_s,
            wind_north_m_s,
            hold_envelope,
            exact_arc,
        )
    )


def advance(
    east_m: float,
    north_m: float,
    course_rad: float,
    speed_m_s: float,
    course_cmd_rad: float,
    speed_cmd_m_s: float,
    envelope: VehicleEnvelope,
    dt_s: float,
    wind_east_m_s: float = 0.0,
    wind_north_m_s: float = 0.0,
    hold_envelope: bool = True,
    exact_arc: bool = True,
) -> tuple[float, float, float, float, float, float]:
    """``step`` on plain floats, unchecked, for inner loops that validated their inputs once
    (the guidance's prediction of the closed loop runs it hundreds of times per check): returns
    (east m, north m, course rad, speed m/s, course rate rad/s, acceleration m/s^2)."""
    max_rate = envelope.max_course_rate_rad_s
    rate = envelope.course_gain_per_s * wrap_pi(course_cmd_rad - course_rad)
    rate = min(max(rate, -max_rate), max_rate)
    target_speed = envelope.clamp_speed(speed_cmd_m_s)
    max_accel = envelope.max_accel_m_s2
    accel = envelope.speed_gain_per_s * (target_speed - speed_m_s)
    accel = min(max(accel, -max_accel), max_accel)
    speed = speed_m_s + accel * dt_s
    speed = min(speed, target_speed) if accel > 0.0 else max(speed, target_speed)
    if hold_envelope:
        speed = envelope.clamp_speed(speed)
    accel = (speed - speed_m_s) / dt_s
    mean_speed = 0.5 * (speed_m_s + speed)
    course1 = course_rad + rate * dt_s
    turn = rate * dt_s
    if exact_arc and abs(turn) > 1e-9:
        # exact arc: integral of (sin, cos)(course0 + rate t) over the step
        d_east = mean_speed * (math.cos(course_rad) - math.cos(course1)) / rate
        d_north = mean_speed * (math.sin(course1) - math.sin(course_rad)) / rate
    else:
        mid = course_rad + 0.5 * turn
        d_east = mean_speed * math.sin(mid) * dt_s
        d_north = mean_speed * math.cos(mid) * dt_s
    return (
        east_m + d_east + wind_east_m_s * dt_s,
        north_m + d_north + wind_north_m_s * dt_s,
        wrap_pi(course1),
        speed,
        rate,
        accel,
    )


def heading_for_ground_course(
    course_rad: float, airspeed_m_s: float, wind_east_m_s: float, wind_north_m_s: float
) -> float:
    """The heading through the air whose ground track is ``course_rad`` in the wind.

    The wind's component across the course is cancelled: sin(heading - course) = -w_cross / V.
    A cross wind the airspeed cannot cancel (|w_cross| >= V) is turned into as far as it can be
    (90 degrees), the best the aircraft can do.
    """
    if airspeed_m_s <= 0.0:
        return course_rad
    right_e, right_n = math.cos(course_rad), -math.sin(course_rad)  # unit vector to the right
    cross = wind_east_m_s * right_e + wind_north_m_s * right_n
    ratio = max(-1.0, min(1.0, -cross / airspeed_m_s))
    return wrap_pi(course_rad + math.asin(ratio))
