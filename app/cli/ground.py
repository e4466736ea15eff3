"""``standoff ground [CONFIG] --broker URL``: the ground station as its own process over MQTT."""

import argparse
import asyncio
import contextlib
import sys
from pathlib import Path

from rich.console import Console

from app.adapters.bus import BrokerUrl
from app.adapters.live_view import LiveView
from app.cli.fly import DEFAULT_CONFIG, default_out_dir, report
from app.config import load_config
from app.errors import ConfigError
from app.mission_config import MissionConfig
from app.runtime.distributed import run_ground
from app.runtime.mission import build_plan

ORDER = 12


def register(subparsers: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    p = subparsers.add_parser(
        "ground",
        help="the ground station alone, for agents in other processes (MQTT)",
        description=(
            "Run the ground station of a mission as its own process: it takes the target "
            "observations, fuses the agents' estimates, decides the stage and publishes it over "
            "an MQTT broker, where one 'standoff agent --vehicle I' per vehicle flies. When the "
            "mission ends it sends 'shutdown' to every agent (they put their vehicles in hold "
            "and exit) and writes the run folder. With --sitl it also runs the built-in "
            "simulator for the mission; otherwise the vehicles are elsewhere."
        ),
    )
    p.add_argument(
        "config",
        nargs="?",
        default=DEFAULT_CONFIG,
        help="mission config: a name in configs/ or a path (default: hil)",
    )
    p.add_argument(
        "--broker",
        metavar="URL",
        help="MQTT broker, mqtt://[user:pass@]host:port (default: the config's 'bus')",
    )
    p.add_argument("--out", type=Path, help="run folder (default: a new folder under runs/)")
    p.add_argument("--vehicles", type=int, help="number of vehicles (default: the config's)")
    p.add_argument(
        "--sitl",
        action="store_true",
        help="also run the built-in simulator (the agents connect to its UDP ports)",
    )
    p.add_argument(
        "--base-port", type=int, help="built-in simulator's first UDP port (default: the config's)"
    )
    p.add_argument("--quiet", action="store_true", help="no live view")
    p.set_defaults(handler=run)


def broker_url(args: argparse.Namespace, config: MissionConfig) -> str:
    """The broker to use: ``--broker``, else the config's ``bus``; checked before any I/O."""
    url: str | None = args.broker or config.bus
    if url is None:
        raise ConfigError(
            "no MQTT broker: give --broker mqtt://host:port (or 'bus' in the config);"
            " the processes of a mission meet on a broker"
        )
    BrokerUrl.parse(url)  # raises BusUrlError (a ConfigError) with the reason
    return url


def run(args: argparse.Namespace) -> int:
    config = load_config(args.config, MissionConfig)
    url = broker_url(args, config)
    if args.base_port is not None and not 1024 <= args.base_port <= 65000:
        raise ConfigError(f"--base-port {args.base_port} is out of range 1024..65000")
    if args.vehicles is not None and not 1 <= args.vehicles <= 50:
        raise ConfigError(f"--vehicles {args.vehicles} is out of range 1..50")
    plan = build_plan(config, args.vehicles)
    out = args.out or default_out_dir(config.name)
    base_port = args.base_port if args.base_port is not None else config.sim.base_port
    console = Console()

    def notify(line: str) -> None:
        console.print(f"standoff ground: {line}", highlight=False, markup=False, soft_wrap=True)
        sys.stdout.flush()

    notify(f"{config.name}, {plan.count} vehicles, run folder {out}")
    view = LiveView(console) if not args.quiet else None
    with view if view is not None else contextlib.nullcontext():
        result = asyncio.run(
            run_ground(
                plan,
                out,
                url,
                sitl_base_port=base_port if args.sitl else None,
                on_snapshot=view.update if view is not None else None,
                notify=notify,
            )
        )
    console.print(report(result.summary), highlight=False, markup=False, soft_wrap=True)
    if result.interrupted:
        notify("interrupted: the agents were told to shut down; partial results written")
        return 130
    return 0
