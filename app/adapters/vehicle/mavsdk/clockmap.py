"""A vehicle's boot clock mapped onto the mission clock: pure arithmetic, no socket, no clock.

Every autopilot stamps its messages with its own ``time_boot_ms``, which starts when it booted;
vehicles booted seconds or minutes apart therefore disagree by that much. The host knows when each
message arrived on its own mission clock, so ``host_t - boot_t`` is the vehicle's offset plus the
transport delay. The delay is never negative and only now and then near its least, so the offset
is the least ``host_t - boot_t`` over a sliding window: jitter and a busy host only make samples
larger, and they are not taken. A message whose boot time went back (a reboot) or that arrived
with its boot clock far ahead of what the host's clock allows (a jump) re-bases the offset at
once; a boot clock that runs slower than the host's is followed once the window has slid past.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Rebase:
    """The offset started again: ``reason`` is ``"first"``, ``"reboot"`` or ``"jump"``."""

    reason: str
    boot_s: float
    previous_boot_s: float | None
    offset_s: float
    previous_offset_s: float | None


class BootClockMap:
    """Maps one vehicle's boot times (s) onto mission time (s): ``t = boot + offset``.

    ``window_s``: how much host time (mission seconds) of samples the running minimum holds.
    ``jump_s``: a boot time that went back by more than this, or an offset sample this much
    below the running minimum (the boot clock leapt ahead), is a new clock (``Rebase``). A boot
    time that went back by less is a late or repeated message (``update`` returns it as is; the
    caller drops it as stale).
    """

    def __init__(self, window_s: float = 10.0, jump_s: float = 5.0) -> None:
        for name, value in (("window_s", window_s), ("jump_s", jump_s)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        self.window_s = window_s
        self.jump_s = jump_s
        self.rebases = 0
        # (host time, offset sample), offsets increasing from the left: a monotone deque
        self._samples: deque[tuple[float, float]] = deque()
        self._last_boot_s: float | None = None
        self._offset_s: float | None = None

    @property
    def offset_s(self) -> float | None:
        """The current offset (None before the first message)."""
        return self._offset_s

    def to_mission(self, boot_s: float) -> float:
        """Mission time of a boot time on the current offset (0 offset before the first)."""
        return boot_s + (self._offset_s or 0.0)

    def update(self, boot_s: float, host_t_s: float) -> tuple[float, Rebase | None]:
        """Take a message stamped ``boot_s`` that arrived at mission time ``host_t_s``.

        Returns its mission time and, when the offset started again, why."""
        if not (math.isfinite(boot_s) and math.isfinite(host_t_s)):
            raise ValueError(f"times must be finite, got boot {boot_s!r}, host {host_t_s!r}")
        sample = host_t_s - boot_s
        last, offset = self._last_boot_s, self._offset_s
        rebase: Rebase | None = None
        if offset is None:
            rebase = Rebase("first", boot_s, None, sample, None)
        elif last is not None and last - boot_s > self.jump_s:
            rebase = Rebase("reboot", boot_s, last, sample, offset)
        elif offset - sample > self.jump_s:
            rebase = Rebase("jump", boot_s, last, sample, offset)
        elif last is not None and boot_s <= last:
            return boot_s + offset, None  # late or repeated: not a sample
        if rebase is not None:
            self._samples.clear()
            if rebase.reason != "first":
                self.rebases += 1
        self._last_boot_s = boot_s
        samples = self._samples
        while samples and samples[-1][1] >= sample:
            samples.pop()
        samples.append((host_t_s, sample))
        while samples[0][0] < host_t_s - self.window_s and len(samples) > 1:
            samples.popleft()
        self._offset_s = samples[0][1]
        return boot_s + self._offset_s, rebase
