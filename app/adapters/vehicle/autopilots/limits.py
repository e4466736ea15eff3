"""What every outgoing setpoint is held to (the vehicle's envelope and the setpoint-only
limits), and the limiter that holds it there."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Final, Literal

from app.core.frames import wrap_pi
from app.core.plant import VehicleEnvelope, require_positive
from app.runtime.ports.vehicle import CourseSpeedCommand


@dataclass(frozen=True, slots=True)
class SetpointLimits:
    """What every outgoing setpoint is held to: the vehicle's ``envelope`` (Table 2: 10..18 m/s,
    2 m/s^2, 0.2 rad/s) and what only setpoints need.

    ``limit_course_change``: the *commanded* course turns no faster than the envelope's course
    rate between two setpoints (vehicle time); False leaves the course unconstrained.
    ``max_climb_rate_m_s`` and ``altitude_gain_per_s``: the climb rate commanded towards the
    altitude, gain * error saturated at the maximum.
    """

    envelope: VehicleEnvelope
    limit_course_change: bool = True
    max_climb_rate_m_s: float = 3.0
    altitude_gain_per_s: float = 0.5

    def __post_init__(self) -> None:
        require_positive(
            "SetpointLimits",
            max_climb_rate_m_s=self.max_climb_rate_m_s,
            altitude_gain_per_s=self.altitude_gain_per_s,
        )

    @property
    def max_course_change_rad_s(self) -> float | None:
        """How fast the commanded course may turn (rad/s); None: unconstrained."""
        return self.envelope.max_course_rate_rad_s if self.limit_course_change else None


@dataclass(frozen=True, slots=True)
class SentSetpoint:
    """The last setpoint that left, with the vehicle time it left at."""

    t_s: float
    course_rad: float
    speed_m_s: float


COURSE_TOLERANCE_RAD: Final = 1e-9

LimitKind = Literal["speed_below_min", "speed_above_max", "course_rate", "course_rate_feed_forward"]


@dataclass(frozen=True, slots=True)
class Limited:
    """Why a setpoint was changed before it left: ``kind`` for counting, ``detail`` for logs."""

    kind: LimitKind
    detail: str

    def __str__(self) -> str:
        return self.detail


def limit_setpoint(
    command: CourseSpeedCommand,
    t_s: float,
    previous: SentSetpoint | None,
    limits: SetpointLimits,
) -> tuple[CourseSpeedCommand, tuple[Limited, ...]]:
    """The command brought within the limits, and why it had to be (empty when it was not).

    Speed is clamped into [min, max]. When a previous setpoint is known, the course moves
    towards the requested one by at most ``max_course_change_rad_s * (t_s - previous.t_s)``
    (the shorter way round); time running backwards counts as no time. The course rate to feed
    forward (``course_rate_rad_s``) is held within the envelope's +-max course rate, whatever
    ``limit_course_change`` says: no vehicle turns faster, and it becomes a curvature or a bank.
    """
    reasons: list[Limited] = []
    envelope = limits.envelope
    speed = command.speed_m_s
    if speed < envelope.min_speed_m_s:
        reasons.append(
            Limited("speed_below_min", f"speed {speed:.3f} m/s below {envelope.min_speed_m_s} m/s")
        )
        speed = envelope.min_speed_m_s
    elif speed > envelope.max_speed_m_s:
        reasons.append(
            Limited("speed_above_max", f"speed {speed:.3f} m/s above {envelope.max_speed_m_s} m/s")
        )
        speed = envelope.max_speed_m_s
    course = command.course_rad
    if not -math.pi <= course < math.pi:
        course = wrap_pi(course)
    rate = limits.max_course_change_rad_s
    if previous is not None and rate is not None:
        dt = max(t_s - previous.t_s, 0.0)
        allowed = rate * dt
        delta = wrap_pi(course - previous.course_rad)
        if abs(delta) > allowed + COURSE_TOLERANCE_RAD:
            reasons.append(
                Limited(
                    "course_rate",
                    f"course change {delta:+.4f} rad in {dt:.3f} s exceeds {rate} rad/s",
                )
            )
            course = wrap_pi(previous.course_rad + math.copysign(allowed, delta))
            # the path's own course is not flown either: the limited course is
            command = replace(command, path_course_rad=None)
    max_rate = envelope.max_course_rate_rad_s
    course_rate = command.course_rate_rad_s
    if abs(course_rate) > max_rate + COURSE_TOLERANCE_RAD:
        reasons.append(
            Limited(
                "course_rate_feed_forward",
                f"course rate {course_rate:+.4f} rad/s to feed forward exceeds {max_rate} rad/s",
            )
        )
        course_rate = math.copysign(max_rate, course_rate)
    if not reasons:
        return replace(command, course_rad=course), ()
    return replace(
        command, course_rad=course, speed_m_s=speed, course_rate_rad_s=course_rate
    ), tuple(reasons)
