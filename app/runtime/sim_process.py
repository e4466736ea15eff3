"""The built-in simulator for a mission, in a process of its own.

``standoff fly`` runs the simulator beside the mission rather than inside it, so that the two
do not share one interpreter (and its lock) and a high speed-up stays faithful on two cores::

    python -m app.runtime.sim_process MISSION.json --base-port P [--vehicles N]

MISSION.json is a validated mission config (``MissionConfig``) as JSON; the simulator is the one
``app.config.plan.sim_config`` builds from it. It prints its endpoints and ``running`` once
the vehicles are up, and stops on SIGINT or SIGTERM.
"""

import argparse
import asyncio
import contextlib
import sys
from collections.abc import AsyncIterator, Sequence
from pathlib import Path

from app.config.mission import MissionConfig
from app.errors import LinkError


def main(argv: Sequence[str] | None = None) -> int:
    from app.cli.sitl import serve  # the `standoff sitl` server loop (signals, endpoints)
    from app.config.plan import build_plan, sim_config

    parser = argparse.ArgumentParser(prog="python -m app.runtime.sim_process")
    parser.add_argument("config", type=Path)
    parser.add_argument("--base-port", type=int, required=True)
    parser.add_argument("--vehicles", type=int)
    args = parser.parse_args(argv)
    config = MissionConfig.model_validate_json(args.config.read_text(encoding="utf-8"))
    plan = build_plan(config, args.vehicles)
    return asyncio.run(serve(sim_config(plan, args.base_port), None, sys.stdout))


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
        "app.runtime.sim_process",
        str(path),
        "--base-port",
        str(base_port),
        "--vehicles",
        str(vehicles),
        stdout=asyncio.subprocess.PIPE,
        stderr=log_file,
    )
    try:
        assert proc.stdout is not None
        try:
            async with asyncio.timeout(timeout_s):
                while True:
                    line = await proc.stdout.readline()
                    if not line:
                        err = b"" if proc.stderr is None else await proc.stderr.read()
                        raise LinkError(
                            "the built-in simulator did not start: "
                            + (err.decode(errors="replace").strip().splitlines() or ["no output"])[
                                -1
                            ]
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
        log_file.close()
        with contextlib.suppress(OSError):
            path.unlink()


if __name__ == "__main__":
    sys.exit(main())
