"""Bus throughput: messages per second through the in-process bus and MQTT (a local mosquitto).

    python -m benchmarks.bench_bus [--messages N] [--broker mqtt://host:port]

One publisher sends N VehicleStatus messages on one topic; one subscriber (another client)
reads them all. The time runs from the first publish to the last message read, so it covers
encoding, the transport, validation on receipt and the subscriber's queue.

Then the in-process fan-out, as a team hears each status: N / K statuses to K other clients
of one broker (``--subscribers K``, 20), with the payload validated once per delivery and the
frozen message shared (the broker's default) against validated in every client.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import math
import tempfile
import time
from pathlib import Path

from app.adapters.bus import InProcessBroker, open_bus
from app.runtime.ports import topics
from app.runtime.ports.messages import VehicleStatus


def _status(i: int) -> VehicleStatus:
    return VehicleStatus(
        sender="agent-1", t_s=i * 0.1, vehicle=0, east_m=10.0 + i, north_m=-20.0, alt_m=100.0,
        course_rad=1.0, speed_m_s=14.0, phase_rad=0.5, stage="track", link="ok", healthy=True,
    )  # fmt: skip


async def _run(url: str | None, n: int) -> tuple[float, int]:
    broker = InProcessBroker() if url is None else None
    messages = [_status(i) for i in range(n)]
    async with (
        open_bus(url, client_id="bench-sub", queue_size=n, broker=broker) as sub_bus,
        open_bus(url, client_id="bench-pub", broker=broker) as pub,
        sub_bus.subscribe(topics.ALL_STATUS) as sub,
    ):
        topic = topics.status(0)
        start = time.perf_counter()
        async with asyncio.TaskGroup() as tg:

            async def publish_all() -> None:
                for message in messages:
                    await pub.publish(topic, message)

            tg.create_task(publish_all(), name="bench-publisher")
            received = 0
            async with asyncio.timeout(60):
                async for _ in sub:
                    received += 1
                    if received == n:
                        break
        elapsed = time.perf_counter() - start
    return elapsed, sub_bus.stats.dropped


async def _fan_out(share: bool, n: int, k: int) -> float:
    """Seconds to deliver ``n`` statuses from one publisher to ``k`` other clients of one
    in-process broker (as a team of ``k`` agents hears each status), the payload validated
    once per delivery (``share``) or once per client."""
    broker = InProcessBroker(share_decoded=share)
    messages = [_status(i) for i in range(n)]
    async with contextlib.AsyncExitStack() as stack:
        subs = []
        for i in range(k):
            bus = await stack.enter_async_context(
                open_bus(None, client_id=f"bench-sub-{i}", queue_size=n, broker=broker)
            )
            subs.append(await stack.enter_async_context(bus.subscribe(topics.ALL_STATUS)))
        pub = await stack.enter_async_context(open_bus(None, client_id="bench-pub", broker=broker))
        topic = topics.status(0)
        start = time.perf_counter()
        for message in messages:
            await pub.publish(topic, message)
        for sub in subs:
            for _ in range(n):
                await anext(sub)
        return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=20_000)
    parser.add_argument("--broker", help="an MQTT URL; default: start a mosquitto on loopback")
    parser.add_argument(
        "--subscribers", type=int, default=20, help="clients of the fan-out comparison (20)"
    )
    args = parser.parse_args()
    n = args.messages
    k = args.subscribers
    fan_n = max(1, n // k)
    # side by side, alternating, the better of three each: the machine is shared
    once, each = math.inf, math.inf
    for _ in range(3):
        once = min(once, asyncio.run(_fan_out(True, fan_n, k)))
        each = min(each, asyncio.run(_fan_out(False, fan_n, k)))

    inproc_s, _ = asyncio.run(_run(None, n))
    if args.broker:
        mqtt_s, dropped = asyncio.run(_run(args.broker, n))
    else:
        from tests.support.mosquitto import Mosquitto  # the test helper starts a throwaway broker

        with tempfile.TemporaryDirectory() as tmp:
            broker = Mosquitto(Path(tmp))
            broker.start()
            try:
                mqtt_s, dropped = asyncio.run(_run(broker.url, n))
            finally:
                broker.stop()
    print(f"messages: {n} VehicleStatus, one publisher, one subscriber, QoS 0")
    print(f"in-process: {n / inproc_s:10.0f} msg/s  ({inproc_s * 1e6 / n:6.1f} us/msg)")
    print(f"MQTT:       {n / mqtt_s:10.0f} msg/s  ({mqtt_s * 1e6 / n:6.1f} us/msg)")
    print(f"in-process / MQTT throughput ratio: {mqtt_s / inproc_s:.1f}")
    if dropped:
        print(f"(MQTT subscriber queue dropped {dropped})")
    print(
        f"in-process fan-out, {fan_n} statuses to {k} clients: validated once per delivery"
        f" {once * 1e6 / fan_n:7.1f} us/status, once per client {each * 1e6 / fan_n:7.1f}"
        f" us/status (once / per client {once / each:.2f})"
    )


if __name__ == "__main__":
    main()
