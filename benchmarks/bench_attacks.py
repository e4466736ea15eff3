"""The attacks of issue #14, each during the track stage of a live mission over a real mosquitto.

    python -m benchmarks.bench_attacks [CONFIG] [--only NAME ...] [--seconds S] [--rate HZ]
                                       [--speedup X] [--out DIR] [--mission-key]

Flies CONFIG (default ``test-short``: three vehicles, about 60 s of wall time at 2x) on the
built-in simulator, composed in this process (``Mission``) with its bus on a mosquitto started
on a free loopback port, once clean and once per attack. Each attack starts when the ground
station enters the track stage and sends its messages at ``--rate`` per second (default 5) for
``--seconds`` of wall time (default 10) from its own MQTT client (``intruder``), stamped from
the ground's mission time: forged statuses far in the future (sender agent-1 on vehicle 0's own
topic, so that the identity rule lets them through and the time window must refuse them),
forged ``estimate.global`` and ``estimate.local`` placing the target 500 m away, observations
stamped 1e5 s ahead, ``command/all`` hold claiming to be the ground, ``t_s`` 1e308 statuses and
observations, one-model ``estimate.local``, ``estimate.global`` with x = 1e200, the nesting bomb
retained on the mission topic, a garbage flood (100 KB of numbers a message), and a burst of 40
fake camera fixes 10 km away in 0.2 s into vehicle 1's MAVLink port, once a second.

With ``--mission-key`` the team seals its messages with a per-mission key the intruder does not
hold ([bus] mission_key_file, docs/bus.md): every forged message is then dropped unread (the
``command-hold`` attack, which nothing else can refuse on a broker without logins).

Prints per attack what it sent, whether the mission completed, how many times a vehicle left the
formation, the track stage's RMS distance error against the clean run's (ratio), the fused
estimate's largest error in track, and the counts of refused messages (the summary's ground
block, the agents' counters and the bus clients' drops). The issue's figures: every mission
completes, no vehicle leaves, the ratio stays within 1.2, every forged message is counted.
"""

import argparse
import asyncio
import json
import math
import random
import socket
import tempfile
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import paho.mqtt.publish
from pymavlink.dialects.v20 import common as mavlink

from app.adapters.bus import MqttBus
from app.adapters.bus.signing import MissionKey
from app.compose.mission import Mission
from app.compose.parts import MissionResult
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan, sim_config
from app.runtime.ports import messages as bus
from app.runtime.ports import topics
from app.runtime.ports.view import MissionSnapshot
from sitl.ports import find_free_udp_base_port
from sitl.server import SimulatorServer
from tests.support.mosquitto import Mosquitto

WALL_TIMEOUT_S = 300.0
EYE = tuple(tuple(1.0 if i == j else 0.0 for j in range(6)) for i in range(6))


@dataclass
class Context:
    mission: Mission
    intruder: MqttBus
    broker: Mosquitto
    base_port: int
    origin: tuple[float, float]
    tracking: asyncio.Event
    sent: int = 0

    def now(self) -> float:
        ground = self.mission.ground
        t = ground.state.mission_t_s if ground is not None else 0.0
        return t if math.isfinite(t) else 0.0

    def target(self) -> tuple[float, float]:
        ground = self.mission.ground
        fused = ground.state.fused if ground is not None else None
        return (float(fused.x[0]), float(fused.x[2])) if fused is not None else (0.0, 0.0)


Send = Callable[[Context, int], Awaitable[None]]


def _status(t: float, **change: Any) -> bus.VehicleStatus:
    values: dict[str, Any] = {
        "sender": "agent-1", "t_s": t, "vehicle": 0, "east_m": 0.0, "north_m": 90.0,
        "alt_m": 100.0, "course_rad": 0.0, "speed_m_s": 14.0, "phase_rad": 0.0,
        "stage": "track", "link": "ok", "healthy": True,
    }  # fmt: skip
    values.update(change)
    return bus.VehicleStatus(**values)


def _estimate_x(ctx: Context, off_m: float) -> tuple[float, ...]:
    e, n = ctx.target()
    return (e + off_m, 0.0, n, 0.0, 0.0, 0.0)


async def far_future_status(ctx: Context, _k: int) -> None:
    await ctx.intruder.publish(topics.status(0), _status(ctx.now() + 10_000.0))


async def status_1e308(ctx: Context, _k: int) -> None:
    await ctx.intruder.publish(topics.status(0), _status(1e308))


async def global_500m(ctx: Context, _k: int) -> None:
    message = bus.GlobalEstimate(
        sender="ground", t_s=ctx.now(), x=_estimate_x(ctx, 500.0), P=EYE, beta={0: 0.3, 1: 0.3}
    )
    await ctx.intruder.publish(topics.GLOBAL_ESTIMATE, message)


async def global_1e200(ctx: Context, _k: int) -> None:
    x = (1e200, 0.0, 0.0, 0.0, 0.0, 0.0)
    message = bus.GlobalEstimate(sender="ground", t_s=ctx.now(), x=x, P=EYE, beta={})
    await ctx.intruder.publish(topics.GLOBAL_ESTIMATE, message)


async def local_500m(ctx: Context, _k: int) -> None:
    message = bus.LocalEstimate(
        sender="agent-1", t_s=ctx.now(), vehicle=0, x=_estimate_x(ctx, 500.0), P=EYE
    )
    await ctx.intruder.publish(topics.local_estimate(0), message)


async def local_one_model(ctx: Context, _k: int) -> None:
    x = _estimate_x(ctx, 0.0)
    message = bus.LocalEstimate(
        sender="agent-1", t_s=ctx.now(), vehicle=0, x=x, P=EYE,
        mu=(1.0,), model_x=(x,), model_P=(EYE,),
    )  # fmt: skip
    await ctx.intruder.publish(topics.local_estimate(0), message)


def _observation(t: float, east: float, north: float) -> bus.TargetObservation:
    return bus.TargetObservation(
        sender="ground", t_s=t, sensor="ground-0", vehicle=0, east_m=east, north_m=north,
        sigma_m=3.0,
    )  # fmt: skip


async def future_observation(ctx: Context, _k: int) -> None:
    e, n = ctx.target()
    await ctx.intruder.publish(topics.observation(0), _observation(ctx.now() + 1e5, e, n))


async def observation_1e308(ctx: Context, _k: int) -> None:
    e, n = ctx.target()
    await ctx.intruder.publish(topics.observation(0), _observation(1e308, e, n))


async def command_hold(ctx: Context, _k: int) -> None:
    command = bus.Command(sender="ground", t_s=ctx.now(), command="hold")
    await ctx.intruder.publish(topics.command(), command, qos=1)


def _raw(ctx: Context, topic: topics.Topic, payload: bytes, retain: bool = False) -> None:
    paho.mqtt.publish.single(
        str(topic), payload, retain=retain, hostname="127.0.0.1", port=ctx.broker.port
    )


async def nesting_bomb(ctx: Context, _k: int) -> None:
    bomb = b"[" * 5000 + b"]" * 5000
    await asyncio.to_thread(_raw, ctx, topics.MISSION, bomb, True)


async def garbage_flood(ctx: Context, k: int) -> None:
    rng = random.Random(k)
    numbers = json.dumps([rng.random() for _ in range(5000)]).encode()  # ~100 KB
    payload = b'{"v":2,"kind":"status","sender":"agent-1","x":' + numbers + b"}"
    for topic in (topics.status(0), topics.GLOBAL_ESTIMATE, topics.observation(1)):
        await asyncio.to_thread(_raw, ctx, topic, payload)


async def fake_fixes(ctx: Context, _k: int) -> None:
    """40 CAMERA_TRACKING_GEO_STATUS 10 km away in 0.2 s into vehicle 1's MAVLink port."""
    lat0, lon0 = ctx.origin
    lat = lat0 + 10_000.0 / 6_371_000.0 * 180.0 / math.pi
    nan = math.nan
    link = mavlink.MAVLink(None, srcSystem=1, srcComponent=100)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for _ in range(40):
            message = mavlink.MAVLink_camera_tracking_geo_status_message(
                mavlink.CAMERA_TRACKING_STATUS_FLAGS_ACTIVE, round(lat * 1e7), round(lon0 * 1e7),
                0.0, 3.0, nan, nan, nan, nan, nan, 200.0, nan, nan,
            )  # fmt: skip
            sock.sendto(message.pack(link), ("127.0.0.1", ctx.base_port))
            await asyncio.sleep(0.005)
    finally:
        sock.close()


ATTACKS: dict[str, tuple[str, Send, float]] = {
    # name: (what is sent, how, sends per second: 0 = the --rate)
    "status-far-future": ("status of vehicle 0 as agent-1, t_s +10,000 s", far_future_status, 0),
    "estimate-global-500m": ("estimate.global from 'ground', target 500 m off", global_500m, 0),
    "estimate-local-500m": ("estimate.local from 'agent-1', target 500 m off", local_500m, 0),
    "observation-future": ("observation for vehicle 0, t_s +1e5 s", future_observation, 0),
    "command-hold": ("command/all hold with sender 'ground' from 'intruder'", command_hold, 0),
    "status-1e308": ("status for vehicle 0, t_s 1e308", status_1e308, 0),
    "observation-1e308": ("observation for vehicle 0, t_s 1e308", observation_1e308, 0),
    "local-one-model": ("estimate.local with one IMM model", local_one_model, 0),
    "global-1e200": ("estimate.global with x = 1e200", global_1e200, 0),
    "nesting-bomb": ("[ x 5000 + ] x 5000 retained on the mission topic", nesting_bomb, 0),
    "garbage-flood": ("100 KB arrays on 3 topics", garbage_flood, 0),
    "fake-fixes": ("40 fake camera fixes 10 km off in 0.2 s into vehicle 1's port", fake_fixes, 1),
}  # fmt: skip


async def attack(ctx: Context, send: Send, rate_hz: float, seconds: float) -> int:
    """Wait for the track stage, then ``send`` at ``rate_hz`` for ``seconds``; how many sent."""
    await ctx.tracking.wait()
    start = time.monotonic()
    while time.monotonic() - start < seconds:
        await send(ctx, ctx.sent)
        ctx.sent += 1
        await asyncio.sleep(max(0.0, start + ctx.sent / rate_hz - time.monotonic()))
    return ctx.sent


def track_figures(result: MissionResult, radius_m: float) -> tuple[float, float]:
    """The track stage's RMS distance error of the active vehicles and the fused estimate's
    largest position error (m)."""
    errors: list[float] = []
    estimate: list[float] = []
    for s in result.samples:
        if s.stage != "track":
            continue
        errors.extend(s.distance_errors(radius_m).values())
        if s.estimate is not None:
            estimate.append(
                math.hypot(s.estimate[0] - s.target_east_m, s.estimate[1] - s.target_north_m)
            )
    rms = float(np.sqrt(np.mean(np.square(errors)))) if errors else math.nan
    return rms, max(estimate, default=math.nan)


def refused_counts(mission: Mission, summary: dict[str, Any]) -> dict[str, int]:
    """Every count of a message not believed: the ground's, the agents', the bus clients'."""
    out: dict[str, int] = {}
    ground = summary.get("ground") or {}
    for key in ("statuses_refused", "local_estimates_refused", "message_errors"):
        out[f"ground.{key}"] = int(ground.get(key, 0))
    agents = summary.get("agents") or {}
    for key in (
        "messages_refused",
        "message_errors",
        "tick_errors",
        "commands_nonfinite",
        "fixes_rate_limited",
        "observations_dropped",
        "fused_unread",
    ):
        out[f"agents.{key}"] = sum(int(a.get(key, 0)) for a in agents.values())
    for client in mission.buses:
        drops = getattr(client, "drops", {})
        for reason, n in drops.items():
            out[f"bus.{reason}"] = out.get(f"bus.{reason}", 0) + int(n)
    return {k: v for k, v in out.items() if v}


async def fly(
    config: MissionConfig, broker: Mosquitto, out: Path, name: str | None, args: argparse.Namespace
) -> dict[str, Any]:
    sim = config.sim.model_copy(update={"speedup": args.speedup})
    update: dict[str, Any] = {"bus": broker.url, "sim": sim}
    if args.mission_key:
        key_file = out.parent / "mission.key"
        key_file.parent.mkdir(parents=True, exist_ok=True)
        key_file.write_text(MissionKey.generate().hex() + "\n", encoding="ascii")
        update["bus_login"] = config.bus_login.model_copy(
            update={"mission_key_file": str(key_file)}
        )
    plan = build_plan(config.model_copy(update=update))
    base_port = find_free_udp_base_port(plan.count)
    sent = 0
    async with (
        asyncio.timeout(WALL_TIMEOUT_S),
        SimulatorServer(sim_config(plan, base_port)) as server,
        MqttBus(broker.url, client_id="intruder") as intruder,
    ):
        tracking = asyncio.Event()

        def on_snapshot(snapshot: MissionSnapshot) -> None:
            if snapshot.stage == "track":
                tracking.set()

        mission = Mission(
            plan, out, simulator=server, broker_url=broker.url, on_snapshot=on_snapshot
        )
        ctx = Context(
            mission,
            intruder,
            broker,
            base_port,
            (config.origin.lat_deg, config.origin.lon_deg),
            tracking,
        )
        crashed = ""
        async with asyncio.TaskGroup() as tg:
            task = None
            if name is not None:
                _what, send, rate = ATTACKS[name]
                task = tg.create_task(attack(ctx, send, rate or args.rate, args.seconds))
            try:
                result = await mission.run()
            except Exception as exc:  # the figure is whether it survived
                crashed = f"{type(exc).__name__}: {exc}"
                result = None
            if task is not None and not task.done():
                task.cancel()  # the mission ended first
            sent = ctx.sent
    if name == "nesting-bomb":  # clear the retained bomb for the next run
        paho.mqtt.publish.single(
            str(topics.MISSION), b"", retain=True, hostname="127.0.0.1", port=broker.port
        )
    if result is None:
        return {"completed": False, "crashed": crashed, "sent": sent}
    summary = result.summary
    rms, est_max = track_figures(result, plan.config.radius_m)
    events = summary.get("events", {})
    return {
        "completed": not result.interrupted and events.get("mission_complete", 0) >= 1,
        "left": int(events.get("vehicle_left", 0)),
        "track_rms_m": rms,
        "estimate_max_m": est_max,
        "refused": refused_counts(mission, summary),
        "sent": sent,
    }


async def main_async(args: argparse.Namespace) -> None:
    config = load_config(args.config, MissionConfig)
    names = args.only or list(ATTACKS)
    with tempfile.TemporaryDirectory(prefix="bench-attacks-") as tmp:
        root = Path(args.out) if args.out is not None else Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        broker = Mosquitto(root)
        broker.start()
        try:
            clean = await fly(config, broker, root / "clean", None, args)
            print(
                f"clean: completed={clean['completed']} left={clean.get('left')} "
                f"track RMS {clean.get('track_rms_m', math.nan):.2f} m, fused estimate at most "
                f"{clean.get('estimate_max_m', math.nan):.2f} m off, refused "
                f"{clean.get('refused')}",
                flush=True,
            )
            for name in names:
                what = ATTACKS[name][0]
                r = await fly(config, broker, root / name, name, args)
                if not r["completed"]:
                    print(f"{name}: {what}; sent {r['sent']}: NOT COMPLETED {r.get('crashed', '')}")
                    continue
                ratio = r["track_rms_m"] / clean["track_rms_m"]
                print(
                    f"{name}: {what}; sent {r['sent']}: completed, left {r['left']}, track RMS "
                    f"{r['track_rms_m']:.2f} m ({ratio:.2f}x clean), fused estimate at most "
                    f"{r['estimate_max_m']:.2f} m off; refused {r['refused']}",
                    flush=True,
                )
        finally:
            broker.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="test-short")
    parser.add_argument("--only", nargs="*", choices=list(ATTACKS))
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=5.0)
    parser.add_argument("--out", help="keep the run folders here (default: a temporary one)")
    parser.add_argument(
        "--speedup", type=float, default=2.0, help="simulator speed-up (default 2: one process)"
    )
    parser.add_argument(
        "--mission-key",
        action="store_true",
        help="the team seals its messages with a mission key ([bus] mission_key_file) that the "
        "intruder does not hold",
    )
    asyncio.run(main_async(parser.parse_args()))


if __name__ == "__main__":
    main()
