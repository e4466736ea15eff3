"""What MAVSDK's plugin calls cost the mission's process: its asyncio wrappers against the calls
made on the loop (``app.adapters.vehicle.mavsdk.direct``), side by side in one run.

Run:  .venv/bin/python -m benchmarks.bench_mavsdk_calls [--vehicles N] [--seconds S] [--rounds R]

The built-in simulator (``standoff sitl``, a process of its own, so that its CPU is not counted)
flies N vehicles at real time. This process connects to them with MAVSDK and, for each vehicle,
does what a mission's link and agent do all flight long: it reads GLOBAL_POSITION_INT, VFR_HUD
and HEARTBEAT through MavlinkDirect and answers each position with a tick of CPU (``--tick-ms``,
an agent's median tick) and a velocity setpoint. It does that for S seconds through MAVSDK's
asyncio wrappers (``OffboardAsync``, ``MavlinkDirectAsync``: a pool thread per call, a loop
wake-up per message), then for S seconds on the loop (the setpoint made on the loop, the
messages through one ``LoopInbox``), R times in turn. Printed first: how long a setpoint and a
``send_message`` made on the loop hold it. Then, per phase: the process's CPU (all its threads:
the pool's and MAVSDK's too) as a share of one core, the same without the ticks per vehicle (the
link's own cost), the messages read and setpoints sent, the loop wake-ups the messages took,
and how late the positions reached the reader (host arrival against the vehicle's boot time,
above each vehicle's least: the spread of the delivery delay);
then the ratio of the two ways' CPU without the ticks.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import subprocess
import sys
import time
from collections.abc import AsyncGenerator, Awaitable, Callable
from contextlib import aclosing
from dataclasses import dataclass
from typing import Any

import numpy as np
from mavsdk import ComponentType, Configuration, ForwardingOption, Mavsdk, System
from mavsdk.asyncio import System as AsyncSystem
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.plugins.mavlink_direct import MavlinkDirect, MavlinkMessage
from mavsdk.plugins.offboard import Offboard, VelocityNedYaw

from app.adapters.vehicle.mavsdk.direct import LoopInbox, LoopMavlinkDirect, LoopOffboard
from app.adapters.vehicle.mavsdk.logs import route_mavsdk_logs
from sitl.ports import find_free_udp_base_port

MESSAGES = ("GLOBAL_POSITION_INT", "VFR_HUD", "HEARTBEAT")


@dataclass
class Phase:
    way: str
    cpu_s: float
    wall_s: float
    messages: int
    setpoints: int
    wakeups: int | None
    late_s: list[float]


class Plugins:
    """One vehicle's two plugins, one way or the other."""

    def __init__(
        self,
        subscribe: Callable[[str], AsyncGenerator[MavlinkMessage]],
        send: Callable[[VelocityNedYaw], Awaitable[Any]],
        keep: tuple[object, ...],
    ) -> None:
        self.subscribe = subscribe
        self.send = send
        self._keep = keep  # the plugin objects: MAVSDK stops resending when they go


def wrapped(system: System) -> Plugins:
    async_system = AsyncSystem(system)
    offboard, direct = OffboardAsync(async_system), MavlinkDirectAsync(async_system)
    return Plugins(direct.subscribe_message, offboard.set_velocity_ned, (offboard, direct))


def on_loop(system: System, inbox: LoopInbox) -> Plugins:
    offboard = LoopOffboard(Offboard(system))
    direct = LoopMavlinkDirect(MavlinkDirect(system), inbox)
    return Plugins(direct.subscribe_message, offboard.set_velocity_ned, (offboard, direct))


def busy(seconds: float) -> None:
    """Hold the loop for ``seconds`` of CPU, as an agent's tick does."""
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass


async def fly_phase(
    plugins: list[Plugins], seconds: float, tick_s: float
) -> tuple[int, int, list[float]]:
    """Read the messages for ``seconds``, answering each vehicle's GLOBAL_POSITION_INT with a
    tick of ``tick_s`` and a setpoint; the counts of messages and setpoints, and each
    position's lateness (its host arrival against its boot time, above the vehicle's least)."""
    counts = {"messages": 0, "setpoints": 0}
    offsets: list[list[float]] = [[] for _ in plugins]

    async def read(i: int, name: str) -> None:
        vehicle = plugins[i]
        async with aclosing(vehicle.subscribe(name)) as messages:
            async for message in messages:
                counts["messages"] += 1
                if name != "GLOBAL_POSITION_INT":
                    continue
                boot_s = json.loads(message.fields_json)["time_boot_ms"] / 1000.0
                offsets[i].append(time.monotonic() - boot_s)
                busy(tick_s)
                course = 0.01 * counts["setpoints"]
                value = VelocityNedYaw(15.0 * math.cos(course), 15.0 * math.sin(course), 0.0, 0.0)
                await vehicle.send(value)
                counts["setpoints"] += 1

    tasks = [asyncio.create_task(read(i, name)) for i in range(len(plugins)) for name in MESSAGES]
    await asyncio.sleep(seconds)
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    late = [o - min(each) for each in offsets if each for o in each]
    return counts["messages"], counts["setpoints"], late


def print_call_times(system: System, calls: int = 2000) -> None:
    """How long the calls made on the loop hold it: MAVSDK's blocking setpoint and
    ``send_message`` on one vehicle, ``calls`` each (p50 / p99 / max in microseconds, and how
    many took over a millisecond)."""
    offboard, direct = Offboard(system), MavlinkDirect(system)
    setpoint = VelocityNedYaw(10.0, 5.0, 0.0, 30.0)
    fields = {"tc1": 0, "ts1": 1, "target_system": 1, "target_component": 1}
    timesync = MavlinkMessage(
        message_name="TIMESYNC",
        target_system_id=1,
        target_component_id=1,
        fields_json=json.dumps(fields),
    )
    for name, call in (
        ("Offboard.set_velocity_ned", lambda: offboard.set_velocity_ned(setpoint)),
        ("MavlinkDirect.send_message", lambda: direct.send_message(timesync)),
    ):
        held = []
        for _ in range(calls):
            start = time.perf_counter()
            call()
            held.append(time.perf_counter() - start)
        p50, p99, most = np.percentile(np.asarray(held) * 1e6, [50, 99, 100])
        slow = sum(h > 1e-3 for h in held)
        print(
            f"{name}: {calls} calls, p50 {p50:.1f} us, p99 {p99:.1f} us, max {most:.0f} us, "
            f"{slow} over 1 ms"
        )


async def run(base: int, vehicles: int, seconds: float, rounds: int, tick_s: float) -> list[Phase]:
    route_mavsdk_logs()  # to the logger, as a mission's hub does, not the terminal
    loop = asyncio.get_running_loop()
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        for i in range(vehicles):
            url = f"udpin://127.0.0.1:{base + i}"
            await loop.run_in_executor(
                None,
                mavsdk.add_any_connection_with_handle_and_forwarding,
                url,
                ForwardingOption.OFF,
            )
        async with asyncio.timeout(30.0):
            while True:
                systems = [s for s in mavsdk.get_systems() if s.has_autopilot()]
                if len(systems) == vehicles:
                    break
                await asyncio.sleep(0.2)
        print_call_times(systems[0])
        phases: list[Phase] = []
        for _ in range(rounds):
            for way in ("asyncio wrappers", "on the loop"):
                inbox = LoopInbox(loop)
                plugins = [
                    wrapped(s) if way == "asyncio wrappers" else on_loop(s, inbox) for s in systems
                ]
                await asyncio.sleep(1.0)  # the subscriptions settle
                cpu0, wall0 = time.process_time(), time.monotonic()
                messages, setpoints, late = await fly_phase(plugins, seconds, tick_s)
                cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
                wakeups = inbox.wakeups if way == "on the loop" else None
                phases.append(Phase(way, cpu, wall, messages, setpoints, wakeups, late))
                del plugins
                await asyncio.sleep(0.5)
        return phases
    finally:
        mavsdk.destroy()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=10)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument(
        "--tick-ms", type=float, default=0.6, help="CPU per position frame (an agent's tick)"
    )
    args = parser.parse_args()
    base = find_free_udp_base_port(args.vehicles)
    command = ["sitl", "--vehicles", str(args.vehicles), "--base-port", str(base)]
    sim = subprocess.Popen(
        [sys.executable, "-m", "app", *command, "--speedup", "1"], stderr=subprocess.DEVNULL
    )
    try:
        phases = asyncio.run(
            run(base, args.vehicles, args.seconds, args.rounds, args.tick_ms / 1000.0)
        )
    finally:
        sim.terminate()
        sim.wait(10.0)
    n, tick_s = args.vehicles, args.tick_ms / 1000.0
    print(
        f"{n} vehicles, {args.seconds:.0f} s per phase, a {args.tick_ms:g} ms tick per position, "
        "the simulator in its own process"
    )
    print(
        f"{'way':18s} {'CPU % core':>10s} {'link / veh':>10s} {'messages':>9s} "
        f"{'setpoints':>9s} {'wake-ups':>9s}  position late p50 / p90 / p99 / max (ms)"
    )

    def link_share(p: Phase) -> float:
        return 100.0 * (p.cpu_s - p.setpoints * tick_s) / p.wall_s

    for p in phases:
        wakeups = "-" if p.wakeups is None else str(p.wakeups)
        late = np.percentile(np.asarray(p.late_s) * 1000.0, [50, 90, 99, 100])
        print(
            f"{p.way:18s} {100.0 * p.cpu_s / p.wall_s:10.2f} {link_share(p) / n:10.3f} "
            f"{p.messages:9d} {p.setpoints:9d} {wakeups:>9s}  "
            + " / ".join(f"{v:.1f}" for v in late)
        )
    for r in range(args.rounds):
        wrapped_phase, loop_phase = phases[2 * r], phases[2 * r + 1]
        ratio = link_share(loop_phase) / link_share(wrapped_phase)
        print(f"round {r + 1}: the link's CPU, on the loop / asyncio wrappers = {ratio:.2f}x")


if __name__ == "__main__":
    main()
