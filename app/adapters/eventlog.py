"""The run's event log: one JSON object per line, flushed as it goes so a crash loses nothing.

Every event carries the vehicle time ``t_s`` it refers to, a ``kind`` and its own fields; the
log also counts events per kind, which the run summary reports. Vehicles are written as users
number them, from 1 (``app.runtime.events.for_users``: ``vehicle``, and the lists ``vehicles``,
``active``, ``agents``).

Kinds that can come at the sensor or setpoint rate for as long as their cause lasts (a camera
that keeps reporting nonsense, a vehicle that refuses every speed command) are written once per
``REPEAT_WINDOW_S`` of event time for each of their keys (``REPEATED_KINDS``); the next line
written for that key says in ``repeats`` how many were held back before it. The last one held
back of each key (with the rest in its ``repeats``) is written before the next event of another
kind, and when the log closes, so the file stays in the order the events came and a run's last
event (``agent_stop``, ``mission_complete``) is its last line. The counts count them all.
"""

import json
import math
from collections import Counter
from pathlib import Path
from types import TracebackType
from typing import IO, Final, Self

from app.runtime.events import for_users

#: event time (s) within which a repeated event of one key is written once
REPEAT_WINDOW_S: Final = 5.0
#: the kinds written once per window, with the fields that tell their repeats apart
REPEATED_KINDS: Final = {
    "observation_dropped": ("vehicle", "outcome"),
    "command_refused": ("vehicle", "reason"),
    "telemetry_rejected": ("vehicle", "reason"),
}


def _plain(value: object) -> object:
    """JSON has no NaN or infinity: write them as strings so the line stays valid JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


class EventLog:
    """Append-only JSON-lines file; a context manager so it is closed on every exit path."""

    def __init__(self, path: Path) -> None:
        self._path = path
        self._file: IO[str] | None = None
        self.counts: Counter[str] = Counter()
        #: per repeated key: event time last written, events held back since, the last of them
        self._repeats: dict[tuple[object, ...], tuple[float, int, dict[str, object]]] = {}

    def __enter__(self) -> Self:
        self._path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self._path.open("a", encoding="utf-8")
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._file is not None:
            self._write_held()
            self._file.close()
            self._file = None

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        """Write one event; ``fields`` must be JSON-serialisable (non-finite floats become text)."""
        self.counts[kind] += 1
        if self._file is None:
            return
        numbered = for_users(fields)
        record = {"t_s": _plain(t_s), "kind": kind, **{k: _plain(v) for k, v in numbered.items()}}
        key_fields = REPEATED_KINDS.get(kind)
        if key_fields is not None:
            key = (kind, *(str(fields.get(name)) for name in key_fields))
            last = self._repeats.get(key)
            if last is not None and 0.0 <= t_s - last[0] < REPEAT_WINDOW_S:
                self._repeats[key] = (last[0], last[1] + 1, record)
                return
            self._repeats[key] = (t_s, 0, record)
            if last is not None and last[1]:
                record = record | {"repeats": last[1]}
        else:
            self._write_held()
        self._write(record)

    def _write_held(self) -> None:
        """Write the last event held back of each repeated key (its ``repeats``: the others)."""
        for key, (_, held, record) in self._repeats.items():
            if held:
                self._write(record | ({"repeats": held - 1} if held > 1 else {}))
                t = record["t_s"]
                self._repeats[key] = (float(t) if isinstance(t, int | float) else 0.0, 0, record)

    def _write(self, record: dict[str, object]) -> None:
        assert self._file is not None
        self._file.write(json.dumps(record, default=str) + "\n")
        self._file.flush()
