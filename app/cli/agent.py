"""``standoff agent --vehicle N [CONFIG] --broker URL``: one vehicle's agent as its own process."""

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
            "vehicle-<N>.tlog, events-agent-<N>.jsonl and agent-<N>.json to --out."
        ),
    )
    p.add_argument(
        "--vehicle",
        type=int,
        required=True,
        metavar="N",
        help="which vehicle, 1..<vehicles> (its MAVLink system id, as in vehicle-N.tlog)",
    )
    add_mission_options(p, "MQTT broker, mqtt[s]://host:port (default: the config's 'bus')")
    add_login_options(p)
    p.add_argument(
        "--connect",
        metavar="URL",
        help=(
            "the vehicle's MAVSDK URL (udpin://, udpout://, tcp://, serial://); default: the "
            "config's URL for this vehicle, else the built-in simulator's port base-port + N - 1"
        ),
    )
    p.add_argument(
        "--out",
        type=Path,
        help="folder for the tlog and logs (default: runs/<name>-agent-<N>); the ground's "
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
    from app.errors import ConfigError
    from app.runtime.ports import topics

    config = with_overrides(load_config(args.config, MissionConfig), args)
    url = broker_url(args, config)
    plan = build_plan(config)
    number: int = args.vehicle  # as users read it: the system id, agent-N, vehicle-N.tlog
    if not 1 <= number <= plan.count:
        raise ConfigError(f"--vehicle {number}: the mission's vehicles are 1..{plan.count}")
    vehicle = number - 1  # the 0-based index inside
    connect = validate_url(agent_url(plan, vehicle, args.connect, config.sim.base_port))
    builtin = args.connect is None and not config.link.connect
    name = topics.agent(vehicle)
    options = bus_options(args, config, name)
    out = args.out or Path("runs") / f"{config.name}-{name}"

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
    where = f"vehicle {number} {'in hold' if result.held else 'hold not confirmed'}"
    if result.stopped_by is not None:
        notify(f"agent {number}: stopped by {result.stopped_by.name}; {where}")
        return 128 + int(result.stopped_by)
    if result.reason != "shutdown":
        print(
            f"standoff agent: error: agent {number}: {result.reason}; {where}",
            file=sys.stderr,
        )
        return 1
    notify(f"agent {number}: shutdown by the ground station; {where}")
    return 0
