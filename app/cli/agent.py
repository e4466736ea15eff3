"""``standoff agent --vehicle I [CONFIG] --broker URL``: one vehicle's agent as its own process."""

import argparse
import sys
from pathlib import Path

from app.cli._login import add_login_options
from app.cli._options import add_mission_options

ORDER = 13


def register(subparsers: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    p = subparsers.add_parser(
        "agent",
        help="one vehicle's agent, for a ground station in another process (MQTT)",
        description=(
            "Fly one vehicle of a mission as its own process (as on the vehicle's onboard "
            "computer): connect to it over MAVLink, take off, start offboard control and run "
            "its agent (local estimator, guidance, phase keeping) with the ground station and "
            "the other agents over an MQTT broker. Stops when the ground station sends "
            "'shutdown', or on SIGINT/SIGTERM; either way the vehicle is left in hold. Writes "
            "vehicle-<I+1>.tlog, events-agent-<I>.jsonl and agent-<I>.json to --out."
        ),
    )
    p.add_argument(
        "--vehicle",
        type=int,
        required=True,
        metavar="I",
        help="which vehicle, 0-based (MAVLink system id I+1)",
    )
    add_mission_options(p, "MQTT broker, mqtt[s]://host:port (default: the config's 'bus')")
    add_login_options(p)
    p.add_argument(
        "--connect",
        metavar="URL",
        help=(
            "the vehicle's MAVSDK URL (udpin://, udpout://, tcp://, serial://); default: the "
            "config's URL for this vehicle, else the built-in simulator's port base-port + I"
        ),
    )
    p.add_argument(
        "--out",
        type=Path,
        help="folder for the tlog and logs (default: runs/<name>-agent-<I>); the ground's "
        "run folder keeps a mission together",
    )
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from app.adapters.vehicle.mavsdk.urls import validate_url
    from app.cli._login import bus_options
    from app.cli._options import broker_url, with_overrides
    from app.compose.distributed import agent_url, run_agent
    from app.config import load_config
    from app.config.mission import MissionConfig
    from app.config.plan import build_plan

    config = with_overrides(load_config(args.config, MissionConfig), args)
    url = broker_url(args, config)
    plan = build_plan(config)
    vehicle: int = args.vehicle
    connect = validate_url(agent_url(plan, vehicle, args.connect, config.sim.base_port))
    builtin = args.connect is None and not config.link.connect
    options = bus_options(args, config, f"agent-{vehicle}")
    out = args.out or Path("runs") / f"{config.name}-agent-{vehicle}"

    def notify(line: str) -> None:
        print(f"standoff agent: {line}", flush=True)

    result = asyncio.run(
        run_agent(
            plan,
            vehicle,
            url,
            connect,
            out,
            builtin_simulator=builtin,
            notify=notify,
            bus_options=options,
        )
    )
    where = f"vehicle {vehicle + 1} {'in hold' if result.held else 'hold not confirmed'}"
    if result.stopped_by is not None:
        notify(f"agent {vehicle}: stopped by {result.stopped_by.name}; {where}")
        return 128 + int(result.stopped_by)
    if result.reason != "shutdown":
        print(
            f"standoff agent: error: agent {vehicle}: {result.reason}; {where}",
            file=sys.stderr,
        )
        return 1
    notify(f"agent {vehicle}: shutdown by the ground station; {where}")
    return 0
