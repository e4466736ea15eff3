"""How much of the coordinated turn an airframe flies at a bank, learned in flight.

A level coordinated turn at bank phi and airspeed V turns the course at g tan(phi) / V. Real
ArduPlane 4.6.2 SITL (its stock plane model, GUIDED) turned at 0.70 of that (median of ~9,700
samples over three aircraft at 10-22 m/s, 0.65-0.73 in every speed band): an adapter that sizes
its bank limit and heading command on the ideal turn gets 0.7 of the course rate it asks for,
0.14 rad/s for an envelope of 0.2, and a 90 m circle at 14 m/s cannot be held.

``TurnEfficiency`` fits eta in rate = eta g tan(phi) / V by least squares through the origin
over samples taken at least ``period_s`` apart (the course rate over that interval against the
mean bank and speed), forgetting old ones with time constant ``memory_s``. Only samples in a
turn (|g tan(phi) / V| >= ``min_ideal_rate_rad_s``) at a steady bank (its frames over the
interval span less than ``max_roll_rate_rad_s`` x the interval) count. Real ArduPlane's bank
hunts +-5-8 deg about its demand with a period of about 1.5 s; over the intervals where the
bank was changing, the course turned at 0.80-0.87 of the coordinated rate, against 0.66-0.70 at
a steady bank (three aircraft of one 10-minute mission, 0.5 s intervals, steady = under
3 deg/s). Counting all of them put the fit at 0.73-0.75 over a mission and let it wander up to
0.87-0.91 for minutes (memory 120 s), and a bank limit sized on 0.87 left an aircraft 27 m
outside the circle. The estimate is ready after ``min_turning_s`` of steady samples and is
clamped to [``min_efficiency``, 1]: above 1 is noise (a level turn cannot beat the coordinated
one) and the floor bounds the bank the adapter will ask for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Final

from app.core.frames import wrap_pi

#: standard gravity (m/s^2), as ArduPilot's GRAVITY_MSS
GRAVITY_M_S2: Final = 9.80665


@dataclass(frozen=True, slots=True)
class TurnEfficiencyParams:
    period_s: float = 0.5
    #: a longer gap (telemetry outage) restarts the interval instead of spanning it
    max_period_s: float = 2.0
    memory_s: float = 120.0
    min_ideal_rate_rad_s: float = 0.03
    min_turning_s: float = 10.0
    min_efficiency: float = 0.4
    min_speed_m_s: float = 3.0
    #: an interval over which the bank changed faster than this is not a steady turn (3 deg/s)
    max_roll_rate_rad_s: float = math.radians(3.0)

    def __post_init__(self) -> None:
        for name in ("period_s", "max_period_s", "memory_s", "min_ideal_rate_rad_s",
                     "min_turning_s", "min_efficiency", "min_speed_m_s",
                     "max_roll_rate_rad_s"):  # fmt: skip
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if self.max_period_s < self.period_s:
            raise ValueError(
                f"max_period_s ({self.max_period_s}) must be >= period_s ({self.period_s})"
            )
        if self.min_efficiency > 1.0:
            raise ValueError(f"min_efficiency must be <= 1, got {self.min_efficiency!r}")


@dataclass(frozen=True, slots=True)
class _Mark:
    t_s: float
    course_rad: float
    roll_min_rad: float
    roll_max_rad: float
    roll_sum_rad: float
    speed_sum_m_s: float
    count: int


@dataclass(frozen=True, slots=True)
class TurnEfficiency:
    """The fit so far: sums of rate x ideal and ideal^2 (forgotten), turning time, and how many
    turning intervals were left out because the bank was changing."""

    params: TurnEfficiencyParams = TurnEfficiencyParams()
    sum_xy: float = 0.0
    sum_xx: float = 0.0
    turning_s: float = 0.0
    samples: int = 0
    unsteady: int = 0
    _mark: _Mark | None = None

    @property
    def ready(self) -> bool:
        return self.turning_s >= self.params.min_turning_s and self.sum_xx > 0.0

    @property
    def efficiency(self) -> float:
        """eta in [min_efficiency, 1] once ``ready``, else 1 (the coordinated turn)."""
        if not self.ready:
            return 1.0
        eta = self.sum_xy / self.sum_xx
        return max(self.params.min_efficiency, min(1.0, eta))

    def update(
        self, t_s: float, course_rad: float, roll_rad: float | None, speed_m_s: float | None
    ) -> TurnEfficiency:
        """One telemetry frame (time, course over ground, bank > 0 right, airspeed). A frame
        with a non-finite value, no bank or no speed, or out of time order, restarts the
        interval."""
        if (
            roll_rad is None
            or speed_m_s is None
            or not all(math.isfinite(v) for v in (t_s, course_rad, roll_rad, speed_m_s))
        ):
            return replace(self, _mark=None)
        mark, p = self._mark, self.params
        if mark is None or t_s <= mark.t_s or t_s - mark.t_s > p.max_period_s:
            first = _Mark(t_s, course_rad, roll_rad, roll_rad, roll_rad, speed_m_s, 1)
            return replace(self, _mark=first)
        if t_s - mark.t_s < p.period_s:
            grown = _Mark(
                mark.t_s,
                mark.course_rad,
                min(mark.roll_min_rad, roll_rad),
                max(mark.roll_max_rad, roll_rad),
                mark.roll_sum_rad + roll_rad,
                mark.speed_sum_m_s + speed_m_s,
                mark.count + 1,
            )
            return replace(self, _mark=grown)
        dt = t_s - mark.t_s
        next_mark = _Mark(t_s, course_rad, roll_rad, roll_rad, roll_rad, speed_m_s, 1)
        roll = (mark.roll_sum_rad + roll_rad) / (mark.count + 1)
        speed = (mark.speed_sum_m_s + speed_m_s) / (mark.count + 1)
        if speed < p.min_speed_m_s or abs(roll) >= 0.5 * math.pi:
            return replace(self, _mark=next_mark)
        ideal = GRAVITY_M_S2 * math.tan(roll) / speed
        keep = math.exp(-dt / p.memory_s)
        if abs(ideal) < p.min_ideal_rate_rad_s:
            return replace(self, _mark=next_mark)
        swing = max(mark.roll_max_rad, roll_rad) - min(mark.roll_min_rad, roll_rad)
        if swing > p.max_roll_rate_rad_s * dt:
            return replace(self, unsteady=self.unsteady + 1, _mark=next_mark)
        rate = wrap_pi(course_rad - mark.course_rad) / dt
        return TurnEfficiency(
            p,
            keep * self.sum_xy + rate * ideal,
            keep * self.sum_xx + ideal * ideal,
            self.turning_s + dt,
            self.samples + 1,
            self.unsteady,
            next_mark,
        )
