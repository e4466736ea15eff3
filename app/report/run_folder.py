"""A mission's run folder: ``summary.json``, ``track.csv`` (with its stage) and the figures."""

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from app.core.mission.team import TeamSample
from app.report.summary import summarize
from app.report.track import TrackRow, write_track_csv

TRACK_EXTRA_COLUMNS = ("active", "estimate_east_m", "estimate_north_m", "stage")


def write_run_folder(
    out_dir: Path,
    samples: Sequence[TeamSample],
    *,
    radius_m: float,
    tracking_command_s: float,
    radius_tolerance_m: float,
    spacing_tolerance_rad: float,
    extra: Mapping[str, Any],
) -> dict[str, Any]:
    """Score ``samples`` (``summarize``), add ``extra`` (the run's own figures: counters, times),
    write the folder and return the summary. The figures (matplotlib) only when there are
    samples."""
    summary = summarize(
        samples, radius_m, tracking_command_s, radius_tolerance_m, spacing_tolerance_rad
    )
    summary.update(extra)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    nan = math.nan
    rows = [
        TrackRow(
            s.t_s,
            v.vehicle,
            v.east_m,
            v.north_m,
            v.course_rad,
            v.speed_m_s,
            s.target_east_m,
            s.target_north_m,
            (
                float(v.active),
                *(s.estimate[:2] if s.estimate is not None else (nan, nan)),
                s.stage,
            ),
        )
        for s in samples
        for v in s.vehicles
    ]
    write_track_csv(out_dir / "track.csv", rows, extra_columns=TRACK_EXTRA_COLUMNS)
    if samples:
        from app.report.mission_plots import plot_mission  # matplotlib: 0.45 s, at the end only

        plot_mission(samples, radius_m, out_dir)
    return summary
