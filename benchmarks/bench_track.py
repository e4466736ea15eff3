"""The mission's track stage: the paper's guidance against this project's, in the mission fast-sim.

Run:  .venv/bin/python -m benchmarks.bench_track [CONFIG] [--seeds 1 2 3] [--latency-ticks 1]
      [--vary-command S] [--truth]

Flies the whole mission (``app.compose.mission_fastsim``: IMM-UKF per vehicle on a seeded
sigma^2 = 10 m^2 camera, the ground's fusion fed back, stages, 10 Hz control), with commands
acting ``--latency-ticks`` control periods (0.1 s) late, once per variant of the track stage,
all on the same seeds:

- paper: the approach's law (optimal c, the circle r_d, the eq. 15 correction), no
  compensation of the delay;
- planned: the planned orbit (``orbit_plan="ellipse"``) at c = 2 (law ``frew``), the mission's
  default track stage before the two below;
- +cap: planned, with the ground speed capped where the orbit needs more turn rate than the
  vehicle has (``speed_cap``);
- +latency: planned, the agents steering on the state predicted for the middle of each
  command's 0.1 s hold, ``--latency-ticks`` * 0.1 s late (``latency_s``, ``hold_s``);
- +both: planned with the cap and the latency compensation;
- +slow: +latency with a long turn flown slow (``GuidanceParams.turn_slow_rad`` from the
  config, ``[guidance] track_turn_slow_deg``: the ground speed capped on a ramp of the course
  error down to the minimum), the mission's default track stage before ``track_c``; the
  variants above have it off (every variant keeps the config's track phase gain);
- config: the track stage as the config has it (for ``hil``: +slow flown with c = 1.2,
  ``[guidance] track_law = "fixed"``, ``track_c``);
- with ``--horizon``, also +horizon: +latency with the receding-horizon planner
  (``planner="horizon"``, ``app.core.guidance.horizon``: the team's course rates and speeds
  planned 40 s ahead on the estimate every 2 s), printed with the agents' CPU per run;
- with ``--lead-speed V``, also +lead: +latency with gather and adjust led at V m/s
  (``PhaseParams.lead_speed_m_s``: the vehicle furthest behind its seat flies V, the others
  slower by the phase law), which changes the formation time and the state the track starts in;
- with ``--truth``, also +truth: +latency with every agent steering on the true target
  (``MissionSimSetup.truth_fed``), what guidance and phase keeping give with perfect knowledge
  of the target, which separates their share of the errors from the estimation's.

``--vary-command S`` makes seed k also give the tracking command k * S seconds later, so the
team meets the target's turns in another configuration each time (which vehicle is where, at
what speed, how far off), as timing does from one live run to the next; the figures after a
turn depend on that far more than on the camera noise the seed draws.

Prints per track segment the RMS and max |distance error| (m) and |spacing error| (deg) of the
team against the true target, the time from the segment's start until every vehicle stays within
3 m of the circle (settle_s) and the RMS distance error from then on, with ratios against the
paper's (the mean over the seeds; a seed that never settles counts as NaN), the
gather + adjust time, whether every command was finite and within the speed limits, and the
largest course rate a command asked of the vehicle when it acted, over the limit (at most 1 but
for the latency compensation's prediction error, a few tenths of a per cent).
"""

import argparse
import math
import time
from dataclasses import replace
from typing import Any

import numpy as np

from app.compose.mission_fastsim import MissionSimSetup, run_mission_sim, track_figures
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import MissionPlan, build_plan

HOLD_S = 0.1  # the control period: each command acts for one


def _seconds(value: float | None) -> float | str:
    """A time for the table, or "never" for a team that never formed."""
    return "never" if value is None else round(value, 1)


KEYS = (
    "dist_rms_m",
    "dist_max_m",
    "spacing_rms_deg",
    "spacing_max_deg",
    "settle_s",
    "settled_dist_rms_m",
)


def variant(
    plan: MissionPlan, latency_s: float = 0.0, hold_s: float = 0.0, **guidance: Any
) -> MissionPlan:
    """The plan with the track stage's guidance fields replaced and the agents' latency
    compensation set (both 0: none)."""
    agents = []
    for a in plan.agents:
        track = a.track if a.track is not None else a.agent
        track = replace(track, guidance=replace(track.guidance, **guidance))
        agents.append(replace(a, track=track, latency_s=latency_s, hold_s=hold_s))
    return replace(plan, agents=tuple(agents))


def fly(plan: MissionPlan, seed: int, latency: int, truth_fed: bool = False) -> dict:
    t0 = time.process_time()
    setup = MissionSimSetup(plan, seed=seed, latency_ticks=latency, truth_fed=truth_fed)
    result = run_mission_sim(setup)
    cpu = time.process_time() - t0
    lim = plan.config.limits
    cmd = result.commands
    ok = bool(
        np.isfinite(cmd).all()
        and (cmd[:, 3] >= lim.min_speed_m_s - 1e-9).all()
        and (cmd[:, 3] <= lim.max_speed_m_s + 1e-9).all()
    )
    # the course rate each command asks of the vehicle when it acts, over the limit
    rate_ratio = float(np.abs(cmd[:, 4]).max() / lim.max_course_rate_rad_s)
    return {
        "figures": track_figures(result, plan.target.labels),
        "formation_s": result.summary["convergence"]["time_to_formation_s"],
        "commands_ok": ok,
        "rate_ratio": rate_ratio,
        "cpu_s": cpu,
    }


def mean_figures(runs: list[dict], labels: tuple[str, ...]) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for label in labels:
        rows = [r["figures"][label] for r in runs if label in r["figures"]]
        if rows:
            out[label] = {k: float(np.mean([row.get(k, math.nan) for row in rows])) for k in KEYS}
    return out


def with_lead_speed(plan: MissionPlan, lead_speed_m_s: float) -> MissionPlan:
    """The plan with gather's and adjust's phase keeping led at ``lead_speed_m_s``
    (``PhaseParams.lead_speed_m_s``, config ``phase.gather_lead_speed_m_s``)."""
    agents = tuple(
        replace(
            a, agent=replace(a.agent, phase=replace(a.agent.phase, lead_speed_m_s=lead_speed_m_s))
        )
        for a in plan.agents
    )
    return replace(plan, agents=agents)


def variants(
    plan: MissionPlan, lag: float, horizon: bool = False, lead_speed_m_s: float | None = None
) -> dict[str, MissionPlan]:
    base = plan.agents[0].agent.guidance
    track = plan.agents[0].track
    slow = None if track is None else track.guidance.turn_slow_rad
    planned: dict[str, Any] = {
        "law": "frew",
        "orbit_plan": "ellipse",
        "speed_cap": False,
        "turn_slow_rad": None,
    }
    off: dict[str, Any] = {"speed_cap": False, "turn_slow_rad": None}
    out = {
        "paper": variant(plan, law=base.law, orbit_plan="circle", **off),
        "planned": variant(plan, **planned),
        "+cap": variant(plan, **(planned | {"speed_cap": True})),
        "+latency": variant(plan, lag, HOLD_S, **planned),
        "+both": variant(plan, lag, HOLD_S, **(planned | {"speed_cap": True})),
    }
    if slow is not None:
        out["+slow"] = variant(plan, lag, HOLD_S, **(planned | {"turn_slow_rad": slow}))
    out["config"] = variant(plan, lag, HOLD_S)
    if horizon:
        out["+horizon"] = variant(plan, lag, HOLD_S, **(planned | {"planner": "horizon"}))
    if lead_speed_m_s is not None:
        out["+lead"] = with_lead_speed(out["+latency"], lead_speed_m_s)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="hil")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--latency-ticks", type=int, default=0)
    parser.add_argument(
        "--truth", action="store_true", help="also fly +latency with the true target (+truth)"
    )
    parser.add_argument(
        "--horizon", action="store_true", help="also fly +latency with the receding horizon"
    )
    parser.add_argument(
        "--lead-speed",
        type=float,
        metavar="V",
        help="also fly +latency with gather and adjust led at V m/s (+lead)",
    )
    parser.add_argument(
        "--vary-command",
        type=float,
        default=0.0,
        metavar="S",
        help="seed k also moves the tracking command k * S seconds later (default 0)",
    )
    args = parser.parse_args()
    config = load_config(args.config, MissionConfig)
    labels = tuple(build_plan(config).target.labels)
    lag = 0.1 * args.latency_ticks
    runs: dict[str, list[dict]] = {}
    for seed in args.seeds:
        moved = config.model_copy(
            update={"tracking_command_s": config.tracking_command_s + args.vary_command * seed}
        )
        plans = variants(build_plan(moved), lag, args.horizon, args.lead_speed)
        for name, p in plans.items():
            runs.setdefault(name, []).append(fly(p, seed, args.latency_ticks))
        if args.truth:
            truth = fly(plans["+latency"], seed, args.latency_ticks, truth_fed=True)
            runs.setdefault("+truth", []).append(truth)
    figures = {name: mean_figures(rs, labels) for name, rs in runs.items()}
    print(
        f"mission fast-sim '{config.name}', seeds {args.seeds} (tracking command moved "
        f"{args.vary_command:g} s per seed), latency "
        f"{args.latency_ticks} tick(s), compensated (latency {lag:.2f} s, hold {HOLD_S} s) in "
        "+latency and +both "
        "(see the module docstring for the variants). Ratios against paper."
    )
    names = list(runs)
    header = f"{'segment':8s} {'figure':16s} " + " ".join(f"{n:>9s}" for n in names)
    header += "  ratios: " + " ".join(f"{n:>9s}" for n in names[1:])
    print(header)
    print("-" * len(header))
    for label in labels:
        if any(label not in figures[n] for n in names):
            continue
        for key in KEYS:
            vals = [figures[n][label][key] for n in names]
            ratios = [v / vals[0] if vals[0] > 0 else math.nan for v in vals[1:]]
            print(
                f"{label:8s} {key:16s} "
                + " ".join(f"{v:9.2f}" for v in vals)
                + "          "
                + " ".join(f"{r:9.2f}" for r in ratios)
            )
    for name in names:
        rs = runs[name]
        print(
            f"{name:12s}: gather + adjust {[_seconds(r['formation_s']) for r in rs]} s; commands "
            f"finite, speeds within limits: {all(r['commands_ok'] for r in rs)}; largest "
            f"course rate asked / limit {max(r['rate_ratio'] for r in rs):.4f}; "
            f"cpu {np.mean([r['cpu_s'] for r in rs]):.1f} s/run"
        )


if __name__ == "__main__":
    main()
