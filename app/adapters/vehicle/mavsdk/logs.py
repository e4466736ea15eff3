"""libmavsdk's own log lines routed to the ``mavsdk`` Python logger, repeats held back."""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Final

from mavsdk import LogLevel, log_subscribe

_LOG_LEVELS: Final = {
    LogLevel.DEBUG: logging.DEBUG,
    LogLevel.INFO: logging.INFO,
    LogLevel.WARN: logging.WARNING,
    LogLevel.ERROR: logging.ERROR,
}
_mavsdk_log = logging.getLogger("mavsdk")
_log_route_lock = threading.Lock()
_log_routed = False


class RepeatLimiter:
    """Lets each distinct message through at most once per ``window_s`` seconds and says how
    many of it were held back since it last went through. Thread-safe (libmavsdk logs from its
    own threads)."""

    def __init__(self, window_s: float, clock: Callable[[], float] = time.monotonic) -> None:
        if not (math.isfinite(window_s) and window_s >= 0.0):
            raise ValueError(f"window_s must be finite and >= 0, got {window_s!r}")
        self._window_s = window_s
        self._clock = clock
        self._lock = threading.Lock()
        self._last: dict[str, tuple[float, int]] = {}  # message -> (time let through, held back)

    def admit(self, message: str) -> int | None:
        """None: hold this one back; else let it through, after that many were held back."""
        now = self._clock()
        with self._lock:
            last = self._last.get(message)
            if last is not None and now - last[0] < self._window_s:
                self._last[message] = (last[0], last[1] + 1)
                return None
            if len(self._last) > 1000:  # messages with changing text: forget the oldest
                self._last.clear()
            self._last[message] = (now, 0)
            return 0 if last is None else last[1]


#: how often the same libmavsdk log line may appear (a cut link logs "Sending message failed"
#: at the setpoint rate)
MAVSDK_LOG_REPEAT_S: Final = 5.0


def route_mavsdk_logs() -> None:
    """Send libmavsdk's own log lines to the ``mavsdk`` Python logger instead of stdout, each
    distinct line at most once per ``MAVSDK_LOG_REPEAT_S`` with a count of the repeats held
    back.

    Process-wide (libmavsdk has one log callback); idempotent.
    """
    global _log_routed
    with _log_route_lock:
        if _log_routed:
            return
        limiter = RepeatLimiter(MAVSDK_LOG_REPEAT_S)

        def handler(level: LogLevel, message: str, file: str | None, line: int) -> bool:
            held = limiter.admit(message)
            if held is None:
                return True
            more = f" (and {held} times more since it was last logged)" if held else ""
            _mavsdk_log.log(
                _LOG_LEVELS.get(level, logging.INFO), "%s (%s:%d)%s", message, file, line, more
            )
            return True

        log_subscribe(handler)
        _log_routed = True
