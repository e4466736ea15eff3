"""``standoff plot RUN_DIR``: re-draw a run folder's figures from its files, without flying."""

from __future__ import annotations

import argparse
from pathlib import Path

ORDER = 62


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "plot",
        help="re-draw a run folder's figures (PNG) from its files",
        description=(
            "Re-draw a run folder's figures (trajectories.png, distance_error.png, "
            "phase_difference.png, estimate_error.png) from its track.csv and config.json, "
            "without flying."
        ),
    )
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a run folder of standoff fly")
    p.add_argument("--out", type=Path, metavar="DIR", help="where to write them (default: RUN_DIR)")
    p.add_argument(
        "--radius-m",
        type=float,
        help="the standoff radius (default: config.json's; needed for folders without one)",
    )
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    import math

    from app.errors import InputError
    from app.report.mission_plots import plot_mission
    from app.report.run_folder import (
        CONFIG_FILE,
        SUMMARY_FILE,
        TRACK_FILE,
        read_run_config,
        read_track_samples,
        run_title,
    )

    run_dir: Path = args.run_dir
    if not run_dir.is_dir():
        raise InputError(f"{run_dir}: not a folder")
    title = run_title(run_dir, "")
    radius_m = args.radius_m
    if radius_m is None:
        if not (run_dir / CONFIG_FILE).exists() and not (run_dir / SUMMARY_FILE).exists():
            raise InputError(f"{run_dir}: no {CONFIG_FILE} (an older run folder): give --radius-m")
        mission, _ = read_run_config(run_dir)
        radius_m = mission.radius_m
        title = run_title(run_dir, mission.name)
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        raise InputError(f"--radius-m must be a positive number, got {radius_m}")
    samples = read_track_samples(run_dir / TRACK_FILE)
    written = plot_mission(samples, radius_m, args.out or run_dir, title=title)
    if not written:
        raise InputError(f"{run_dir / TRACK_FILE}: no samples after standby: nothing to draw")
    for path in written:
        print(path)
    return 0
