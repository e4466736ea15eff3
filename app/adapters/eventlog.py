"""The run's event log: one JSON object per line, flushed as it goes so a crash loses nothing.

Every event carries the vehicle time ``t_s`` it refers to, a ``kind`` and its own fields; the
log also counts events per kind, which the run summary reports.
"""

import json
import math
from collections import Counter
from pathlib import Path
from types import TracebackType
from typing import IO, Self


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
            self._file.close()
            self._file = None

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        """Write one event; ``fields`` must be JSON-serialisable (non-finite floats become text)."""
        self.counts[kind] += 1
        if self._file is None:
            return
        record = {"t_s": _plain(t_s), "kind": kind, **{k: _plain(v) for k, v in fields.items()}}
        self._file.write(json.dumps(record, default=str) + "\n")
        self._file.flush()
