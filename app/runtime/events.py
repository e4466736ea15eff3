"""Where runtime loops report what happened: an event sink (the run's JSON-lines log, or none)."""

import logging
from typing import Protocol

log = logging.getLogger("standoff.events")


class EventSink(Protocol):
    def emit(self, kind: str, t_s: float, **fields: object) -> None: ...


class LoggingSink:
    """Sends every event to the ``standoff.events`` logger (and to ``inner`` when given)."""

    def __init__(self, inner: EventSink | None = None) -> None:
        self._inner = inner

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        detail = " ".join(f"{k}={v}" for k, v in fields.items())
        log.info("t=%.2f %s %s", t_s, kind, detail)
        if self._inner is not None:
            self._inner.emit(kind, t_s, **fields)
