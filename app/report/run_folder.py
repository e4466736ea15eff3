"""A mission's run folder: ``summary.json``, ``track.csv`` (with its stage), ``config.json``
(the resolved mission and estimator files) and the figures; and reading them back
(``standoff plot``, ``standoff replay``).

The folder also holds ``events.jsonl``, one ``vehicle-N.tlog`` per vehicle and
``observations.jsonl`` (``app.adapters.observations_log``), written while the mission flies.
"""

import csv
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.core.mission.team import TeamSample, VehicleSample
from app.errors import InputError
from app.report.summary import summarize
from app.report.track import TrackRow, write_track_csv

if TYPE_CHECKING:
    from app.config.estimator import EstimatorConfig
    from app.config.mission import MissionConfig

TRACK_EXTRA_COLUMNS = (
    "active",
    "estimate_east_m",
    "estimate_north_m",
    "stage",
    "segment",
    "outage",
    "up_m",
)
CONFIG_FILE = "config.json"
TRACK_FILE = "track.csv"
SUMMARY_FILE = "summary.json"
#: config.json's layout: {"schema": 1, "mission": {...}, "estimator": {...}}
CONFIG_SCHEMA = 1


def write_run_folder(
    out_dir: Path,
    samples: Sequence[TeamSample],
    *,
    radius_m: float,
    tracking_command_s: float,
    radius_tolerance_m: float,
    spacing_tolerance_rad: float,
    extra: Mapping[str, Any],
    title: str = "",
    outages: Sequence[tuple[float, float | None, str]] = (),
) -> dict[str, Any]:
    """Score ``samples`` (``summarize``), add ``extra`` (the run's own figures: counters, times),
    write the folder and return the summary. The figures (matplotlib, headed ``title``, else
    ``run_title``) only when there are samples. ``outages``: (start, end or None, reason) in
    mission time, marked in track.csv's ``outage`` column (``outage_marks``)."""
    summary = summarize(
        samples, radius_m, tracking_command_s, radius_tolerance_m, spacing_tolerance_rad
    )
    summary.update(extra)
    (out_dir / SUMMARY_FILE).write_text(json.dumps(summary, indent=2, default=str) + "\n")
    nan = math.nan
    rows = [
        TrackRow(
            s.t_s,
            v.vehicle + 1,  # numbered as users read them: the MAVLink system id
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
                s.target_segment,
                mark,
                nan if v.up_m is None else v.up_m,
            ),
        )
        for s, mark in zip(samples, outage_marks([s.t_s for s in samples], outages), strict=True)
        for v in s.vehicles
    ]
    write_track_csv(out_dir / TRACK_FILE, rows, extra_columns=TRACK_EXTRA_COLUMNS)
    if samples:
        from app.report.mission_plots import plot_mission  # matplotlib: 0.45 s, at the end only

        mission = extra.get("mission")
        name = title or run_title(out_dir, mission if isinstance(mission, str) else "")
        plot_mission(samples, radius_m, out_dir, title=name)
    return summary


def outage_marks(
    times_s: Sequence[float], outages: Sequence[tuple[float, float | None, str]]
) -> list[str]:
    """Per sample time (ascending), the reason of the outage it borders or falls in ('' for
    none): the last sample before the outage's start, every sample up to its end (None: to the
    end of the run) and the first sample after it. The ground's mission time waits for the
    vehicles' statuses, so an outage leaves a hole in the file: the two marked samples either
    side of it say where it is."""
    marks = [""] * len(times_s)
    for start, end, reason in outages:
        before = [k for k, t in enumerate(times_s) if t < start]
        inside = [k for k, t in enumerate(times_s) if t >= start and (end is None or t <= end)]
        after = [k for k, t in enumerate(times_s) if end is not None and t > end]
        for k in (*before[-1:], *inside, *after[:1]):
            marks[k] = marks[k] or reason
    return marks


def run_title(run_dir: Path, mission: str) -> str:
    """What heads a run's figures: the folder's name, and the mission's when it is not in it."""
    name = run_dir.resolve().name
    return name if not mission or mission in name else f"{name} ({mission})"


def write_run_config(out_dir: Path, config: "MissionConfig") -> Path:
    """``config.json``: the mission file as resolved (every default filled in) and the
    estimator file it names, so that the run can be replayed and re-plotted from its folder."""
    from app.config.estimator import EstimatorConfig
    from app.config.loading import load_config

    estimator = load_config(config.estimator.config, EstimatorConfig)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / CONFIG_FILE
    document = {
        "schema": CONFIG_SCHEMA,
        "mission": config.model_dump(mode="json"),
        "estimator": estimator.model_dump(mode="json"),
    }
    path.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    return path


def read_json(path: Path) -> dict[str, Any]:
    """A run folder's JSON file; ``InputError`` naming the file when it is missing or bad."""
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such file (is {path.parent} a run folder?)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: cannot read: {exc}") from exc
    if not isinstance(document, dict):
        raise InputError(f"{path}: not a JSON object")
    return document


def read_run_config(run_dir: Path) -> tuple["MissionConfig", "EstimatorConfig"]:
    """The mission and estimator configs of a run folder (``config.json``), validated. A
    folder without one but with the mission config in its ``summary.json`` (``run.config``)
    gets that, with the estimator file it names as it is now."""
    from app.config.estimator import EstimatorConfig
    from app.config.loading import load_config, validate_config
    from app.config.mission import MissionConfig

    path = run_dir / CONFIG_FILE
    if not path.exists() and (run_dir / SUMMARY_FILE).exists():
        run = read_json(run_dir / SUMMARY_FILE).get("run")
        raw = run.get("config") if isinstance(run, dict) else None
        if isinstance(raw, dict):
            source = f"{run_dir / SUMMARY_FILE}: run.config"
            mission = validate_config(raw, MissionConfig, source)
            return mission, load_config(mission.estimator.config, EstimatorConfig)
    document = read_json(path)
    if document.get("schema") != CONFIG_SCHEMA or not {"mission", "estimator"} <= set(document):
        raise InputError(f"{path}: not a config.json of schema {CONFIG_SCHEMA}")
    mission = validate_config(document["mission"], MissionConfig, f"{path}: mission")
    estimator = validate_config(document["estimator"], EstimatorConfig, f"{path}: estimator")
    return mission, estimator


def _float(row: Mapping[str, str], name: str, path: Path, line: int) -> float:
    try:
        return float(row[name])
    except (KeyError, TypeError, ValueError):
        raise InputError(
            f"{path}:{line}: column {name!r}: not a number: {row.get(name)!r}"
        ) from None


_TRACK_NEEDS = {"t_s", "vehicle", "east_m", "north_m", "course_rad", "speed_m_s", "stage"}


def _up(row: dict[str, str], path: Path, line: int) -> float | None:
    """The row's height about the origin; None where it has none (older folders, or nan)."""
    if not row.get("up_m"):
        return None
    up = _float(row, "up_m", path, line)
    return up if math.isfinite(up) else None


def read_track_samples(path: Path) -> list[TeamSample]:
    """A run folder's ``track.csv`` back as the ground's samples (one per time). Not in the
    file: the target's velocity (0 here) and the estimate's (0); ``segment`` is '' in folders
    written before it was a column."""
    try:
        handle = path.open(newline="", encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file (is {path.parent} a run folder?)") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc}") from exc
    times: dict[float, list[tuple[dict[str, str], int]]] = {}
    with handle:
        reader = csv.DictReader(handle)
        missing = _TRACK_NEEDS - set(reader.fieldnames or ())
        if missing:
            raise InputError(f"{path}: not a mission track (no {', '.join(sorted(missing))})")
        for line, row in enumerate(reader, start=2):
            times.setdefault(_float(row, "t_s", path, line), []).append((row, line))
    samples = []
    for t, rows in sorted(times.items()):
        first, line = rows[0]
        estimate = None
        if "estimate_east_m" in first:
            e, n = (_float(first, k, path, line) for k in ("estimate_east_m", "estimate_north_m"))
            if math.isfinite(e) and math.isfinite(n):
                estimate = (e, n, 0.0, 0.0)
        vehicles = tuple(
            VehicleSample(
                int(_float(row, "vehicle", path, ln)) - 1,  # the file numbers them from 1
                _float(row, "active", path, ln) > 0.5 if "active" in row else True,
                _float(row, "east_m", path, ln),
                _float(row, "north_m", path, ln),
                _float(row, "speed_m_s", path, ln),
                _float(row, "course_rad", path, ln),
                _up(row, path, ln),
            )
            for row, ln in rows
        )
        samples.append(
            TeamSample(
                t,
                first["stage"],
                first.get("segment") or "",
                _float(first, "target_east_m", path, line),
                _float(first, "target_north_m", path, line),
                0.0,
                0.0,
                estimate,
                vehicles,
            )
        )
    return samples
