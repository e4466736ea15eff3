"""The default event sink: every event to the ``standoff.events`` logger, then on (the port:
``app.runtime.ports.events``); and how an event's vehicles read to a user.

Inside the app a vehicle is its index from 0; a user numbers vehicles from 1, as their MAVLink
system ids, ``vehicle-N.tlog``, the live view and the summary do. ``for_users`` turns an event's
fields into those numbers: the terminal's lines and ``events.jsonl`` both use it.
"""

import logging
from collections.abc import Mapping
from typing import TypeGuard

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


VEHICLE_FIELD = "vehicle"
"""An event field holding one vehicle's index."""
VEHICLE_LIST_FIELDS = frozenset({"vehicles", "active", "agents"})
"""Event fields that hold a list of vehicle indices when they hold a list (``vehicles`` is a
count in ``mission_start``, left alone)."""


def _is_index(value: object) -> TypeGuard[int]:
    return isinstance(value, int) and not isinstance(value, bool)


def for_users(fields: Mapping[str, object]) -> dict[str, object]:
    """An event's fields with each vehicle index (from 0) as the vehicle's number (from 1)."""
    out = dict(fields)
    vehicle = out.get(VEHICLE_FIELD)
    if _is_index(vehicle):
        out[VEHICLE_FIELD] = vehicle + 1
    for name in VEHICLE_LIST_FIELDS & out.keys():
        value = out[name]
        if isinstance(value, list | tuple) and all(_is_index(v) for v in value):
            out[name] = [v + 1 for v in value]
    return out


class LoggingSink:
    """Sends every event to the ``standoff.events`` logger (and to ``inner`` when given)."""

    def __init__(self, inner: EventSink | None = None) -> None:
        self._inner = inner

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        detail = " ".join(f"{k}={v}" for k, v in for_users(fields).items())
        warn = kind in WARNING_KINDS and not fields.get("repeat", False)
        level = logging.WARNING if warn else logging.INFO
        log.log(level, "t=%.2f %s %s", t_s, kind, detail)
        if self._inner is not None:
            self._inner.emit(kind, t_s, **fields)
