"""Where runtime loops report what happened: an event sink (the run's JSON-lines log, or none)."""

import logging
from typing import Protocol

log = logging.getLogger("standoff.events")


class EventSink(Protocol):
    def emit(self, kind: str, t_s: float, **fields: object) -> None: ...


WARNING_KINDS = frozenset({"falling_behind"})
"""Events logged as warnings (shown on the terminal) unless they say ``repeat=True``; the
others are logged at INFO."""


class LoggingSink:
    """Sends every event to the ``standoff.events`` logger (and to ``inner`` when given)."""

    def __init__(self, inner: EventSink | None = None) -> None:
        self._inner = inner

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        detail = " ".join(f"{k}={v}" for k, v in fields.items())
        warn = kind in WARNING_KINDS and not fields.get("repeat", False)
        level = logging.WARNING if warn else logging.INFO
        log.log(level, "t=%.2f %s %s", t_s, kind, detail)
        if self._inner is not None:
            self._inner.emit(kind, t_s, **fields)
