"""``standoff simulate SCENARIO``: the fast numerical simulation (paper section 5.1 and beyond)."""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from app.errors import ConfigError

if TYPE_CHECKING:
    from app.config.scenario import ScenarioConfig
    from app.core.sampled_run import SimulationResult
    from app.runtime.fastsim import SimulationSetup

ORDER = 40


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help="fast numerical simulation of a scenario (paper section 5.1)",
        description=(
            "Run a scenario (a name in configs/, e.g. sim-a, sim-b, phase, phase-gather, or a "
            "path to a TOML file) with the eq. (2) vehicle model, print the figures of merit and "
            "write track.csv and PNG plots into --out."
        ),
    )
    parser.add_argument("scenario", metavar="SCENARIO", help="scenario name or TOML path")
    parser.add_argument("--out", type=Path, default=None, help="folder for track.csv and PNGs")
    parser.add_argument(
        "--law",
        choices=("proposed", "frew", "fixed"),
        default=None,
        help="guidance field: proposed (optimal c + inverse field), frew (c = 2), fixed (--c)",
    )
    parser.add_argument("--c", type=float, default=None, help="c for --law fixed")
    parser.add_argument(
        "--phase-law", choices=("paper", "frew", "none"), default=None, help="phase controller"
    )
    parser.add_argument("--phase-gain", type=float, default=None, help="k of eq. (24), 1/s")
    parser.add_argument(
        "--predictive-phase",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="steer on the phase each vehicle will have on the circle (default: scenario's)",
    )
    parser.add_argument(
        "--feed-forward",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="lag-compensated course command (--no-feed-forward: the paper's literal loop)",
    )
    parser.add_argument("--dt", type=float, default=None, help="step, s (default 0.01)")
    parser.add_argument("--k", type=float, default=None, help="course gain k of eq. (2), 1/s")
    parser.add_argument("--duration", type=float, default=None, help="run length, s")
    parser.add_argument(
        "--compare",
        action="store_true",
        help="also run Frew's field (c = 2) and overlay it in the standoff plot",
    )
    parser.add_argument(
        "--track-every", type=float, default=0.1, help="track.csv sample interval, s"
    )
    parser.set_defaults(handler=run)


def _positive(name: str, value: float | None) -> None:
    if value is not None and not (math.isfinite(value) and value > 0.0):
        raise ConfigError(f"{name} must be a finite number > 0, got {value}")


def scenario_with_overrides(args: argparse.Namespace) -> ScenarioConfig:
    """The scenario file with the command line's overrides applied (validated again)."""
    from app.config import load_config
    from app.config.scenario import ScenarioConfig

    for name in ("c", "dt", "k", "duration", "track_every"):
        _positive(f"--{name.replace('_', '-')}", getattr(args, name))
    if args.phase_gain is not None and not (
        math.isfinite(args.phase_gain) and args.phase_gain >= 0
    ):
        raise ConfigError(f"--phase-gain must be a finite number >= 0, got {args.phase_gain}")
    scenario = load_config(args.scenario, ScenarioConfig)
    guidance = scenario.guidance
    if args.law is not None:
        guidance = guidance.model_copy(update={"law": args.law})
    if args.c is not None:
        guidance = guidance.model_copy(update={"c": args.c})
    if args.feed_forward is not None:
        guidance = guidance.model_copy(update={"feed_forward": args.feed_forward})
    if guidance.law == "fixed" and guidance.c is None:
        raise ConfigError("--law fixed needs --c")
    phase = scenario.phase
    if args.phase_law is not None:
        phase = phase.model_copy(update={"law": args.phase_law})
    if args.phase_gain is not None:
        phase = phase.model_copy(update={"gain_per_s": args.phase_gain})
    if args.predictive_phase is not None:
        phase = phase.model_copy(update={"predictive": args.predictive_phase})
    limits = scenario.limits
    if args.k is not None:
        limits = limits.model_copy(update={"course_gain_per_s": args.k})
    update: dict[str, object] = {"guidance": guidance, "phase": phase, "limits": limits}
    if args.dt is not None:
        update["dt_s"] = args.dt
    if args.duration is not None:
        update["duration_s"] = args.duration
    return scenario.model_copy(update=update)


def _fmt_s(value: float) -> str:
    return "never" if math.isinf(value) else f"{value:.2f} s"


def _describe(scenario: ScenarioConfig) -> str:
    g = scenario.guidance
    law = g.law if g.law != "fixed" else f"fixed c={g.c}"
    ff = "feed-forward" if g.feed_forward else "no feed-forward"
    text = f"law {law}, {ff}, k {scenario.limits.course_gain_per_s}, dt {scenario.dt_s} s"
    if len(scenario.vehicles) > 1:
        p = scenario.phase
        text += f", phase {p.law} gain {p.gain_per_s}{' predictive' if p.predictive else ''}"
    return text


def run(args: argparse.Namespace) -> int:
    from app.config.scenario import build_setup
    from app.runtime.fastsim import (
        phase_figures,
        phase_lower_bound_s,
        run_simulation,
        standoff_figures,
    )

    scenario = scenario_with_overrides(args)
    try:
        setup = build_setup(scenario)
    except ValueError as exc:
        raise ConfigError(f"{args.scenario}: {exc}") from exc
    started = time.process_time()
    result = run_simulation(setup)
    compute_s = time.process_time() - started
    name = Path(args.scenario).stem
    print(f"{name}: {scenario.description or 'scenario'}")
    print(f"  {_describe(scenario)}; {len(setup.starts)} vehicle(s), {setup.duration_s:g} s")
    print(f"  compute time: {compute_s:.2f} s")
    figures = standoff_figures(result)
    print(f"  settle time (|r - r_d| < 3 m to the end): {_fmt_s(figures.settle_s)}")
    print(f"  minimum distance error r - r_d: {figures.min_distance_error_m:.2f} m")
    print(f"  circle crossings (deeper than 0.5 m): {figures.crossings}")
    print(f"  peak course rate: {figures.peak_course_rate_rad_s:.3f} rad/s")
    inverse_events = sum(1 for _, e in result.events if e.kind == "inverse-field-on")
    if inverse_events:
        print(f"  inverse field used: {inverse_events} time(s)")
    results: dict[str, SimulationResult] = {_label(scenario): result}
    if args.compare and scenario.guidance.law != "frew":
        frew = run_simulation(_with_law(setup, "frew"))
        fig = standoff_figures(frew)
        print(
            f"  Frew's field (c = 2) for comparison: settle {_fmt_s(fig.settle_s)}, "
            f"min error {fig.min_distance_error_m:.2f} m, crossings {fig.crossings}"
        )
        results["Frew (c = 2)"] = frew
    if len(setup.starts) > 1:
        ph = phase_figures(result)
        print(f"  phase spacing within 2 deg of 360/n for good: {_fmt_s(ph.settle_s)}")
        bound = phase_lower_bound_s(setup)
        on_circle = bool((abs(result.distance_error_m()[0]) < 3.0).all())
        kind = "lower bound" if on_circle else "estimate (fixed cruise paths)"
        print(f"  speed-limited {kind} for that: {bound:.1f} s")
        print(
            f"  speeds {ph.min_speed_m_s:.2f}..{ph.max_speed_m_s:.2f} m/s, "
            f"max |acceleration| {ph.max_abs_accel_m_s2:.2f} m/s^2"
        )
    if args.out is not None:
        _write_outputs(args.out, name, result, results, args.track_every)
    return 0


def _label(scenario: ScenarioConfig) -> str:
    g = scenario.guidance
    if g.law == "proposed":
        return "proposed (optimal c, ILVF)"
    if g.law == "frew":
        return "Frew (c = 2)"
    return f"fixed c = {g.c}"


def _with_law(setup: SimulationSetup, law: str) -> SimulationSetup:
    agents = tuple(
        replace(a, guidance=replace(a.guidance, law=law, inverse_field=None))  # type: ignore[arg-type]
        for a in setup.agents
    )
    return replace(setup, agents=agents)


def _write_outputs(
    out: Path,
    name: str,
    result: SimulationResult,
    results: dict[str, SimulationResult],
    track_every_s: float,
) -> None:
    from app.report.simulation_plots import plot_phase, plot_standoff
    from app.report.track import (
        SIMULATION_EXTRA_COLUMNS,
        simulation_track_rows,
        write_track_csv,
    )

    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {out}: cannot create: {exc}") from exc
    rows = simulation_track_rows(result, track_every_s)
    write_track_csv(out / "track.csv", rows, SIMULATION_EXTRA_COLUMNS)
    written = [out / "track.csv"]
    written.append(plot_standoff(results, out / "standoff.png", f"{name}: distance keeping"))
    if result.n_vehicles > 1:
        written.append(plot_phase(result, out / "phase.png", f"{name}: phase keeping"))
    print("  wrote " + ", ".join(str(p) for p in written))
