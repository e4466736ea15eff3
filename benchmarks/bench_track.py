"""The mission's track stage, paper guidance against the planned orbit, in the mission fast-sim.

Run:  .venv/bin/python -m benchmarks.bench_track [CONFIG] [--seeds 1 2 3] [--latency-ticks 1]

Flies the whole mission (``app.runtime.mission_fastsim``: IMM-UKF per vehicle on a seeded
sigma^2 = 10 m^2 camera, the ground's fusion fed back, stages, 10 Hz control) once with the
track stage on the mission's own guidance (the paper's: optimal c, the field to the circle r_d,
the eq. 15 correction), on the planned orbit (``orbit_plan="ellipse"``), and on the planned
orbit with c = 2 (law ``frew``), with the same seeds, and prints per track segment the RMS and
max |distance error| (m) and |spacing error| (deg) of the team against the true target, with
ratios against the paper's. With several seeds
the figures are the mean over the seeds. Also prints the gather + adjust time and checks that
every command was finite and within the speed and course-rate limits.
"""

import argparse
import math
import time
from dataclasses import replace
from typing import Any

import numpy as np

from app.config import load_config
from app.core.agent import AgentParams
from app.mission_config import MissionConfig
from app.runtime.mission import MissionPlan, build_plan
from app.runtime.mission_fastsim import MissionSimSetup, run_mission_sim, track_figures

KEYS = ("dist_rms_m", "dist_max_m", "spacing_rms_deg", "spacing_max_deg")


def track_params(plan: MissionPlan, **guidance: Any) -> tuple[AgentParams, ...]:
    """The mission's track-stage parameters with some guidance fields replaced."""
    out = []
    for a in plan.agents:
        track = a.track if a.track is not None else a.agent
        out.append(replace(track, guidance=replace(track.guidance, **guidance)))
    return tuple(out)


def fly(plan: MissionPlan, track: tuple[AgentParams, ...], seed: int, latency: int) -> dict:
    t0 = time.process_time()
    result = run_mission_sim(
        MissionSimSetup(plan, seed=seed, latency_ticks=latency, track_override=track)
    )
    cpu = time.process_time() - t0
    lim = plan.config.limits
    cmd = result.commands
    ok = bool(
        np.isfinite(cmd).all()
        and (cmd[:, 3] >= lim.min_speed_m_s - 1e-9).all()
        and (cmd[:, 3] <= lim.max_speed_m_s + 1e-9).all()
        and (np.abs(cmd[:, 4]) <= lim.max_course_rate_rad_s + 1e-9).all()
    )
    return {
        "figures": track_figures(result, plan.target.labels),
        "formation_s": result.summary["convergence"]["time_to_formation_s"],
        "commands_ok": ok,
        "cpu_s": cpu,
    }


def mean_figures(runs: list[dict], labels: tuple[str, ...]) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for label in labels:
        rows = [r["figures"][label] for r in runs if label in r["figures"]]
        if rows:
            out[label] = {k: float(np.mean([row.get(k, math.nan) for row in rows])) for k in KEYS}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="hil")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--latency-ticks", type=int, default=0)
    args = parser.parse_args()
    plan = build_plan(load_config(args.config, MissionConfig))
    labels = tuple(plan.target.labels)
    variants = {
        "paper": track_params(plan),
        "planned": track_params(plan, orbit_plan="ellipse"),
        "planned,c=2": track_params(plan, orbit_plan="ellipse", law="frew"),
    }
    runs = {
        name: [fly(plan, track, s, args.latency_ticks) for s in args.seeds]
        for name, track in variants.items()
    }
    figures = {name: mean_figures(rs, labels) for name, rs in runs.items()}
    print(
        f"mission fast-sim '{plan.config.name}', seeds {args.seeds}, latency "
        f"{args.latency_ticks} tick(s). Track stage: paper = the mission's law (optimal c, the "
        "circle, eq. 15); planned = the planned orbit (orbit_plan='ellipse'); planned,c=2 = the "
        "same with c = 2 (law 'frew'). Ratios against paper."
    )
    names = list(variants)
    header = f"{'segment':8s} {'figure':16s} " + " ".join(f"{n:>12s}" for n in names)
    header += " " + " ".join(f"{'ratio ' + n:>18s}" for n in names[1:])
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
                + " ".join(f"{v:12.2f}" for v in vals)
                + " "
                + " ".join(f"{r:18.2f}" for r in ratios)
            )
    for name in names:
        rs = runs[name]
        print(
            f"{name:12s}: gather + adjust {[r['formation_s'] for r in rs]} s; commands finite and "
            f"within limits: {all(r['commands_ok'] for r in rs)}; "
            f"cpu {np.mean([r['cpu_s'] for r in rs]):.1f} s/run"
        )


if __name__ == "__main__":
    main()
