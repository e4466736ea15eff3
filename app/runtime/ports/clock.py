"""The clock port: the host's clocks, for what the mission measures in wall time (never physics).

Physics runs on the vehicles' telemetry time, mapped onto one mission clock (``MissionClock``)
by the vehicle links; the host's clocks otherwise only stamp files (``time_s``) and measure how
long a run took (``monotonic_s``).
"""

import math
import time
from collections.abc import Callable
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


class MissionClock:
    """Mission time on the host: seconds since the mission's epoch, times ``rate``.

    ``host`` is the host clock read (wall time by default: processes on different machines that
    agree on the epoch, such as the ground station's announced one, agree on mission time to the
    accuracy of their clock sync); ``epoch_s`` is on that clock. ``rate`` is mission seconds per
    host second: the built-in simulator's speed-up, 1 for real vehicles. The vehicle links map each
    vehicle's boot clock onto this one (``app.adapters.vehicle.mavsdk.clockmap``).
    """

    def __init__(
        self, epoch_s: float, rate: float = 1.0, host: Callable[[], float] = time.time
    ) -> None:
        if not (math.isfinite(epoch_s) and math.isfinite(rate) and rate > 0.0):
            raise ValueError(f"epoch_s must be finite and rate > 0, got {epoch_s!r}, {rate!r}")
        self.epoch_s = epoch_s
        self.rate = rate
        self._host = host

    @classmethod
    def starting_now(
        cls, rate: float = 1.0, host: Callable[[], float] = time.time
    ) -> "MissionClock":
        """A mission clock whose time 0 is now."""
        return cls(host(), rate, host)

    def now_s(self) -> float:
        return (self._host() - self.epoch_s) * self.rate

    def __call__(self) -> float:
        return self.now_s()
