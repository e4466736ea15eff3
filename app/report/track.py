"""The track file (design.md section 6): one CSV row per vehicle per sample.

Columns: ``t_s,vehicle,east_m,north_m,course_rad,speed_m_s,target_east_m,target_north_m``, then
any extra columns the writer is given. Used by ``standoff simulate`` and by the mission's run
folder, so it takes plain rows, not a simulation result.
"""

import csv
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.sampled_run import SimulationResult

TRACK_COLUMNS = (
    "t_s",
    "vehicle",
    "east_m",
    "north_m",
    "course_rad",
    "speed_m_s",
    "target_east_m",
    "target_north_m",
)


@dataclass(frozen=True, slots=True)
class TrackRow:
    """One vehicle at one time: m east/north of the origin, course rad clockwise from north, m/s;
    ``extras`` line up with the writer's ``extra_columns`` (numbers, or words such as a stage)."""

    t_s: float
    vehicle: int
    east_m: float
    north_m: float
    course_rad: float
    speed_m_s: float
    target_east_m: float
    target_north_m: float
    extras: tuple[float | str, ...] = ()


def _fmt(value: float) -> str:
    return (
        "nan"
        if not math.isfinite(value)
        else f"{value:.6g}"
        if abs(value) < 1e-3
        else (f"{value:.4f}")
    )


def write_track_csv(
    path: str | Path, rows: Iterable[TrackRow], extra_columns: Sequence[str] = ()
) -> int:
    """Write rows to ``path`` (parent folders created); return the number of rows written.

    Raises ``ValueError`` if a row's extras do not match ``extra_columns``.
    """
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    count = 0
    with out.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow((*TRACK_COLUMNS, *extra_columns))
        for row in rows:
            if len(row.extras) != len(extra_columns):
                raise ValueError(
                    f"track row has {len(row.extras)} extras for {len(extra_columns)} columns"
                )
            writer.writerow(
                (
                    f"{row.t_s:.3f}",
                    row.vehicle,
                    _fmt(row.east_m),
                    _fmt(row.north_m),
                    f"{row.course_rad:.5f}",
                    f"{row.speed_m_s:.3f}",
                    _fmt(row.target_east_m),
                    _fmt(row.target_north_m),
                    *(x if isinstance(x, str) else _fmt(x) for x in row.extras),
                )
            )
            count += 1
    return count


SIMULATION_EXTRA_COLUMNS = ("course_rate_rad_s", "distance_error_m", "c", "inverse_field")


def simulation_track_rows(result: SimulationResult, every_s: float = 0.1) -> list[TrackRow]:
    """Rows of a fast-simulation result, one sample every ``every_s`` (at least every step),
    with the extra columns ``SIMULATION_EXTRA_COLUMNS``."""
    dt = float(result.t_s[1] - result.t_s[0]) if result.t_s.size > 1 else every_s
    stride = max(1, round(every_s / dt))
    error = result.distance_error_m()
    rows: list[TrackRow] = []
    for j in np.arange(0, result.t_s.size, stride):
        for i in range(result.n_vehicles):
            rows.append(
                TrackRow(
                    float(result.t_s[j]),
                    i + 1,  # numbered as users read them (as the plots and the tlogs)
                    float(result.east_m[j, i]),
                    float(result.north_m[j, i]),
                    float(result.course_rad[j, i]),
                    float(result.speed_m_s[j, i]),
                    float(result.target_east_m[j]),
                    float(result.target_north_m[j]),
                    (
                        float(result.course_rate_rad_s[j, i]),
                        float(error[j, i]),
                        float(result.c[j, i]),
                        1.0 if result.inverse[j, i] else 0.0,
                    ),
                )
            )
    return rows
