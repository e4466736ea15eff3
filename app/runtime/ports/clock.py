"""The clock port: the host's clocks, for what the mission measures in wall time (never physics).

Physics runs on the vehicles' telemetry time; the host's clocks only stamp files (``time_s``)
and measure how long a run took (``monotonic_s``).
"""

import time
from typing import Protocol


class Clock(Protocol):
    def time_s(self) -> float:
        """Seconds since the Unix epoch (wall time)."""
        ...

    def monotonic_s(self) -> float:
        """Seconds on a clock that never goes back (for durations)."""
        ...


class SystemClock:
    """The host's clocks (the default)."""

    def time_s(self) -> float:
        return time.time()

    def monotonic_s(self) -> float:
        return time.monotonic()


SYSTEM_CLOCK = SystemClock()
