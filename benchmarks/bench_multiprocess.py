"""One mission two ways: in one process (``standoff fly``) and as 4 processes over mosquitto.

    python -m benchmarks.bench_multiprocess [CONFIG] [--out DIR] [--broker URL]

Flies CONFIG (default: the paper's section 5.2 mission, ``configs/hil.toml``) on the built-in
simulator first with ``Mission.run`` (in-process bus), then as ``standoff ground --sitl`` plus
one ``standoff agent`` per vehicle, each a process of its own, over a mosquitto started on a free
loopback port (or ``--broker``). Prints the summary figures side by side with their ratio
(multi-process / in-process): the gather + adjust times from the tracking command, and the RMS
distance and spacing errors per part of the run. The issue's target is every ratio within 10 %.
Each run takes about as long as ``standoff fly`` (2-3 min of wall time for the default).

One live run varies from the next by about as much as the two ways differ (the simulator runs
in real time at the config's speed-up, so the moment each estimate and setpoint lands moves
from run to run, and the state at a target manoeuvre is sensitive to it). ``--pairs N`` flies N
pairs, interleaved (one process, then four, ...), and compares the means; beside the ratio it
prints each way's run-to-run spread (sample standard deviation over mean), which says how far
apart two identical set-ups already are.
"""

import argparse
import asyncio
import contextlib
import json
import math
import signal
import statistics
import sys
import tempfile
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

from app.compose.mission import Mission
from app.config import load_config, resolve_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from sitl.ports import find_free_udp_base_port

STARTUP_TIMEOUT_S = 60.0


async def in_process(config_name: str, out: Path) -> dict[str, Any]:
    config = load_config(config_name, MissionConfig).model_copy(update={"bus": None})
    plan = build_plan(config)
    result = await Mission(plan, out, base_port=find_free_udp_base_port(plan.count)).run()
    return result.summary


@contextlib.asynccontextmanager
async def standoff(*args: str, log: Path) -> AsyncIterator[asyncio.subprocess.Process]:
    """``python -m app ARGS`` with stdout piped (readiness lines) and stderr to ``log``."""
    with log.open("wb") as err:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "app", *args, stdout=asyncio.subprocess.PIPE, stderr=err
        )
        try:
            yield proc
        finally:
            if proc.returncode is None:
                proc.send_signal(signal.SIGINT)
                try:
                    async with asyncio.timeout(20.0):
                        await proc.communicate()
                except TimeoutError:
                    proc.kill()
                    await proc.wait()


async def wait_line(proc: asyncio.subprocess.Process, needle: str) -> None:
    assert proc.stdout is not None
    async with asyncio.timeout(STARTUP_TIMEOUT_S):
        while True:
            line = await proc.stdout.readline()
            if not line:
                raise RuntimeError(f"process exited before printing {needle!r}")
            if needle.encode() in line:
                return


async def multi_process(config_name: str, out: Path, broker: str) -> dict[str, Any]:
    """Agents first (each listens on its vehicle's port), then the ground with the simulator."""
    config = load_config(config_name, MissionConfig)
    n = config.vehicles
    base_port = find_free_udp_base_port(n)
    path = str(resolve_config(config_name))
    common = [path, "--broker", broker, "--base-port", str(base_port), "--out", str(out)]
    async with contextlib.AsyncExitStack() as stack:
        agents = []
        for i in range(n):
            agents.append(
                await stack.enter_async_context(
                    standoff(
                        "agent", "--vehicle", str(i + 1), *common, log=out / f"agent-{i + 1}.err"
                    )
                )
            )
        for i, agent in enumerate(agents):
            await wait_line(agent, f"waiting for vehicle {i + 1}")
        ground = await stack.enter_async_context(
            standoff("ground", *common, "--sitl", "--quiet", log=out / "ground.err")
        )
        await ground.communicate()
        for agent in agents:
            await agent.communicate()
        codes = [agent.returncode for agent in agents]
    if ground.returncode != 0 or any(codes):
        raise RuntimeError(
            f"ground exited {ground.returncode}, agents {codes}: see the .err files in {out}"
        )
    summary: dict[str, Any] = json.loads((out / "summary.json").read_text())
    return summary


@contextlib.contextmanager
def broker_url(given: str | None, workdir: Path) -> Iterator[str]:
    if given is not None:
        yield given
        return
    from tests.support.mosquitto import Mosquitto  # the test helper starts a throwaway broker

    broker = Mosquitto(workdir)
    broker.start()
    try:
        yield broker.url
    finally:
        broker.stop()


def figures(summary: dict[str, Any]) -> dict[str, float | None]:
    """The compared figures of one run, by name."""
    conv = summary["convergence"]
    out: dict[str, float | None] = {
        "on the circle (s from command)": conv.get("time_to_circle_s"),
        "spaced (s from command)": conv.get("time_to_spacing_s"),
        "gather + adjust (s from command)": conv.get("time_to_formation_s"),
    }
    parts = summary["parts"]
    track = [p["team"]["start_s"] for k, p in parts.items() if k.startswith("track")]
    out["track starts (s from command)"] = min(track) if track else None
    for key, part in parts.items():
        if key == "standby":
            continue
        team = part["team"]
        out[f"{key} RMS distance (m)"] = team.get("distance_error_m", {}).get("rms")
        out[f"{key} RMS spacing (deg)"] = team.get("spacing_error_deg", {}).get("rms")
    out["wall time (s)"] = summary.get("wall_s")
    # the ground dropping a vehicle it still hears (its statuses late) re-spaces the others
    out["vehicles left the formation"] = float(summary.get("events", {}).get("vehicle_left", 0))
    return out


def _num(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:9.2f}"


def _finite(values: list[float | None]) -> list[float]:
    return [v for v in values if v is not None and math.isfinite(v)]


def _spread(values: list[float]) -> str:
    if len(values) < 2 or statistics.fmean(values) == 0.0:
        return "-"
    return f"{statistics.stdev(values) / abs(statistics.fmean(values)):6.0%}"


def table(ones: list[dict[str, Any]], multis: list[dict[str, Any]]) -> str:
    """Means of each figure over the runs of each way, their ratio and each way's spread."""
    a = [figures(s) for s in ones]
    b = [figures(s) for s in multis]
    names: list[str] = []
    for row in a + b:
        names += [k for k in row if k not in names]
    width = max(len(k) for k in names)
    lines = [
        f"{'figure':<{width}}  {'1 process':>9}  {'4 procs':>9}  {'ratio':>6}  "
        f"{'spread 1':>8}  {'spread 4':>8}"
    ]
    for name in names:
        xs = _finite([row.get(name) for row in a])
        ys = _finite([row.get(name) for row in b])
        x = statistics.fmean(xs) if xs else None
        y = statistics.fmean(ys) if ys else None
        ratio = "-"
        if x is not None and y is not None and x != 0:
            ratio = f"{y / x:6.2f}"
        lines.append(
            f"{name:<{width}}  {_num(x):>9}  {_num(y):>9}  {ratio:>6}  "
            f"{_spread(xs):>8}  {_spread(ys):>8}"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_multiprocess")
    parser.add_argument("config", nargs="?", default="hil")
    parser.add_argument("--out", type=Path, help="keep the run folders here")
    parser.add_argument("--broker", help="an MQTT URL; default: start a mosquitto on loopback")
    parser.add_argument("--pairs", type=int, default=1, help="pairs of runs to average (1)")
    args = parser.parse_args()
    if args.pairs < 1:
        parser.error("--pairs must be at least 1")
    ones: list[dict[str, Any]] = []
    multis: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="bench-mp-") as tmp:
        root = args.out or Path(tmp)
        with broker_url(args.broker, Path(tmp)) as url:
            for k in range(args.pairs):
                print(f"pair {k + 1}/{args.pairs}: {args.config} in one process ...", flush=True)
                ones.append(asyncio.run(in_process(args.config, root / f"one-process-{k}")))
                print(f"pair {k + 1}/{args.pairs}: ground + agents over {url} ...", flush=True)
                folder = root / f"multi-process-{k}"
                folder.mkdir(parents=True, exist_ok=True)  # the agents' logs
                multis.append(asyncio.run(multi_process(args.config, folder, url)))
    print(f"means over {args.pairs} pair(s); spread = standard deviation / mean over the runs")
    print(table(ones, multis))
    return 0


if __name__ == "__main__":
    sys.exit(main())
