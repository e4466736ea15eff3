"""MAVLink telemetry logs (``.tlog``) as QGroundControl, MAVProxy and pymavlink write and replay
them: records of an 8-byte big-endian timestamp (microseconds since the Unix epoch) followed by
one MAVLink packet as it went over the link.

The mission records one per vehicle: every packet the vehicle sent (autopilot, camera and any
other component) and every packet sent to it (by the app, or by a ground station beside it),
stamped with the wall-clock time the relay (``app.adapters.vehicle.mavsdk.relay``) received it.
Nothing is re-encoded: the log holds the bytes that flew.
"""

from __future__ import annotations

import contextlib
import logging
import math
import struct
from collections.abc import Callable, Iterable
from pathlib import Path
from types import TracebackType
from typing import BinaryIO, Self

_log = logging.getLogger(__name__)
_STAMP = struct.Struct(">Q")


class TlogWriter:
    """One .tlog, appended packet by packet; a context manager so the file is always closed.

    Timestamps never go back in a log (a wall clock stepped back by NTP is held at the last
    stamp), so a replay plays it in order.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file: BinaryIO | None = None
        self._last_us = 0
        self.records = 0

    def __enter__(self) -> Self:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("wb")
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        file, self._file = self._file, None
        if file is not None:
            file.close()

    def write(self, t_unix_s: float, packet: bytes | memoryview) -> None:
        """Append one packet received at ``t_unix_s`` (s since the Unix epoch)."""
        if self._file is None:
            raise RuntimeError(f"TlogWriter {self.path} used outside its context")
        if not math.isfinite(t_unix_s) or t_unix_s < 0.0:
            raise ValueError(f"tlog timestamp must be finite and >= 0, got {t_unix_s!r}")
        stamp_us = max(self._last_us, int(t_unix_s * 1e6))
        self._last_us = stamp_us
        self._file.write(_STAMP.pack(stamp_us))
        self._file.write(packet)
        self.records += 1

    def flush(self) -> None:
        if self._file is not None:
            self._file.flush()


class TlogRecorder:
    """The .tlogs of one run, one per vehicle system id, shared by every relay of the run.

    ``paths``: system id -> its log's path; packets of other system ids are not recorded.
    A log that cannot be written (disk full, folder gone) is closed with one logged error and
    the others go on: a flight log never stops a mission.
    """

    def __init__(self, paths: dict[int, Path]) -> None:
        self._paths = dict(paths)
        self._writers: dict[int, TlogWriter] = {}
        self._failed: set[int] = set()
        self._open = False

    @classmethod
    def for_vehicles(
        cls,
        out_dir: Path,
        system_ids: Iterable[int],
        name: Callable[[int], str] = lambda sysid: f"vehicle-{sysid}.tlog",
    ) -> TlogRecorder:
        return cls({s: out_dir / name(s) for s in system_ids})

    @property
    def system_ids(self) -> frozenset[int]:
        return frozenset(self._paths)

    def __enter__(self) -> Self:
        self._open = True
        for system_id, path in self._paths.items():
            writer = TlogWriter(path)
            try:
                writer.__enter__()
            except OSError as exc:
                self._fail(system_id, exc)
                continue
            self._writers[system_id] = writer
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._open = False
        writers, self._writers = self._writers, {}
        for system_id, writer in writers.items():
            try:
                writer.close()
            except OSError as error:
                self._fail(system_id, error)

    def records(self, system_id: int) -> int:
        writer = self._writers.get(system_id)
        return writer.records if writer is not None else 0

    def write(self, system_id: int, t_unix_s: float, packet: bytes | memoryview) -> None:
        """Append a packet to ``system_id``'s log (ignored for a system id without a log)."""
        writer = self._writers.get(system_id)
        if writer is None:
            return
        try:
            writer.write(t_unix_s, packet)
        except OSError as exc:
            del self._writers[system_id]
            with contextlib.suppress(OSError):
                writer.close()
            self._fail(system_id, exc)

    def flush(self) -> None:
        for system_id, writer in list(self._writers.items()):
            try:
                writer.flush()
            except OSError as exc:
                del self._writers[system_id]
                self._fail(system_id, exc)

    def _fail(self, system_id: int, exc: OSError) -> None:
        if system_id not in self._failed:
            self._failed.add(system_id)
            _log.error(
                "vehicle %d: flight log %s not recorded from here on: %s",
                system_id,
                self._paths[system_id],
                exc,
            )
