"""``standoff sitl``: run the built-in MAVLink simulator alone until interrupted."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from app.errors import ConfigError

if TYPE_CHECKING:
    from sitl.config import SimConfig

ORDER = 20


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        "sitl",
        help="run the built-in MAVLink simulator (vehicles, target, camera) alone",
        description=(
            "Run N simulated PX4-like (or ArduPlane-like) fixed-wing vehicles that MAVSDK or "
            "pymavlink clients fly "
            "over UDP. Vehicle i (system id i+1) sends to HOST:BASE_PORT+i; a client listens "
            "there (MAVSDK: udpin://0.0.0.0:BASE_PORT+i). Runs until Ctrl-C."
        ),
    )
    parser.add_argument(
        "--scenario", metavar="FILE", help="scenario TOML (a path, or a name in configs/)"
    )
    parser.add_argument("--vehicles", type=int, metavar="N", help="number of vehicles (default 3)")
    parser.add_argument(
        "--base-port", type=int, metavar="P", help="vehicle i sends to port P+i (default 14540)"
    )
    parser.add_argument(
        "--speedup", type=float, metavar="K", help="simulated time runs K times wall time"
    )
    parser.add_argument("--seed", type=int, metavar="S", help="random seed (camera noise, wind)")
    parser.add_argument(
        "--gcs-host", metavar="HOST", help="where the vehicles send (default 127.0.0.1)"
    )
    parser.add_argument(
        "--bind-host",
        metavar="HOST",
        help="address the vehicle sockets bind (default 127.0.0.1; 0.0.0.0 for other machines)",
    )
    parser.add_argument(
        "--autopilot",
        choices=("px4", "arduplane"),
        help="which autopilot the vehicles imitate (default px4; see docs/simulator.md)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="T",
        help="stop after T simulated seconds (default: run until interrupted)",
    )
    parser.set_defaults(handler=run)


def build_sim_config(args: argparse.Namespace) -> SimConfig:
    """The simulator config from the scenario file (if any) and the command-line overrides."""
    from app.config import load_config
    from app.config.simulator import SitlScenario

    scenario = load_config(args.scenario, SitlScenario) if args.scenario else SitlScenario()
    if args.base_port is not None and not 1 <= args.base_port <= 65535:
        raise ConfigError(f"--base-port must be in 1..65535, got {args.base_port}")
    if args.speedup is not None and not args.speedup > 0.0:
        raise ConfigError(f"--speedup must be > 0, got {args.speedup}")
    if args.seed is not None and args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    if args.duration is not None and not args.duration > 0.0:
        raise ConfigError(f"--duration must be > 0, got {args.duration}")
    network = scenario.network.model_copy(
        update={
            key: value
            for key, value in (("gcs_host", args.gcs_host), ("bind_host", args.bind_host))
            if value is not None
        }
    )
    return scenario.model_copy(update={"network": network}).build(
        count=args.vehicles,
        base_port=args.base_port,
        speedup=args.speedup,
        seed=args.seed,
        autopilot=args.autopilot,
    )


def run(args: argparse.Namespace) -> int:
    import asyncio

    from app.compose.simulator import serve

    config = build_sim_config(args)
    return asyncio.run(serve(config, args.duration, sys.stdout))
