"""Capacity of the built-in simulator: CPU for 50 vehicles at 1x, achieved speed-up for 3.

Run:  .venv/bin/python -m benchmarks.bench_sitl [--seconds 20] [--vehicles 50]

The simulator runs in this process; a load generator in a child process plays the ground
station for every vehicle over UDP (arms it, puts it in offboard and resends a velocity setpoint
at 20 Hz wall time, as MAVSDK does, and drains the telemetry). The figure is this process's CPU
time over wall time (1.0 = one core busy).
"""

import argparse
import asyncio
import math
import multiprocessing
import select
import socket
import time
from dataclasses import replace

from pymavlink.dialects.v20 import common as mavlink

from sitl.config import SimConfig, default_vehicles
from sitl.ports import find_free_udp_base_port
from sitl.server import SimulatorServer


def _load_generator(
    base_port: int, count: int, seconds: float, ready: "multiprocessing.synchronize.Event"
) -> None:
    enc = mavlink.MAVLink(None, 255, 190)
    socks = []
    for i in range(count):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", base_port + i))
        s.setblocking(False)
        socks.append(s)
    ready.set()
    peers: dict[int, tuple[str, int]] = {}
    index = {s.fileno(): i for i, s in enumerate(socks)}
    mask = 1 | 2 | 4 | 64 | 128 | 256 | 1024 | 2048  # velocity only
    packed: dict[int, list[bytes]] = {}
    for i in range(count):
        sysid = i + 1
        course = 2.0 * math.pi * i / count
        setpoint = mavlink.MAVLink_set_position_target_local_ned_message(
            0,
            sysid,
            1,
            mavlink.MAV_FRAME_LOCAL_NED,
            mask,
            0,
            0,
            0,
            18.0 * math.cos(course),
            18.0 * math.sin(course),
            0,
            0,
            0,
            0,
            0,
            0,
        )
        arm = mavlink.MAVLink_command_long_message(
            sysid, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
        )
        offboard = mavlink.MAVLink_command_long_message(
            sysid, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, 6, 0, 0, 0, 0, 0
        )
        packed[i] = [bytes(m.pack(enc)) for m in (setpoint, arm, offboard)]
    start = time.monotonic()
    next_send = start
    while time.monotonic() - start < seconds:
        timeout = max(0.0, next_send - time.monotonic())
        readable, _, _ = select.select(socks, [], [], timeout)
        for s in readable:
            while True:
                try:
                    _, addr = s.recvfrom(4096)
                except BlockingIOError:
                    break
                peers[index[s.fileno()]] = addr
        if time.monotonic() >= next_send:
            next_send += 0.05
            early = time.monotonic() - start < 2.0
            for i, addr in peers.items():
                setpoint, arm, offboard = packed[i]
                socks[i].sendto(setpoint, addr)
                if early:
                    socks[i].sendto(arm, addr)
                    socks[i].sendto(offboard, addr)
    for s in socks:
        s.close()


async def _measure(config: SimConfig, seconds: float) -> dict[str, float]:
    ctx = multiprocessing.get_context("spawn")
    ready = ctx.Event()
    load = ctx.Process(
        target=_load_generator, args=(config.base_port, len(config.vehicles), seconds + 3.0, ready)
    )
    load.start()
    try:
        await asyncio.to_thread(ready.wait, 20.0)
        async with SimulatorServer(config) as sim:
            await asyncio.sleep(2.0)  # connect, arm, offboard
            cpu0, wall0, t0 = time.process_time(), time.monotonic(), sim.time_s
            packets0 = sim.stats_total()
            await asyncio.sleep(seconds)
            cpu1, wall1, t1 = time.process_time(), time.monotonic(), sim.time_s
            packets1 = sim.stats_total()
            offboard = sum(v.mode.name == "offboard" for v in sim.vehicles)
            lag = sim.lag_events
    finally:
        load.join(timeout=10.0)
        if load.is_alive():
            load.terminate()
    wall = wall1 - wall0
    return {
        "cpu_cores": (cpu1 - cpu0) / wall,
        "achieved_speedup": (t1 - t0) / wall,
        "packets_in_per_s": (packets1.packets_in - packets0.packets_in) / wall,
        "packets_out_per_s": (packets1.packets_out - packets0.packets_out) / wall,
        "offboard": float(offboard),
        "lag_events": float(lag),
    }


def _config(count: int, speedup: float) -> SimConfig:
    base = find_free_udp_base_port(count, host="127.0.0.1")
    return replace(
        SimConfig(vehicles=default_vehicles(count), speedup=speedup, telemetry_rate_hz=10.0),
        base_port=base,
    )


def _report(label: str, figures: dict[str, float], count: int) -> None:
    print(
        f"{label:<34} cpu {figures['cpu_cores']:5.2f} core  "
        f"achieved speed-up {figures['achieved_speedup']:6.1f}x  "
        f"in {figures['packets_in_per_s']:7.0f}/s  out {figures['packets_out_per_s']:7.0f}/s  "
        f"offboard {int(figures['offboard'])}/{count}  lag events {int(figures['lag_events'])}",
        flush=True,
    )


async def _main(seconds: float, vehicles: int) -> None:
    print(
        f"built-in simulator capacity ({seconds:g} s wall per run, 10 Hz telemetry, "
        f"setpoints at 20 Hz wall)"
    )
    figures = await _measure(_config(vehicles, 1.0), seconds)
    _report(f"{vehicles} vehicles at 1x", figures, vehicles)
    for speedup in (20.0, 50.0, 100.0):
        figures = await _measure(_config(3, speedup), seconds)
        _report(f"3 vehicles at {speedup:g}x", figures, 3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="wall seconds per run")
    parser.add_argument("--vehicles", type=int, default=50, help="vehicles in the 1x run")
    args = parser.parse_args()
    asyncio.run(_main(args.seconds, args.vehicles))


if __name__ == "__main__":
    main()
