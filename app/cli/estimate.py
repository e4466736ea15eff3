"""``standoff estimate``: the federated IMM-UKF estimator on a measurements file, or scenario data.

Composition root of the estimator: reads and validates the estimator config and scenario
configs, builds the core parameters, runs the estimator, writes estimates, prints figures,
draws plots.
"""

from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING

from app.errors import InputError

if TYPE_CHECKING:
    import numpy as np

    from app.core.estimation.local import StepReport
    from app.core.estimation.messages import Observation
    from app.core.estimation.metrics import ErrorSeries
    from app.core.estimation.pipeline import RunResult

ORDER = 50

_log = logging.getLogger(__name__)

_MAX_LOGGED_REJECTIONS = 20


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        "estimate",
        help="run the federated IMM-UKF target estimator on a measurements CSV",
        description=(
            "Estimate the target's position and velocity from the vehicles' position fixes "
            "(one local IMM-UKF per sensor, fused by a federated main filter). Either run on "
            "--measurements, or --generate scenario data to try it."
        ),
    )
    parser.add_argument("--measurements", type=Path, help="CSV t_s,sensor,east_m,north_m[,sigma_m]")
    parser.add_argument("--out", type=Path, help="estimates CSV to write (one row per measurement)")
    parser.add_argument(
        "--truth", type=Path, help="CSV t_s,east_m,north_m,v_east_m_s,v_north_m_s[,segment]"
    )
    parser.add_argument(
        "--config", default="estimator", help="estimator config name or file (default: estimator)"
    )
    parser.add_argument("--plots", type=Path, help="directory for PNG plots (needs --truth)")
    parser.add_argument(
        "--centralised",
        action="store_true",
        help="run one IMM-UKF on every measurement instead of the federated filter",
    )
    parser.add_argument(
        "--generate",
        metavar="SCENARIO",
        help="write measurements.csv and truth.csv of a scenario (est-fig12, est-fig12-sigma10, "
        "est-hil or a file) to --out-dir, then stop",
    )
    parser.add_argument("--seed", type=int, default=1, help="seed for --generate (default 1)")
    parser.add_argument("--out-dir", type=Path, help="directory for --generate")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from app.adapters.estimation_csv import read_measurements, read_truth, write_estimates
    from app.config.estimator import load_estimator
    from app.core.estimation.pipeline import run_centralised, run_federated

    if args.generate is not None:
        return _generate(args)
    if args.measurements is None or args.out is None:
        raise InputError("need --measurements M.csv and --out E.csv (or --generate SCENARIO)")
    if args.plots is not None and args.truth is None:
        raise InputError("--plots needs --truth")
    params = load_estimator(args.config)
    observations = read_measurements(args.measurements)
    truth = read_truth(args.truth) if args.truth is not None else None
    if args.centralised:
        result = run_centralised(observations, params.local)
    else:
        result = run_federated(observations, params)
    _log_rejections(observations, result.reports)
    track = result.fused
    write_estimates(args.out, track.t_s, track.x, track.p)
    _print_counts(observations, result, args.out)
    if truth is not None:
        # scipy.stats only when scored: it doubles the start-up of every other subcommand
        from app.core.estimation.metrics import errors

        series = errors(track.t_s, track.x, truth.t_s, truth.states, truth.segments, track.p)
        _print_errors(series, observations, truth.t_s, truth.states)
        if args.plots is not None:
            from app.report.estimation_plots import plot_estimation  # matplotlib only when asked

            written = plot_estimation(args.plots, observations, truth, track)
            for path in written:
                print(f"plot: {path}")
    return 0


def _generate(args: argparse.Namespace) -> int:
    from app.adapters.estimation_csv import write_measurements, write_truth
    from app.config.scenario import generate_scenario

    if args.out_dir is None:
        raise InputError("--generate needs --out-dir DIR")
    data = generate_scenario(args.generate, args.seed)
    try:
        args.out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{args.out_dir}: cannot create: {exc.strerror or exc}") from exc
    measurements = args.out_dir / "measurements.csv"
    truth = args.out_dir / "truth.csv"
    write_measurements(measurements, data.observations)
    write_truth(truth, data.truth_t_s, data.truth, data.segments)
    print(f"{len(data.observations)} measurements: {measurements}")
    print(f"{len(data.truth_t_s)} truth rows: {truth}")
    print(
        f"try: standoff estimate --measurements {measurements} --truth {truth} "
        f"--out {args.out_dir / 'estimates.csv'} --plots {args.out_dir}"
    )
    return 0


def _log_rejections(observations: list[Observation], reports: tuple[StepReport, ...]) -> None:
    logged = 0
    for obs, report in zip(observations, reports, strict=True):
        if report.reason and report.outcome != "restarted":
            if logged < _MAX_LOGGED_REJECTIONS:
                _log.warning(
                    "measurement t=%s sensor=%s %s: %s",
                    obs.t_s,
                    obs.sensor,
                    report.outcome,
                    report.reason,
                )
            logged += 1
        elif report.outcome == "restarted":
            _log.warning("sensor %s t=%s: %s", obs.sensor, obs.t_s, report.reason)
    if logged > _MAX_LOGGED_REJECTIONS:
        _log.warning("... and %d more rejected measurements", logged - _MAX_LOGGED_REJECTIONS)


def _print_counts(observations: list[Observation], result: RunResult, out: Path) -> None:
    print(f"{len(observations)} measurements, {result.fused.t_s.shape[0]} estimates: {out}")
    for sensor, c in result.counters.items():
        print(
            f"  sensor {sensor}: used {c.updated + c.late_used} (late {c.late_used}), "
            f"stale {c.stale_dropped}, invalid {c.invalid}, gated {c.gated}, "
            f"restarts {c.restarts}"
        )


def _print_errors(
    series: ErrorSeries,
    observations: list[Observation],
    truth_t: np.ndarray,
    truth: np.ndarray,
) -> None:
    raw = _raw_error(observations, truth_t, truth)
    pos, vel = series.rmse()
    print(f"raw measurement position error: {raw:.3f} m RMS")
    print(f"estimate RMSE: position {pos:.3f} m, velocity {vel:.3f} m/s")
    print(f"  {'segment':<20} {'position m':>10} {'velocity m/s':>12} {'n':>7}")
    for label, (p, v, n) in series.per_segment().items():
        print(f"  {label:<20} {p:>10.3f} {v:>12.3f} {n:>7d}")
    turns = series.mask_for("turn")
    if turns.any():
        p, v = series.rmse(turns)
        print(f"  {'(all turns)':<20} {p:>10.3f} {v:>12.3f} {int(turns.sum()):>7d}")


def _raw_error(observations: list[Observation], truth_t: np.ndarray, truth: np.ndarray) -> float:
    import numpy as np

    rows = [
        (o.t_s, o.east_m, o.north_m)
        for o in observations
        if math.isfinite(o.t_s) and truth_t[0] <= o.t_s <= truth_t[-1]
    ]
    if not rows:
        return float("nan")
    arr = np.array(rows)
    arr = arr[np.all(np.isfinite(arr), axis=1)]
    de = arr[:, 1] - np.interp(arr[:, 0], truth_t, truth[:, 0])
    dn = arr[:, 2] - np.interp(arr[:, 0], truth_t, truth[:, 1])
    return float(np.sqrt(np.mean(de * de + dn * dn)))
