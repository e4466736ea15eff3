"""When a periodic message is due, in mission time: the schedule lives in the state it paces."""

import math
from dataclasses import dataclass

from app.core.values import replace


@dataclass(frozen=True, slots=True)
class Every:
    """Due at the first time at or after ``next_t_s``; once sent (``sent``), ``period_s`` later
    (s; 0: every time it is asked)."""

    period_s: float
    next_t_s: float = -math.inf

    def __post_init__(self) -> None:
        if not (math.isfinite(self.period_s) and self.period_s >= 0.0):
            raise ValueError(f"period_s must be finite and >= 0, got {self.period_s!r}")

    def due(self, t_s: float) -> bool:
        return t_s >= self.next_t_s

    def sent(self, t_s: float) -> "Every":
        return replace(self, next_t_s=t_s + self.period_s)
