"""``standoff fly [CONFIG]``: a whole mission in one process (the main job)."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import datetime as dt
import math
import sys
import threading
from collections.abc import AsyncIterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.cli._options import add_mission_options
from app.errors import ConfigError

if TYPE_CHECKING:
    from app.config.mission import MissionConfig

ORDER = 10


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "fly",
        help="fly a mission: built-in simulator (default), SITL or real vehicles",
        description=(
            "Fly a cooperative standoff-tracking mission in one process: the vehicles (the "
            "built-in simulator unless --connect is given), the ground station and one agent "
            "per vehicle, over the in-process bus or MQTT (--broker). With no CONFIG: the "
            "paper's section 5.2 scenario on 3 simulated vehicles. Writes a run folder. "
            "While it flies, a vehicle whose mode someone else changed (RC, a ground-control "
            "station, RTL, a failsafe) is left alone until you type 'resume N' (N: the vehicle "
            "number, from 1, as the live view and the events print it; 'resume' alone: every "
            "vehicle) and Enter; 'hold N' holds one."
        ),
    )
    add_mission_options(
        p,
        "MQTT broker, mqtt://[user:pass@]host:port (default: the config's 'bus', else in-process)",
    )
    p.add_argument("--out", type=Path, help="run folder (default: a new folder under runs/)")
    p.add_argument(
        "--connect",
        nargs="+",
        metavar="URL",
        help="fly external vehicles (udpin://, udpout://, tcp://, serial://)",
    )
    p.add_argument(
        "--simulator",
        action="store_true",
        help="fly the built-in simulator even where the file lists vehicles to connect to: "
        "the file's autopilot adapter against the simulator's matching personality (PX4 v1.16 "
        "or ArduPlane 4.6), for a side-by-side with the real autopilots",
    )
    p.add_argument("--speedup", type=float, help="built-in simulator speed-up factor")
    p.add_argument("--seed", type=int, help="built-in simulator's random seed")
    gcs = p.add_mutually_exclusive_group()
    gcs.add_argument(
        "--gcs",
        metavar="ENDPOINT",
        help="where a ground station (QGroundControl, MAVProxy) sees the vehicles: HOST:PORT "
        "or udpout:HOST:PORT (sent there), udpin:HOST:PORT (listened on, vehicle i on PORT+i) "
        "(default: the config's [link] gcs_forward, udpout:127.0.0.1:14550 as PX4 SITL does)",
    )
    gcs.add_argument(
        "--no-gcs", action="store_true", help="serve no ground station (the .tlogs are recorded)"
    )
    p.add_argument("--quiet", action="store_true", help="no live view")
    p.add_argument(
        "--no-stdin",
        action="store_true",
        help="do not read operator commands (resume N, hold N) from standard input",
    )
    p.add_argument(
        "--dry-run", action="store_true", help="check the file, print the plan: as standoff check"
    )
    p.set_defaults(handler=run)


def on_the_simulator(config: MissionConfig) -> MissionConfig:
    """The mission flown by the built-in simulator: no vehicles to connect to, and the
    simulator's personality the one the file's autopilot adapter is written for."""
    from app.config.loading import validate_config
    from app.config.mission import MissionConfig

    personality = "arduplane" if config.link.autopilot == "arduplane" else "px4"
    raw = config.model_dump()
    raw["link"]["connect"] = []
    raw["sim"]["autopilot"] = personality
    return validate_config(raw, MissionConfig, "--simulator")


def with_gcs(config: MissionConfig, args: argparse.Namespace) -> MissionConfig:
    """The config with --gcs ENDPOINT or --no-gcs in ``[link] gcs_forward`` (checked)."""
    from app.config.loading import validate_config
    from app.config.mission import MissionConfig

    spec = "off" if getattr(args, "no_gcs", False) else getattr(args, "gcs", None)
    if spec is None:
        return config
    raw = config.model_dump()
    raw["link"]["gcs_forward"] = spec
    return validate_config(raw, MissionConfig, "--gcs" if spec != "off" else "--no-gcs")


def gcs_line(config: MissionConfig) -> str:
    """The line that tells the operator where a ground station sees the vehicles."""
    spec = config.link.gcs_forward
    if spec == "off":
        return "ground station: none (--no-gcs); each vehicle's traffic is in its .tlog"
    if spec.startswith("udpin:"):
        return (
            f"ground station: vehicle i listened for on {spec}+i-1 "
            "(e.g. mavproxy.py --master=udpout:HOST:PORT)"
        )
    default = " (QGroundControl's default port)" if spec.endswith(":14550") else ""
    return f"ground station: every vehicle sent to {spec}{default}; --gcs, --no-gcs to change"


def default_out_dir(name: str) -> Path:
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"{name}-{stamp}"


def run(args: argparse.Namespace) -> int:
    from rich.console import Console

    from app.adapters.live_view import LiveView
    from app.cli._options import with_overrides
    from app.compose.mission import Mission, fly_until_interrupted
    from app.config import load_config
    from app.config.mission import MissionConfig
    from app.config.plan import build_plan

    config = with_gcs(with_overrides(load_config(args.config, MissionConfig), args), args)
    if args.simulator:
        if args.connect:
            raise ConfigError("--simulator and --connect exclude each other")
        config = on_the_simulator(config)
    plan = build_plan(config)
    if args.dry_run:  # standoff check's plan
        from app.compose.plan_text import describe_plan

        print(
            describe_plan(plan, args.connect or (), args.broker, args.base_port, str(args.config))
        )
        return 0
    out = args.out or default_out_dir(config.name)
    console = Console()
    console.print(
        f"standoff fly: {config.name}, {plan.count} vehicles, run folder {out}", soft_wrap=True
    )
    console.print(gcs_line(config), soft_wrap=True, highlight=False, markup=False)
    view = LiveView(console) if not args.quiet else None
    with view if view is not None else contextlib.nullcontext():
        mission = Mission(
            plan,
            out,
            connect=args.connect or (),
            broker_url=args.broker,
            base_port=args.base_port,
            on_snapshot=view.update if view is not None else None,
            operator=None if args.no_stdin else stdin_lines(),
            notify=lambda line: console.print(line, soft_wrap=True, highlight=False, markup=False),
        )
        result = asyncio.run(fly_until_interrupted(mission.run(), mission.station_t_s))
    console.print(report(result.summary), highlight=False, markup=False, soft_wrap=True)
    return 0


async def stdin_lines() -> AsyncIterator[str]:
    """The operator's lines from standard input, read by a daemon thread (a blocked read never
    holds up the exit, and the terminal's output stays blocking); ends at end of input."""
    loop = asyncio.get_running_loop()
    queue: asyncio.Queue[str | None] = asyncio.Queue()

    def read() -> None:
        try:
            for line in sys.stdin:
                loop.call_soon_threadsafe(queue.put_nowait, line)
        except (OSError, ValueError, RuntimeError):
            pass  # stdin closed, or the loop went away
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(queue.put_nowait, None)

    threading.Thread(target=read, name="operator-stdin", daemon=True).start()
    while (line := await queue.get()) is not None:
        yield line


def _fmt(value: object, spec: str = ".1f") -> str:
    return format(value, spec) if isinstance(value, float) and math.isfinite(value) else "-"


def _falling_behind(summary: dict[str, object]) -> str | None:
    """A warning when an agent steered past more than a tenth of its telemetry frames."""
    agents = summary.get("agents")
    if not isinstance(agents, dict):
        return None
    shares = {}
    for vehicle, c in agents.items():
        if isinstance(c, dict) and c.get("ticks", 0) + c.get("frames_skipped", 0) > 0:
            shares[vehicle] = c.get("frames_skipped", 0) / (c["ticks"] + c["frames_skipped"])
    if not shares or max(shares.values()) <= 0.1:
        return None
    worst = max(shares.values())
    return (
        f"warning: the agents fell behind their vehicles (up to {worst:.0%} of the telemetry "
        "frames skipped): this machine was short of CPU and the figures suffer; lower "
        "--speedup or run the agents as separate processes"
    )


def _cpu_line(summary: dict[str, object]) -> str:
    """The CPU the run took per vehicle, as a share of one core at 1x real time."""
    cpu = summary.get("cpu")
    if not isinstance(cpu, dict):
        return ""
    share = cpu.get("per_vehicle_at_1x") or {}

    def pct(key: str) -> str:
        value = share.get(key)
        return "-" if not isinstance(value, float) else f"{100.0 * value:.2f} %"

    return (
        "CPU per vehicle at 1x real time (of one core): agents' own work "
        f"{pct('agents')}, this process {pct('process')}"
        f" (ground, agents, links), with its children (the simulator, the MAVLink relays)"
        f" {pct('with_children')}"
    )


def _percent(value: object) -> str:
    return f"{100.0 * value:.0f} %" if isinstance(value, float) and math.isfinite(value) else "-"


def _course_loop_line(summary: dict[str, object]) -> str:
    """Each vehicle's identified course loop (k, delay), or for one not identified how far
    its identification got: what an operator of a real autopilot wants to know of the loop
    the guidance was flown on."""
    agents = summary.get("agents")
    if not isinstance(agents, dict):
        return ""
    parts = []
    for vehicle, c in agents.items():
        loop = c.get("course_loop") if isinstance(c, dict) else None
        if not isinstance(loop, dict):
            continue
        if loop.get("identified"):
            parts.append(
                f"vehicle {vehicle}: k {_fmt(loop.get('gain_per_s'), '.2f')} /s,"
                f" delay {_fmt(loop.get('delay_s'), '.1f')} s"
            )
        else:
            parts.append(
                f"vehicle {vehicle}: not identified"
                f" ({_fmt(loop.get('informative_s'), '.0f')} s informative,"
                f" {_fmt(loop.get('min_s'), '.0f')} needed;"
                f" rel. se {_percent(loop.get('rel_se'))},"
                f" {_percent(loop.get('max_rel_se'))} needed)"
            )
    return "course loop: " + "; ".join(parts) if parts else ""


def _respace_line(loss: dict[str, Any]) -> str:
    after = loss.get("after_first") or {}
    held = ""
    if after:
        held = (
            f"; from then spacing error RMS {_fmt(after['spacing_error_deg']['rms'])} deg,"
            f" within {100.0 * after['within_fraction']:.0f} % of"
            f" {_fmt(after['duration_s'])} s"
        )
    return (
        f"vehicle lost at {_fmt(loss.get('t_s'))} s ({loss.get('vehicles_before')} ->"
        f" {loss.get('vehicles_after')}): re-spaced within {_fmt(loss.get('tolerance_deg'))} deg"
        f" after {_fmt(loss.get('first_within_s'))} s{held}"
    )


def report(summary: dict[str, object]) -> str:
    """The run's headline figures, a few lines for the terminal (the full set: summary.json)."""
    conv = summary.get("convergence")
    lines = [
        f"wall time {_fmt(summary['wall_s'])} s, mission time {_fmt(summary['mission_t_s'])} s"
    ]
    if isinstance(conv, dict):
        lines.append(
            "from the tracking command: on the circle "
            f"{_fmt(conv.get('time_to_circle_s'))} s,"
            f" spaced {_fmt(conv.get('time_to_spacing_s'))} s,"
            f" both {_fmt(conv.get('time_to_formation_s'))} s"
        )
        first = conv.get("first_within")
        if isinstance(first, dict):
            lines.append(
                f"first all within {_fmt(first.get('radius_tolerance_m'))} m and"
                f" {_fmt(first.get('spacing_tolerance_deg'))} deg at one instant:"
                f" {_fmt(first.get('t_s'))} s"
            )
    respace = summary.get("respace")
    if isinstance(respace, list):
        lines.extend(_respace_line(loss) for loss in respace if isinstance(loss, dict))
    behind = _falling_behind(summary)
    if behind:
        lines.append(behind)
    cpu = _cpu_line(summary)
    if cpu:
        lines.append(cpu)
    loop = _course_loop_line(summary)
    if loop:
        lines.append(loop)
    parts = summary.get("parts")
    if isinstance(parts, dict):
        for key, part in parts.items():
            team = part.get("team", {})
            d = team.get("distance_error_m", {})
            sp = team.get("spacing_error_deg", {})
            est = team.get("estimation_rmse", {})
            lines.append(
                f"{key:<14} distance error RMS {_fmt(d.get('rms'))} m"
                f" (max {_fmt(d.get('max_abs'))}),"
                f" spacing error RMS {_fmt(sp.get('rms'))} deg (max {_fmt(sp.get('max_abs'))}),"
                f" estimate RMSE {_fmt(est.get('position_m'), '.2f')} m"
            )
    return "\n".join(lines)
