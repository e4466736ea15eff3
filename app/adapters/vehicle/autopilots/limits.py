"""The envelope every outgoing setpoint is held to, and the limiter that holds it there."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Final, Literal

from app.core.frames import wrap_pi
from app.runtime.ports.vehicle import CourseSpeedCommand


@dataclass(frozen=True, slots=True)
class SetpointLimits:
    """The envelope every outgoing setpoint is held to (Table 2: 10..18 m/s, 0.2 rad/s).

    ``max_course_rate_rad_s`` bounds how fast the *commanded* course may turn between two
    setpoints (vehicle time); ``None`` leaves the course unconstrained.
    """

    min_speed_m_s: float
    max_speed_m_s: float
    max_course_rate_rad_s: float | None = None
    max_accel_m_s2: float = 2.0
    max_climb_rate_m_s: float = 3.0
    altitude_gain_per_s: float = 0.5

    def __post_init__(self) -> None:
        for name in (
            "min_speed_m_s",
            "max_speed_m_s",
            "max_accel_m_s2",
            "max_climb_rate_m_s",
            "altitude_gain_per_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if self.min_speed_m_s > self.max_speed_m_s:
            raise ValueError(
                f"min_speed_m_s ({self.min_speed_m_s}) exceeds max_speed_m_s ({self.max_speed_m_s})"
            )
        rate = self.max_course_rate_rad_s
        if rate is not None and not (math.isfinite(rate) and rate > 0.0):
            raise ValueError(f"max_course_rate_rad_s must be finite and > 0, got {rate!r}")


@dataclass(frozen=True, slots=True)
class SentSetpoint:
    """The last setpoint that left, with the vehicle time it left at."""

    t_s: float
    course_rad: float
    speed_m_s: float


COURSE_TOLERANCE_RAD: Final = 1e-9

LimitKind = Literal["speed_below_min", "speed_above_max", "course_rate"]


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
    towards the requested one by at most ``max_course_rate_rad_s * (t_s - previous.t_s)``
    (the shorter way round); time running backwards counts as no time.
    """
    reasons: list[Limited] = []
    speed = command.speed_m_s
    if speed < limits.min_speed_m_s:
        reasons.append(
            Limited("speed_below_min", f"speed {speed:.3f} m/s below {limits.min_speed_m_s} m/s")
        )
        speed = limits.min_speed_m_s
    elif speed > limits.max_speed_m_s:
        reasons.append(
            Limited("speed_above_max", f"speed {speed:.3f} m/s above {limits.max_speed_m_s} m/s")
        )
        speed = limits.max_speed_m_s
    course = command.course_rad
    if not -math.pi <= course < math.pi:
        course = wrap_pi(course)
    if previous is not None and limits.max_course_rate_rad_s is not None:
        dt = max(t_s - previous.t_s, 0.0)
        allowed = limits.max_course_rate_rad_s * dt
        delta = wrap_pi(course - previous.course_rad)
        if abs(delta) > allowed + COURSE_TOLERANCE_RAD:
            reasons.append(
                Limited(
                    "course_rate",
                    f"course change {delta:+.4f} rad in {dt:.3f} s exceeds "
                    f"{limits.max_course_rate_rad_s} rad/s",
                )
            )
            course = wrap_pi(previous.course_rad + math.copysign(allowed, delta))
    if not reasons:
        return replace(command, course_rad=course), ()
    return CourseSpeedCommand(course, speed, command.altitude_m), tuple(reasons)
