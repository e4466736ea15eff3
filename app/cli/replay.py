"""``standoff replay RUN_DIR``: re-run a flown mission's estimation and stage logic from its
run folder (``app.report.replay``) and set the figures beside the run's."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from app.report.replay import ReplayResult

ORDER = 60
#: figures closer than this (relative) to the run's are the same
DEFAULT_TOLERANCE = 1e-6


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "replay",
        help="re-run a flown mission's estimation and stages from its run folder",
        description=(
            "Re-run the local IMM-UKF filters, the federated fusion and the stage logic of a "
            "flown mission on what its agents and ground station were fed (the run folder's "
            "observations.jsonl and config.json), without flying, and print its figures beside "
            "the run's (summary.json, events.jsonl). With --estimator, replay the flight with "
            "another estimator file."
        ),
    )
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a run folder of standoff fly")
    p.add_argument(
        "--estimator",
        metavar="NAME|PATH",
        help="estimator file to replay with (default: the one the run flew, from config.json)",
    )
    p.add_argument(
        "--plots",
        type=Path,
        metavar="DIR",
        help="also draw the replayed run's figures (PNG) into DIR",
    )
    p.add_argument(
        "--tolerance",
        type=float,
        default=DEFAULT_TOLERANCE,
        help="relative difference below which a figure is the run's "
        f"(default {DEFAULT_TOLERANCE:g})",
    )
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    import time

    from app.cli.fly import report
    from app.config.estimator import EstimatorConfig
    from app.config.loading import load_config
    from app.errors import InputError
    from app.report import replay as rp
    from app.report.run_folder import SUMMARY_FILE, read_json, read_run_config, run_title

    run_dir: Path = args.run_dir
    if not run_dir.is_dir():
        raise InputError(f"{run_dir}: not a folder")
    if not (args.tolerance >= 0.0):
        raise InputError(f"--tolerance must be >= 0, got {args.tolerance}")
    mission, estimator = read_run_config(run_dir)
    if args.estimator is not None:
        estimator = load_config(args.estimator, EstimatorConfig)
    plan = rp.replay_plan(mission, estimator)
    recording = rp.read_run_recording(run_dir)
    started = time.perf_counter()
    result = rp.replay(plan, recording)
    elapsed = time.perf_counter() - started
    flown = read_json(run_dir / SUMMARY_FILE)
    events = run_dir / "events.jsonl"
    flown_stages = rp.recorded_stages(events) if events.exists() else None

    print(
        f"standoff replay: {run_dir} ({mission.name}, {plan.count} vehicles): "
        + ", ".join(f"{n} {kind}" for kind, n in result.fed.items())
        + f" records in {elapsed:.1f} s"
    )
    for kind, n in result.unmatched.items():
        if n:
            print(f"warning: {n} {kind} estimate(s) named by the recording were not produced")
    print(f"stages, run:    {_stages(flown_stages) if flown_stages is not None else '-'}")
    print(f"stages, replay: {_stages(result.stages)}")
    # standoff fly's report but its first line (the run's wall time: the replay's is above)
    print("\n".join(report(_as_run_summary(result, elapsed)).splitlines()[1:]))
    print(_comparison(rp.figures(flown), rp.figures(result.summary), args.tolerance))
    same_stages = flown_stages is not None and rp.stage_names(flown_stages) == rp.stage_names(
        result.stages
    )
    differ = rp.same_figures(rp.figures(flown), rp.figures(result.summary), args.tolerance)
    verdict = "the same" if not differ and same_stages else "different"
    print(
        f"replay vs run: stages {'the same' if same_stages else 'different'}, "
        f"figures {'the same' if not differ else f'different in {len(differ)}'} "
        f"(tolerance {args.tolerance:g}): {verdict}"
    )
    if args.plots is not None:
        from app.report.mission_plots import plot_mission

        written = plot_mission(
            result.samples,
            plan.config.radius_m,
            args.plots,
            title=f"{run_title(run_dir, mission.name)}, replayed",
        )
        print("figures: " + ", ".join(str(p) for p in written))
    return 0


def _stages(stages: list[tuple[float, str]]) -> str:
    if not stages:
        return "(none)"
    return " -> ".join(f"{s} {t:.1f} s" for t, s in stages)


def _as_run_summary(result: ReplayResult, elapsed_s: float) -> dict[str, Any]:
    """The replay's figures with the fields ``standoff fly``'s report prints: the time it took
    (wall) and the last sample's mission time."""
    last = result.samples[-1].t_s if result.samples else None
    return {**result.summary, "wall_s": elapsed_s, "mission_t_s": last}


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def _comparison(
    run: dict[str, float | None], replayed: dict[str, float | None], tolerance: float
) -> str:
    """The figures, run and replay side by side; '*' marks those that differ."""
    from app.report.replay import same_figures

    differ = set(same_figures(run, replayed, tolerance))
    names = list(dict.fromkeys([*run, *replayed]))
    width = max((len(n) for n in names), default=10)
    lines = [f"{'figure':<{width}}  {'run':>10}  {'replay':>10}"]
    for name in names:
        mark = " *" if name in differ else ""
        lines.append(
            f"{name:<{width}}  {_fmt(run.get(name)):>10}  {_fmt(replayed.get(name)):>10}{mark}"
        )
    return "\n".join(lines)
