"""``standoff sitl``: run the built-in MAVLink simulator alone until interrupted."""

import argparse
import asyncio
import contextlib
import signal
import sys
from typing import TextIO

from app.config import load_config
from app.config.simulator import SitlScenario
from app.errors import ConfigError, LinkError
from sitl.config import SimConfig
from sitl.server import SimulatorServer

ORDER = 20


def register(subparsers: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
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
    config = build_sim_config(args)
    return asyncio.run(serve(config, args.duration, sys.stdout))


async def serve(config: SimConfig, duration_s: float | None, out: TextIO) -> int:
    """Run the simulator, print its endpoints, stop on SIGINT/SIGTERM or after ``duration_s``."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    try:
        async with SimulatorServer(config) as sim:
            _print_endpoints(sim, out)
            async with asyncio.TaskGroup() as group:
                timer = None
                if duration_s is not None:
                    timer = group.create_task(_stop_at(sim, duration_s, stop), name="sitl-timer")
                await stop.wait()
                if timer is not None:
                    timer.cancel()
            total = sim.stats_total()
            print(
                f"stopped at t = {sim.time_s:.1f} s simulated: {total.packets_in} packets in "
                f"({total.dropped} dropped), {total.packets_out} out",
                file=out,
                flush=True,
            )
    except OSError as exc:  # a vehicle socket that cannot be bound (port taken, bad host)
        raise LinkError(f"cannot open the vehicle sockets: {exc}") from exc
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.remove_signal_handler(sig)
    return 0


async def _stop_at(sim: SimulatorServer, duration_s: float, stop: asyncio.Event) -> None:
    await sim.wait_until(duration_s)
    stop.set()


def _print_endpoints(sim: SimulatorServer, out: TextIO) -> None:
    config = sim.config
    print(
        f"standoff sitl: {len(sim.endpoints)} vehicles, speed-up {config.speedup:g}x, "
        f"seed {config.seed}, origin {config.origin_lat_deg:.6f}, {config.origin_lon_deg:.6f}, "
        f"autopilot {config.autopilot}",
        file=out,
    )
    for endpoint in sim.endpoints:
        print(
            f"  vehicle {endpoint.system_id}: sends to {endpoint.gcs_host}:{endpoint.gcs_port} "
            f"from {endpoint.local_host}:{endpoint.local_port}   "
            f"MAVSDK: {endpoint.mavsdk_url}",
            file=out,
        )
    print("running; Ctrl-C to stop", file=out, flush=True)
