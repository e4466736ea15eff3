"""How slowly an autopilot's airspeed follows its speed command, learned in flight.

Real ArduPlane 4.6.2 SITL's VFR_HUD airspeed followed GUIDED_CHANGE_SPEED about 3 s late
(TECS trades speed against height slowly; a first-order fit gives a 5-6 s time constant).
Guidance and phase keeping ask for a speed expecting the airframe's acceleration limit, so the
speed cap that lets a vehicle turn on the fast side of a moving target's orbit arrives seconds
late and the vehicle swings wide.

``SpeedLag`` fits tau in d(airspeed)/dt = (command - airspeed) / tau by least squares through
the origin of the airspeed's change over intervals of at least ``period_s`` against the mean
of (command - airspeed) over them, forgetting with time constant ``memory_s``; only intervals
with |command - airspeed| >= ``min_error_m_s`` count, and it is ready after ``min_active_s``
of them. tau is clamped to [``min_tau_s``, ``max_tau_s``]. ``lead`` then turns a wanted speed
into the command that, through that lag, makes the airspeed close on the wanted one with time
constant ``target_tau_s``: airspeed + (tau / target_tau)(wanted - airspeed), the gain at most
``max_gain``, and always clamped by the caller to the envelope's speed range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace


@dataclass(frozen=True, slots=True)
class SpeedLagParams:
    period_s: float = 1.0
    max_period_s: float = 3.0
    memory_s: float = 120.0
    min_error_m_s: float = 0.5
    min_active_s: float = 20.0
    min_tau_s: float = 0.5
    max_tau_s: float = 15.0
    target_tau_s: float = 2.0
    max_gain: float = 3.0

    def __post_init__(self) -> None:
        for name in ("period_s", "max_period_s", "memory_s", "min_error_m_s", "min_active_s",
                     "min_tau_s", "max_tau_s", "target_tau_s", "max_gain"):  # fmt: skip
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if self.max_period_s < self.period_s:
            raise ValueError(
                f"max_period_s ({self.max_period_s}) must be >= period_s ({self.period_s})"
            )
        if self.max_tau_s <= self.min_tau_s:
            raise ValueError(f"max_tau_s ({self.max_tau_s}) must be > min_tau_s ({self.min_tau_s})")
        if self.max_gain < 1.0:
            raise ValueError(f"max_gain must be >= 1, got {self.max_gain!r}")


@dataclass(frozen=True, slots=True)
class _Mark:
    t_s: float
    airspeed_m_s: float
    error_sum_m_s: float
    count: int


@dataclass(frozen=True, slots=True)
class SpeedLag:
    """The fit so far: forgotten sums of (accel x error) and error^2, and active time."""

    params: SpeedLagParams = SpeedLagParams()
    sum_xy: float = 0.0
    sum_xx: float = 0.0
    active_s: float = 0.0
    samples: int = 0
    _mark: _Mark | None = None

    @property
    def ready(self) -> bool:
        return self.active_s >= self.params.min_active_s and self.sum_xy > 0.0

    @property
    def tau_s(self) -> float | None:
        """tau within its bounds once ``ready``, else None."""
        if not self.ready:
            return None
        tau = self.sum_xx / self.sum_xy
        return max(self.params.min_tau_s, min(self.params.max_tau_s, tau))

    def lead(self, wanted_m_s: float, airspeed_m_s: float | None) -> float:
        """The speed to command for ``wanted_m_s`` (``wanted_m_s`` itself until ready or with no
        airspeed); the caller clamps it to the envelope."""
        tau = self.tau_s
        if tau is None or airspeed_m_s is None or not math.isfinite(airspeed_m_s):
            return wanted_m_s
        gain = min(max(tau / self.params.target_tau_s, 1.0), self.params.max_gain)
        return airspeed_m_s + gain * (wanted_m_s - airspeed_m_s)

    def update(self, t_s: float, airspeed_m_s: float | None, command_m_s: float) -> SpeedLag:
        """One frame: its time, the airspeed flown and the speed command in force. A frame with
        a non-finite value or no airspeed, or out of time order, restarts the interval."""
        if airspeed_m_s is None or not all(
            math.isfinite(v) for v in (t_s, airspeed_m_s, command_m_s)
        ):
            return replace(self, _mark=None)
        mark, p = self._mark, self.params
        error = command_m_s - airspeed_m_s
        if mark is None or t_s <= mark.t_s or t_s - mark.t_s > p.max_period_s:
            return replace(self, _mark=_Mark(t_s, airspeed_m_s, error, 1))
        if t_s - mark.t_s < p.period_s:
            grown = _Mark(mark.t_s, mark.airspeed_m_s, mark.error_sum_m_s + error, mark.count + 1)
            return replace(self, _mark=grown)
        dt = t_s - mark.t_s
        mean_error = mark.error_sum_m_s / mark.count
        next_mark = _Mark(t_s, airspeed_m_s, error, 1)
        if abs(mean_error) < p.min_error_m_s:
            return replace(self, _mark=next_mark)
        accel = (airspeed_m_s - mark.airspeed_m_s) / dt
        keep = math.exp(-dt / p.memory_s)
        return SpeedLag(
            p,
            keep * self.sum_xy + accel * mean_error,
            keep * self.sum_xx + mean_error * mean_error,
            self.active_s + dt,
            self.samples + 1,
            next_mark,
        )
