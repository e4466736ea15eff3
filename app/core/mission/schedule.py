"""When a periodic message is due, in mission time: the schedule lives in the state it paces."""

import math
from dataclasses import dataclass
from typing import Final

from app.core.values import replace

#: how early, as a share of the period, a time still counts as the slot's: the times that pace
#: a schedule (telemetry frames, statuses, camera fixes) come a period apart give or take a
#: rounding error or the jitter of an autopilot's clock, and one a hair before its slot must
#: not push the message a whole period later
SLOT_EARLY: Final = 0.3


@dataclass(frozen=True, slots=True)
class Every:
    """Due once per period on a grid of slots: at the first time at or after ``next_t_s``
    (less ``SLOT_EARLY`` of a period); once sent (``sent``), the next slot is ``period_s``
    after this one, not after the time it was sent at, so a message paced by times a period
    apart goes out every period, none skipped. After a gap of a whole period or more the grid
    starts again at the time sent. ``period_s`` 0: due every time it is asked."""

    period_s: float
    next_t_s: float = -math.inf

    def __post_init__(self) -> None:
        if not (math.isfinite(self.period_s) and self.period_s >= 0.0):
            raise ValueError(f"period_s must be finite and >= 0, got {self.period_s!r}")

    def due(self, t_s: float) -> bool:
        return t_s >= self.next_t_s - SLOT_EARLY * self.period_s

    def sent(self, t_s: float) -> "Every":
        slot = self.next_t_s
        if not (abs(t_s - slot) < self.period_s):  # the first, or off the grid: it starts here
            slot = t_s
        return replace(self, next_t_s=slot + self.period_s)
