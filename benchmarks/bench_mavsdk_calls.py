"""What MAVSDK's plugin calls cost the mission's process: its asyncio wrappers against the calls
made on the loop (``app.adapters.vehicle.mavsdk.direct``), side by side in one run.

Run:  .venv/bin/python -m benchmarks.bench_mavsdk_calls [--vehicles N] [--seconds S] [--rounds R]

The built-in simulator (``standoff sitl``, a process of its own, so that its CPU is not counted)
flies N vehicles at real time. This process connects to them with MAVSDK and, for each vehicle,
does what a mission's link does all flight long: it reads GLOBAL_POSITION_INT, VFR_HUD and
HEARTBEAT through MavlinkDirect and sends a velocity setpoint at 10 Hz. It does that for S
seconds through MAVSDK's asyncio wrappers (``OffboardAsync``, ``MavlinkDirectAsync``: a pool
thread per call, a loop wake-up per message), then for S seconds on the loop (the setpoint made
on the loop, the messages through one ``LoopInbox``), R times in turn. Printed per phase: the
process's CPU (all its threads: the pool's and MAVSDK's too) as a share of one core, per
vehicle, the messages read and setpoints sent, and the loop wake-ups the messages took; then
the ratio of the two ways' CPU.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import subprocess
import sys
import time
from collections.abc import AsyncGenerator, Awaitable, Callable
from contextlib import aclosing
from dataclasses import dataclass
from typing import Any

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
SETPOINT_PERIOD_S = 0.1


@dataclass
class Phase:
    way: str
    cpu_s: float
    wall_s: float
    messages: int
    setpoints: int
    wakeups: int | None


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


async def fly_phase(plugins: list[Plugins], seconds: float) -> tuple[int, int]:
    """Read the messages and send the setpoints for ``seconds``; the counts of both."""
    counts = {"messages": 0, "setpoints": 0}

    async def read(vehicle: Plugins, name: str) -> None:
        async with aclosing(vehicle.subscribe(name)) as messages:
            async for _ in messages:
                counts["messages"] += 1

    async def steer(vehicle: Plugins, offset_s: float) -> None:
        await asyncio.sleep(offset_s)
        course = 0.0
        while True:
            course += 0.01
            value = VelocityNedYaw(15.0 * math.cos(course), 15.0 * math.sin(course), 0.0, 0.0)
            await vehicle.send(value)
            counts["setpoints"] += 1
            await asyncio.sleep(SETPOINT_PERIOD_S)

    tasks = [asyncio.create_task(read(v, name)) for v in plugins for name in MESSAGES]
    tasks += [
        asyncio.create_task(steer(v, SETPOINT_PERIOD_S * i / len(plugins)))
        for i, v in enumerate(plugins)
    ]
    await asyncio.sleep(seconds)
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    return counts["messages"], counts["setpoints"]


async def run(base: int, vehicles: int, seconds: float, rounds: int) -> list[Phase]:
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
        phases: list[Phase] = []
        for _ in range(rounds):
            for way in ("asyncio wrappers", "on the loop"):
                inbox = LoopInbox(loop)
                plugins = [
                    wrapped(s) if way == "asyncio wrappers" else on_loop(s, inbox) for s in systems
                ]
                await asyncio.sleep(1.0)  # the subscriptions settle
                cpu0, wall0 = time.process_time(), time.monotonic()
                messages, setpoints = await fly_phase(plugins, seconds)
                cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
                wakeups = inbox.wakeups if way == "on the loop" else None
                phases.append(Phase(way, cpu, wall, messages, setpoints, wakeups))
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
    args = parser.parse_args()
    base = find_free_udp_base_port(args.vehicles)
    command = ["sitl", "--vehicles", str(args.vehicles), "--base-port", str(base)]
    sim = subprocess.Popen(
        [sys.executable, "-m", "app", *command, "--speedup", "1"], stderr=subprocess.DEVNULL
    )
    try:
        phases = asyncio.run(run(base, args.vehicles, args.seconds, args.rounds))
    finally:
        sim.terminate()
        sim.wait(10.0)
    n = args.vehicles
    print(f"{n} vehicles, {args.seconds:.0f} s per phase, the simulator in its own process")
    print(
        f"{'way':18s} {'CPU % core':>10s} {'per vehicle':>11s} {'messages':>9s} "
        f"{'setpoints':>9s} {'wake-ups':>9s}"
    )
    for p in phases:
        share = 100.0 * p.cpu_s / p.wall_s
        wakeups = "-" if p.wakeups is None else str(p.wakeups)
        print(
            f"{p.way:18s} {share:10.2f} {share / n:11.3f} {p.messages:9d} {p.setpoints:9d} "
            f"{wakeups:>9s}"
        )
    for r in range(args.rounds):
        wrapped_phase, loop_phase = phases[2 * r], phases[2 * r + 1]
        ratio = (loop_phase.cpu_s / loop_phase.wall_s) / (
            wrapped_phase.cpu_s / wrapped_phase.wall_s
        )
        print(f"round {r + 1}: on the loop / asyncio wrappers CPU = {ratio:.2f}x")


if __name__ == "__main__":
    main()
