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
#: and at most this early (s): a slot paced by times much closer together than its period (a
#: fusion every 0.2 s pacing an allocation every 1 s) comes at its time, not a pace before it
SLOT_EARLY_MAX_S: Final = 0.03


@dataclass(frozen=True, slots=True)
class Every:
    """Due once per period on a grid of slots: at the first time at or after ``next_t_s``
    (less a little: ``slot_due``); once sent (``sent``), the next slot is ``period_s``
    after this one, not after the time it was sent at, so a message paced by times a period
    apart goes out every period, none skipped. After a gap of a whole period or more the grid
    starts again at the time sent. ``period_s`` 0: due every time it is asked."""

    period_s: float
    next_t_s: float = -math.inf

    def __post_init__(self) -> None:
        if not (math.isfinite(self.period_s) and self.period_s >= 0.0):
            raise ValueError(f"period_s must be finite and >= 0, got {self.period_s!r}")

    def due(self, t_s: float) -> bool:
        return slot_due(t_s, self.next_t_s, self.period_s)

    def sent(self, t_s: float) -> "Every":
        return replace(self, next_t_s=following_slot(self.next_t_s, t_s, self.period_s))


def slot_due(t_s: float, slot_t_s: float, period_s: float) -> bool:
    """Whether ``t_s`` is the time of the slot at ``slot_t_s`` (at or after it, less
    ``SLOT_EARLY`` of a period and at most ``SLOT_EARLY_MAX_S``)."""
    return t_s >= slot_t_s - min(SLOT_EARLY * period_s, SLOT_EARLY_MAX_S)


def following_slot(slot_t_s: float, t_s: float, period_s: float) -> float:
    """The slot after the one at ``slot_t_s``, taken at ``t_s``: a period after the slot, or
    after ``t_s`` when that is off the grid: the first, after a gap of a period or more, or
    taken late, half a period (less the early allowance) or more after its slot, as when the
    times that pace it missed the slot; a late one does not catch up, so two never come less
    than half a period apart."""
    early = min(SLOT_EARLY * period_s, SLOT_EARLY_MAX_S)
    if not (-period_s < t_s - slot_t_s < 0.5 * period_s - early):
        slot_t_s = t_s
    return slot_t_s + period_s
