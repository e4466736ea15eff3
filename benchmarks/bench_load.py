"""The one-process ``standoff fly`` on a busy machine and with larger teams, against the same
mission quiet with the file's team, side by side in one run (issue #15: beside two busy
processes every figure within 1.15x of the quiet run; 20 vehicles at 1x within 1.2x of the
three's, the CPU per vehicle growing no faster than linearly; the agents' CPU per vehicle at 1x
real time printed, at most 2 % of a core).

Run:  .venv/bin/python -m benchmarks.bench_load [CONFIG] [--busy 0 2] [--teams N ...]
      [--runs 1] [--speedup X] [--vary-command 4] [--delay S]

Flies ``CONFIG`` (default ``hil``) with ``standoff fly``'s own machinery (the built-in
simulator in its own process, MAVSDK over UDP, the in-process bus) once per variant and run:
every team size of ``--teams`` (default: the file's) with every count of ``--busy`` processes
spinning on the CPU at the app's own priority (``while True: pass``, started before the
mission, stopped after it; default 0 and 2). The first variant is the baseline. Run k flies the
simulator's seed + k - 1 with its tracking command (k - 1) * ``--vary-command`` s later, the
variants of one k one after the other so that whatever else loads the machine falls on them
alike. Prints per variant the means over the runs of the formation time, the formation bound
from where the team was at the tracking command (``bench_gather_bound``, a seat each: run k's
command finds the standby loiter elsewhere, and the bound moves by several seconds), and every
track segment's RMS distance and spacing error, with ratios to the baseline, then the CPU per
vehicle at 1x real time (the agents' own, the whole process, and with the simulator and
mavsdk_server processes), the share of telemetry frames the agents steered past because a
tick was still running (``frames_skipped``), the longest a steered frame waited, and the load
average at the end.

``--delay S`` moves the tracking command and the target's departure (a ``waypoints`` target's
``wait_s``) S s later, so that the team climbs to its altitude stack in standby before it
gathers. A team launched together climbs from one height: at 35 m a level
(``[link] altitude_stack_m``) and about 5 m/s of climb, the top of a 20-vehicle stack is reached
about 150 s into the mission, after the default mission's target has left (130 s). With the
delay the team sizes are compared on the mission they fly once up rather than on the climb.
"""

import argparse
import asyncio
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from app.config import load_config
from app.config.mission import MissionConfig
from app.core.guidance.dubins import MAX_JOIN_TEAM
from benchmarks.bench_gather_bound import run_bounds
from benchmarks.mavlink_runs import Figures, cell, figures_of, fly_mavlink, mean

SPIN = "while True: pass"


def load_figures(summary: dict[str, Any]) -> Figures:
    """What the machine's load did to the app: CPU per vehicle at 1x (% of a core), frames
    steered past (% of the frames steered on or past), the longest frame wait (s)."""
    share = (summary.get("cpu") or {}).get("per_vehicle_at_1x") or {}
    agents = (summary.get("agents") or {}).values()
    skipped = sum(a.get("frames_skipped", 0) for a in agents)
    ticks = sum(a.get("ticks", 0) for a in agents)

    def percent(value: float | None) -> float | None:
        return None if value is None else 100.0 * value

    return {
        "agents %": percent(share.get("agents")),
        "process %": percent(share.get("process")),
        "+children %": percent(share.get("with_children")),
        "skipped %": 100.0 * skipped / (skipped + ticks) if skipped + ticks else None,
        "wait max s": max((a.get("frame_wait_max_s", 0.0) for a in agents), default=None),
    }


def spinning(count: int) -> list[subprocess.Popen[bytes]]:
    """``count`` processes that keep a core busy until stopped."""
    return [subprocess.Popen([sys.executable, "-c", SPIN]) for _ in range(count)]


def stopped(processes: list[subprocess.Popen[bytes]]) -> None:
    for p in processes:
        p.kill()
    for p in processes:
        p.wait()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="hil")
    parser.add_argument("--busy", type=int, nargs="+", default=[0, 2], help="busy processes")
    parser.add_argument("--teams", type=int, nargs="+", help="team sizes (the file's)")
    parser.add_argument("--runs", type=int, default=1, help="runs per variant (1)")
    parser.add_argument("--speedup", type=float, help="simulator speed-up (the config's)")
    parser.add_argument("--vary-command", type=float, default=4.0, help="s per run (4)")
    parser.add_argument(
        "--delay",
        type=float,
        default=0.0,
        help="s later the tracking command and the target's departure (0)",
    )
    args = parser.parse_args()
    config = load_config(args.config, MissionConfig)
    teams = args.teams or [config.vehicles]
    if min(args.busy) < 0 or min(teams) < 1 or args.runs < 1 or args.delay < 0:
        parser.error("--busy takes counts from 0, --teams and --runs from 1, --delay from 0")
    if args.delay:
        if not hasattr(config.target, "wait_s"):
            parser.error("--delay needs a waypoints target (its wait_s)")
        config = config.model_copy(
            update={
                "tracking_command_s": config.tracking_command_s + args.delay,
                "target": config.target.model_copy(
                    update={"wait_s": config.target.wait_s + args.delay}
                ),
            }
        )
    sim = config.sim
    if args.speedup is not None:
        sim = sim.model_copy(update={"speedup": args.speedup})
    print(
        f"bench_load: {config.name}, standoff fly on the built-in simulator at {sim.speedup:g}x,"
        f" teams of {', '.join(map(str, teams))}, beside {', '.join(map(str, args.busy))} busy"
        f" processes, {args.runs} run(s) each, on {os.cpu_count()} cores"
        + (f", tracking command and target {args.delay:g} s later" if args.delay else ""),
        flush=True,
    )
    root = Path(tempfile.mkdtemp(prefix="bench-load-"))
    variants = [(n, busy) for n in teams for busy in args.busy]
    flown: dict[tuple[int, int], list[Figures]] = {}
    loads: dict[tuple[int, int], list[Figures]] = {}
    for k in range(1, args.runs + 1):
        for n, busy in variants:
            variant = config.model_copy(
                update={
                    "vehicles": n,
                    "sim": sim.model_copy(update={"seed": sim.seed + k - 1}),
                    "tracking_command_s": config.tracking_command_s + (k - 1) * args.vary_command,
                }
            )
            out_dir = root / f"run{k}-{n}vehicles-{busy}busy"
            start = time.monotonic()
            spinners = spinning(busy)
            try:
                summary = asyncio.run(fly_mavlink(variant, out_dir))
                load = os.getloadavg()[0]
            finally:
                stopped(spinners)
            figures = figures_of(summary)
            bound = _seat_bound(out_dir, variant)
            formed = figures.get("formation_s")
            flown.setdefault((n, busy), []).append(
                {"formation_s": formed} | ({} if bound is None else {"bound_s": bound}) | figures
            )
            loads.setdefault((n, busy), []).append(load_figures(summary) | {"load avg": load})
            print(
                f"  flown: run {k}, {_name(n, busy)} ({time.monotonic() - start:.0f} s wall,"
                f" {out_dir}): formed "
                + ("never" if formed is None else f"{formed:.1f} s")
                + ("" if bound is None else f", the bound from where the team was {bound:.1f} s")
                + ("" if formed is None or not bound else f" ({formed / bound:.2f}x)"),
                flush=True,
            )
    base = mean(flown[variants[0]])
    keys = list(base)
    print(f"\n{'run':<22}" + "".join(f"{k:>14}" for k in keys))
    for v in variants:
        figures = mean(flown[v])
        cells = "".join(f"{_cell(k, figures, base):>14}" for k in keys)
        print(f"{_name(*v):<22}{cells}")
    load_keys = list(loads[variants[0]][0])
    print(f"\n{'run':<22}" + "".join(f"{k:>13}" for k in load_keys))
    for v in variants:
        means = mean(loads[v])
        print(f"{_name(*v):<22}" + "".join(f"{_number(means.get(k)):>13}" for k in load_keys))
    print(
        "\n(formation: s after the tracking command; bound: the same from where the team was at"
        " the command, at the top speed on the tightest turn, a seat each (bench_gather_bound);"
        " dist: RMS distance error m; spacing: RMS"
        " spacing error deg; means over the runs (never: some run did not form), ratios against"
        " the first row. CPU: % of one core per vehicle at 1x real time: the agents' own"
        " steps, the whole app process, and with its children (simulator, MAVLink relays);"
        " skipped: telemetry frames steered past because a tick was still running)"
    )


def _seat_bound(run_dir: Path, config: MissionConfig) -> float | None:
    """The formation bound from where the run's team was at the tracking command
    (``bench_gather_bound``: a seat each, at the top speed on the tightest turn); None for a
    team larger than the seat search takes or a run folder without a track."""
    if config.vehicles > MAX_JOIN_TEAM or not (run_dir / "track.csv").exists():
        return None
    return run_bounds(run_dir, config)[1]


def _cell(key: str, figures: Figures, base: Figures) -> str:
    """A figure with its ratio to the baseline's; a bound no run had (a team too large to
    search) is left blank, not ``never``."""
    if key == "bound_s" and figures.get(key) is None:
        return "-"
    return cell(figures.get(key), base.get(key))


def _name(vehicles: int, busy: int) -> str:
    return f"{vehicles} vehicles, " + ("quiet" if busy == 0 else f"{busy} busy")


def _number(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


if __name__ == "__main__":
    main()
