"""The event-sink port: where the loops report what happened (the run's event log, or none)."""

from typing import Protocol


class EventSink(Protocol):
    def emit(self, kind: str, t_s: float, **fields: object) -> None: ...
