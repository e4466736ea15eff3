"""One agent's control tick (estimation + guidance + phase keeping), timed over a whole mission.

Run:  .venv/bin/python -m benchmarks.bench_agent_tick [CONFIG ...] [--duration S] [--seed N]
      [--repeat 3]

A vehicle agent's work per telemetry frame, with the pure functions of
``app.core.mission.agent`` that the live agent loop calls: its camera's observation into the
local IMM-UKF (``observe``) and the command (``control``: the target predicted to the frame's
time, guidance with the optimal c, the inverse field and the moving-target correction, phase
keeping on the active team). A fused estimate, when the ground published one since the last
frame, is applied first (``hear_fused``: the federated feedback), as the agent would have
heard it; the timing covers it too.

The sequence is realistic and deterministic: ``configs/hil.toml``'s plan (three vehicles on
the eq. 2 fixed-wing from their standby loiter, the target's A-B-C-D path, seeded sigma^2 =
10 m^2 observations at 10 Hz per vehicle, the ground's fusion and stages from
``app.core.mission.ground``, telemetry at 10 Hz). Only the agents' ticks are timed; the ground
and the vehicle model run outside the timer. Prints the mean, median, p90, p99 and max per tick
in ms, per stage too (target: median <= 2 ms), and what the mean tick costs a vehicle at 1x real
time (a tick per telemetry frame), as a share of one core: the work that a planner replanning
every so often spends in a few long ticks shows in the mean, not in the median.

Given several configs it compares them: each flown ``--repeat`` times, taking turns, and per
config the lowest mean tick of its runs (the least disturbed by the shared machine) with its
ratio to the first config's.
"""

import argparse
import math
import time
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan, sim_config
from app.core.agent import OwnTelemetry
from app.core.estimation.messages import GlobalEstimate, Observation
from app.core.mission.agent import (
    MissionAgentState,
    TeammateFix,
    control,
    hear_fused,
    hear_mission,
    hear_teammate,
    initial_agent_state,
    observe,
)
from app.core.mission.ground import GroundState, VehicleReport, hear_local, hear_status, tick
from app.core.plant import step

TICK_S = 0.1  # telemetry (and control) rate of the built-in simulator: 10 Hz
PHYSICS_DT_S = 0.02
LOCAL_PERIOD_S = 0.2  # the agent publishes its local estimate at 5 Hz
TARGET_MEDIAN_MS = 2.0


def tick_stats(values_ms: list[float]) -> tuple[float, float, float, float, float]:
    """(mean, median, p90, p99, max) of tick times in ms."""
    a = np.asarray(values_ms)
    p50, p90, p99 = np.percentile(a, [50, 90, 99])
    return float(a.mean()), float(p50), float(p90), float(p99), float(a.max())


@dataclass
class Run:
    """One mission's agent ticks: every tick's time (ms), per stage and per part, the wall
    time, the final stage and distance errors."""

    name: str
    count: int
    duration_s: float
    times_ms: list[float]
    by_stage: dict[str, list[float]]
    parts: dict[str, list[float]]
    wall_s: float
    stage: str
    distance_m: list[float]


def fly(path: str, duration_s: float | None, seed: int) -> Run:
    """The mission of ``path`` flown with every agent's tick timed (see the module)."""
    config = load_config(path, MissionConfig)
    plan = build_plan(config)
    sim = sim_config(plan, base_port=14540)  # only for the starts; no socket is opened
    limits = config.limits.build()
    sigma = math.sqrt(config.sim.camera.sigma2_m2)
    rng = np.random.default_rng(seed)
    duration = duration_s if duration_s is not None else plan.end_t_s

    vehicles = [vc.start for vc in sim.vehicles]
    agents: list[MissionAgentState] = [initial_agent_state(p) for p in plan.agents]
    ground = GroundState()
    next_local = [0.0] * plan.count
    fused_pending: list[GlobalEstimate | None] = [None] * plan.count
    times_ms: list[float] = []
    by_stage: dict[str, list[float]] = defaultdict(list)
    parts: dict[str, list[float]] = defaultdict(list)
    steps = round(duration / TICK_S)
    sub = round(TICK_S / PHYSICS_DT_S)
    wall0 = time.perf_counter()
    for k in range(steps + 1):
        t = k * TICK_S
        truth = plan.target.state_at(t)
        commands = []
        for i, p in enumerate(plan.agents):
            v = vehicles[i]
            own = OwnTelemetry(v.east_m, v.north_m, v.course_rad, v.speed_m_s)
            obs = Observation(
                t,
                p.sensor,
                truth.east_m + sigma * float(rng.standard_normal()),
                truth.north_m + sigma * float(rng.standard_normal()),
                sigma,
            )
            state = agents[i]
            pending = fused_pending[i]
            t0 = time.perf_counter()
            if pending is not None:
                state = hear_fused(state, pending, p)
            t1 = time.perf_counter()
            state, _ = observe(state, obs, p)
            t2 = time.perf_counter()
            state, command, _ = control(state, t, own, p)
            t3 = time.perf_counter()
            elapsed_ms = 1e3 * (t3 - t0)
            fused_pending[i] = None
            times_ms.append(elapsed_ms)
            by_stage[state.stage].append(elapsed_ms)
            if pending is not None:
                parts["hear_fused"].append(1e3 * (t1 - t0))
            parts["observe"].append(1e3 * (t2 - t1))
            parts["control"].append(1e3 * (t3 - t2))
            agents[i] = state
            commands.append(command)
            # what the bus carries, outside the timer: status, local estimate
            status = VehicleReport(t, v.east_m, v.north_m, v.course_rad, v.speed_m_s)
            ground = hear_status(ground, p.vehicle, status)
            if t >= next_local[i]:
                estimate = state.local.estimate()
                if estimate is not None:
                    ground = hear_local(ground, estimate)
                    next_local[i] = t + LOCAL_PERIOD_S
        ground, fused, _ = tick(ground, plan.ground)
        for i in range(plan.count):
            if fused is not None:
                fused_pending[i] = fused
            agents[i] = hear_mission(agents[i], ground.stage.stage.value, ground.active)
            for j in range(plan.count):
                if j != i:
                    w = vehicles[j]
                    fix = TeammateFix(t, w.east_m, w.north_m, w.course_rad, w.speed_m_s)
                    agents[i] = hear_teammate(agents[i], j, fix)
        for i, command in enumerate(commands):
            for _ in range(sub):
                vehicles[i] = step(
                    vehicles[i], command.course_rad, command.speed_m_s, limits, PHYSICS_DT_S
                )
    wall = time.perf_counter() - wall0
    truth = plan.target.state_at(duration)
    dist = [
        math.hypot(v.east_m - truth.east_m, v.north_m - truth.north_m) - config.radius_m
        for v in vehicles
    ]
    return Run(
        config.name,
        plan.count,
        duration,
        times_ms,
        by_stage,
        parts,
        wall,
        ground.stage.stage.value,
        dist,
    )


def share(mean_ms: float) -> float:
    """A mean tick's cost to a vehicle at 1x real time, as % of one core."""
    return mean_ms / TICK_S / 10.0


def report(run: Run) -> None:
    print(
        f"bench_agent_tick: {run.name}, {run.count} agents, {run.duration_s:.0f} s of mission at "
        f"{1 / TICK_S:.0f} Hz, {len(run.times_ms)} ticks, {run.wall_s:.1f} s wall in all"
    )
    print(f"final stage {run.stage}, distance errors {[round(d, 1) for d in run.distance_m]} m")
    print("one tick = [hear_fused] + observe + control, ms (per stage, then each part alone)")
    head = f"{'ticks':>6} {'mean':>8} {'median':>8} {'p90':>8} {'p99':>8} {'max':>8}"
    print(f"  {'':<10} {head}")
    rows = [("all", run.times_ms), *sorted(run.by_stage.items()), *run.parts.items()]
    for label, values in rows:
        mean, p50, p90, p99, top = tick_stats(values)
        print(
            f"  {label:<10} {len(values):>6} {mean:8.3f} {p50:8.3f} {p90:8.3f} {p99:8.3f} "
            f"{top:8.3f}"
        )
    mean, p50, *_ = tick_stats(run.times_ms)
    print(
        f"mean {mean:.3f} ms per tick at {1 / TICK_S:.0f} Hz: {share(mean):.2f} % of one "
        "core per vehicle at 1x (the agent's own work)"
    )
    ok = p50 <= TARGET_MEDIAN_MS
    print(f"median {p50:.3f} ms <= {TARGET_MEDIAN_MS} ms: {'PASS' if ok else 'FAIL'}")


def compare(paths: list[str], duration_s: float | None, seed: int, repeat: int) -> None:
    """Every config flown ``repeat`` times, taking turns (so that a busy spell of the machine
    falls on all of them alike); per config the lowest mean tick of its repeats, the least
    disturbed, and its ratio to the first config's."""
    means: dict[str, list[float]] = {path: [] for path in paths}
    for r in range(repeat):
        for path in paths:
            run = fly(path, duration_s, seed)
            mean = tick_stats(run.times_ms)[0]
            means[path].append(mean)
            print(f"  round {r + 1}: {path}: mean tick {mean:.3f} ms ({share(mean):.2f} %)")
    base = min(means[paths[0]])
    print(f"bench_agent_tick: {len(paths)} configs, the lowest of {repeat} runs each")
    print(f"  {'config':<40} {'mean ms':>8} {'% core':>7} {'ratio':>6}")
    for path in paths:
        best = min(means[path])
        print(f"  {path:<40} {best:8.3f} {share(best):7.2f} {best / base:6.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "config",
        nargs="*",
        default=["hil"],
        help="mission config (default: hil); several: compared side by side",
    )
    parser.add_argument("--duration", type=float, help="seconds of mission (default: all of it)")
    parser.add_argument("--seed", type=int, default=1, help="observation noise seed")
    parser.add_argument(
        "--repeat", type=int, default=3, help="runs of each config when comparing (default 3)"
    )
    args = parser.parse_args()
    if len(args.config) == 1:
        report(fly(args.config[0], args.duration, args.seed))
    else:
        compare(args.config, args.duration, args.seed, max(args.repeat, 1))


if __name__ == "__main__":
    main()
