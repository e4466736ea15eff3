"""``standoff ground [CONFIG] --broker URL``: the ground station as its own process over MQTT."""

import argparse
import contextlib
import sys
from pathlib import Path

from app.cli._login import add_login_options
from app.cli._options import add_mission_options

ORDER = 12


def register(subparsers: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    p = subparsers.add_parser(
        "ground",
        help="the ground station alone, for agents in other processes (MQTT)",
        description=(
            "Run the ground station of a mission as its own process: it takes the target "
            "observations, fuses the agents' estimates, decides the stage and publishes it over "
            "an MQTT broker, where one 'standoff agent --vehicle N' per vehicle (N = 1..n, its "
            "MAVLink system id) flies. When the mission ends it sends 'shutdown' to every "
            "agent (they put their vehicles in hold and exit) and writes the run folder. With "
            "--sitl it also runs the built-in simulator for the mission; otherwise the vehicles "
            "are elsewhere."
        ),
    )
    add_mission_options(p, "MQTT broker, mqtt[s]://host:port (default: the config's 'bus')")
    add_login_options(p)
    p.add_argument("--out", type=Path, help="run folder (default: a new folder under runs/)")
    p.add_argument(
        "--sitl",
        action="store_true",
        help="also run the built-in simulator (the agents connect to its UDP ports)",
    )
    p.add_argument("--quiet", action="store_true", help="no live view")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from rich.console import Console

    from app.adapters.live_view import LiveView
    from app.cli._login import bus_options
    from app.cli._options import broker_url, with_overrides
    from app.cli.fly import default_out_dir, report
    from app.compose.distributed import run_ground
    from app.config import load_config
    from app.config.mission import MissionConfig
    from app.config.plan import build_plan

    config = with_overrides(load_config(args.config, MissionConfig), args)
    url = broker_url(args, config)
    options = bus_options(args, config, "ground")
    plan = build_plan(config)
    out = args.out or default_out_dir(config.name)
    base_port = config.sim.base_port
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
                bus_options=options,
            )
        )
    console.print(report(result.summary), highlight=False, markup=False, soft_wrap=True)
    if result.interrupted:
        notify("interrupted: the agents were told to shut down; partial results written")
        return 130
    return 0
