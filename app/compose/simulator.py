"""The built-in simulator served until stopped: alone (``standoff sitl``) or for a mission, in a
process of its own.

``serve`` runs it, prints its endpoints and stops on SIGINT/SIGTERM. ``standoff fly`` runs the
simulator beside the mission rather than inside it, so that the two do not share one
interpreter (and its lock) and a high speed-up stays faithful on two cores::

    python -m app.compose.simulator MISSION.json --base-port P [--vehicles N]

MISSION.json is a validated mission config (``MissionConfig``) as JSON; the simulator is the one
``app.config.plan.sim_config`` builds from it. It prints its endpoints and ``running`` once
the vehicles are up, and stops on SIGINT or SIGTERM; with ``--parent-pipe`` also when its
standard input closes.

``standoff fly`` starts it in a session of its own, so that a Ctrl-C in the terminal (which
signals the whole foreground process group) reaches the mission alone: the mission puts every
vehicle in hold and only then stops the simulator. Before, the simulator stopped at the same
moment, and with twenty vehicles every hold on exit after the first timed out on a silent
link. Its standard input is a pipe from the mission, which closes however the mission ends:
a mission killed outright (SIGKILL) leaves no simulator behind.
"""

import argparse
import asyncio
import contextlib
import signal
import sys
from collections.abc import AsyncIterator, Sequence
from pathlib import Path
from typing import TextIO

from app.config.mission import MissionConfig
from app.config.plan import build_plan, sim_config
from app.errors import LinkError, StandoffError
from sitl.config import SimConfig
from sitl.server import SimulatorServer


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m app.compose.simulator")
    parser.add_argument("config", type=Path)
    parser.add_argument("--base-port", type=int, required=True)
    parser.add_argument("--vehicles", type=int)
    parser.add_argument(
        "--parent-pipe",
        action="store_true",
        help="stop when standard input closes (the process that started it has gone)",
    )
    args = parser.parse_args(argv)
    config = MissionConfig.model_validate_json(args.config.read_text(encoding="utf-8"))
    try:
        plan = build_plan(config, args.vehicles)
        config_sim = sim_config(plan, args.base_port)
        return asyncio.run(serve(config_sim, None, sys.stdout, stop_on_eof=args.parent_pipe))
    except StandoffError as exc:  # the reason, as the last line of simulator.log
        print(f"error: {exc}", file=sys.stderr, flush=True)
        return 2


@contextlib.asynccontextmanager
async def simulator_process(
    config: MissionConfig, vehicles: int, base_port: int, workdir: Path, timeout_s: float = 30.0
) -> AsyncIterator[asyncio.subprocess.Process]:
    """Start the simulator process, wait until it runs, and stop it (SIGINT) on exit."""
    path = workdir / "sim-config.json"
    path.write_text(config.model_dump_json(), encoding="utf-8")
    log_path = workdir / "simulator.log"
    log_file = log_path.open("wb")  # the simulator's own log, kept in the run folder
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "app.compose.simulator",
        str(path),
        "--base-port",
        str(base_port),
        "--vehicles",
        str(vehicles),
        "--parent-pipe",
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=log_file,
        start_new_session=True,
    )
    try:
        assert proc.stdout is not None
        try:
            async with asyncio.timeout(timeout_s):
                while True:
                    line = await proc.stdout.readline()
                    if not line:
                        code = await proc.wait()
                        raise LinkError(
                            "the built-in simulator did not start: "
                            + failure_reason(log_path, code)
                        )
                    if line.startswith(b"running"):
                        break
        except TimeoutError as exc:
            raise LinkError(f"the built-in simulator did not start within {timeout_s} s") from exc
        yield proc
    finally:
        if proc.returncode is None:
            proc.send_signal(2)  # SIGINT: the simulator stops cleanly
            try:
                async with asyncio.timeout(10.0):
                    await proc.wait()
            except TimeoutError:
                proc.kill()
                await proc.wait()
        if proc.stdin is not None:
            proc.stdin.close()
        log_file.close()
        with contextlib.suppress(OSError):
            path.unlink()


def failure_reason(log_path: Path, exit_code: int | None) -> str:
    """Why the simulator process stopped: the last line of its log (its error, or the last
    line of a traceback), else its exit code."""
    try:
        lines = log_path.read_text(encoding="utf-8", errors="replace").strip().splitlines()
    except OSError:
        lines = []
    if lines:
        return f"{lines[-1].strip()} (see {log_path})"
    return f"it exited with code {exit_code} and wrote nothing to {log_path}"


class _EndOfInput(asyncio.Protocol):
    """Sets ``stop`` when the pipe it reads closes; what comes through it is ignored."""

    def __init__(self, stop: asyncio.Event) -> None:
        self._stop = stop

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop.set()


async def serve(
    config: SimConfig, duration_s: float | None, out: TextIO, *, stop_on_eof: bool = False
) -> int:
    """Run the simulator, print its endpoints, stop on SIGINT/SIGTERM or after ``duration_s``
    (and, with ``stop_on_eof``, when standard input closes)."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    watch: asyncio.BaseTransport | None = None
    if stop_on_eof:
        watch, _ = await loop.connect_read_pipe(lambda: _EndOfInput(stop), sys.stdin)
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
        raise LinkError(f"cannot open the vehicle sockets: {exc}") from exc  # names the port
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.remove_signal_handler(sig)
        if watch is not None:
            watch.close()
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


if __name__ == "__main__":
    sys.exit(main())
