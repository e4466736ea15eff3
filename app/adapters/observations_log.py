"""The run folder's ``observations.jsonl``: what estimation and the mission's decisions were fed.

One JSON object a line, in the order the mission's loops consumed them (``InputRecorder``):

- ``{"kind": "header", "schema": 1, "vehicles": n, "truth": true, "role": "mission"}``: first
  line; ``truth`` says whether the run scored its figures against the scripted target (the
  built-in simulator or simulated observations) or about the estimate; ``role`` who wrote it:
  ``mission`` (``standoff fly``: everything, one file), ``ground`` or ``agent-<N>`` (N = i + 1;
  the processes of ``standoff ground`` / ``standoff agent``, each its own
  ``observations-<role>.jsonl``);
- ``{"kind": "observation", "vehicle": i, "t_s", "east_m", "north_m", "sigma_m", "clock_t_s"}``:
  a target fix as agent ``i`` fed it to its local filter, before estimation (the camera's,
  after the backlog merge, or one the ground sent; ``sigma_m`` null: the filter's default);
  ``clock_t_s`` the agent's own clock then (its newest control tick, which it judges message
  times by; null before the first);
- ``{"kind": "fused", "vehicle": i, "t_s", "clock_t_s"}``: agent ``i`` applied the fused
  estimate of ``t_s``;
- ``{"kind": "status", "vehicle": i, "t_s", "east_m", "north_m", "course_rad", "speed_m_s",
  "link_ok", "healthy", "clock_t_s"}``: the ground station took vehicle ``i``'s status (the
  vehicle state that the fusion, the stages and the recorded samples use); ``clock_t_s`` its
  own mission clock then, which it judges message times by (null: none);
- ``{"kind": "local", "vehicle": i, "t_s", "clock_t_s"}``: the ground took agent ``i``'s local
  estimate of ``t_s``.

``vehicle`` is the vehicle's index (0-based, as the bus messages carry it; its MAVLink system id
and the number users see is ``vehicle + 1``). Times are mission seconds; positions m
east/north of the mission origin; courses rad clockwise from north. Numbers are written in
full (``repr``), so a replay is fed exactly what the run was. A write that fails is logged
once and recording stops; it never stops the mission.
"""

import json
import logging
import math
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Self

from app.core.estimation.messages import Observation
from app.core.mission.ground import VehicleReport

log = logging.getLogger(__name__)

OBSERVATIONS_FILE = "observations.jsonl"


def observations_file(role: str) -> str:
    """The file of one process of a mission: ``observations.jsonl`` for the whole mission in one
    process, ``observations-<role>.jsonl`` for the ground's or an agent's."""
    return OBSERVATIONS_FILE if role == "mission" else f"observations-{role}.jsonl"


SCHEMA = 1


def _number(value: float) -> float | None:
    """JSON has no NaN or infinity: those are written as null."""
    return value if math.isfinite(value) else None


def _clock(value: float | None) -> float | None:
    return None if value is None else _number(value)


class ObservationLog:
    """Writes ``observations.jsonl`` (an ``InputRecorder``); a context manager."""

    def __init__(self, path: Path, vehicles: int, *, truth: bool, role: str = "mission") -> None:
        self.path = path
        self.lines = 0
        self.failed: str | None = None
        self._header = {
            "kind": "header",
            "schema": SCHEMA,
            "vehicles": vehicles,
            "truth": truth,
            "role": role,
        }
        self._file: IO[str] | None = None

    def __enter__(self) -> Self:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("w", encoding="utf-8")
        self._write(self._header)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._file is not None:
            try:
                self._file.close()
            except OSError as error:
                self._fail(error)
            self._file = None

    def _fail(self, error: OSError) -> None:
        if self.failed is None:
            self.failed = str(error)
            log.error("%s: recording stopped: %s", self.path, error)

    def _write(self, record: dict[str, Any]) -> None:
        if self._file is None or self.failed is not None:
            return
        try:
            self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
        except OSError as error:
            self._fail(error)
            return
        self.lines += 1

    # --- InputRecorder ----------------------------------------------------------------------

    def observation(self, vehicle: int, obs: Observation, clock_t_s: float) -> None:
        sigma = obs.sigma_m
        self._write(
            {
                "kind": "observation",
                "vehicle": vehicle,
                "t_s": obs.t_s,
                "east_m": _number(obs.east_m),
                "north_m": _number(obs.north_m),
                "sigma_m": None if sigma is None else _number(sigma),
                "clock_t_s": _number(clock_t_s),
            }
        )

    def fused(self, vehicle: int, t_s: float, clock_t_s: float) -> None:
        self._write(
            {"kind": "fused", "vehicle": vehicle, "t_s": t_s, "clock_t_s": _number(clock_t_s)}
        )

    def status(self, vehicle: int, report: VehicleReport, clock_t_s: float | None) -> None:
        self._write(
            {
                "kind": "status",
                "vehicle": vehicle,
                "t_s": report.t_s,
                "east_m": _number(report.east_m),
                "north_m": _number(report.north_m),
                "course_rad": _number(report.course_rad),
                "speed_m_s": _number(report.speed_m_s),
                "link_ok": report.link_ok,
                "healthy": report.healthy,
                "clock_t_s": _clock(clock_t_s),
            }
        )

    def local(self, vehicle: int, t_s: float, clock_t_s: float | None) -> None:
        self._write(
            {"kind": "local", "vehicle": vehicle, "t_s": t_s, "clock_t_s": _clock(clock_t_s)}
        )
