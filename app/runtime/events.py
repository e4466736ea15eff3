"""The default event sink: every event to the ``standoff.events`` logger, then on (the port:
``app.runtime.ports.events``)."""

import logging

from app.runtime.ports.events import EventSink

log = logging.getLogger("standoff.events")


WARNING_KINDS = frozenset(
    {
        "falling_behind",
        "pilot_took_over",
        "handover_timeout",
        "clock_rebased",
    }
)
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
