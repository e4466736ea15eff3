"""MAVSDK's offboard and MavlinkDirect plugins on the event loop: subscribed messages reach the
loop through one inbox with a wake-up per batch, and setpoints and messages go out without the
thread pool (the built-in simulator over real UDP)."""

import asyncio
import math
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import pytest

from app.adapters.vehicle.mavsdk.direct import LoopInbox
from app.core.frames import wrap_pi
from app.runtime.ports.vehicle import CourseSpeedCommand
from tests.adapters.test_vehicle_link_sim import VELOCITY, fly, hub_of, launch
from tests.support.sitl_fixtures import running_sim, sim_config


async def test_a_burst_posted_from_another_thread_runs_in_order_on_one_wakeup() -> None:
    inbox = LoopInbox(asyncio.get_running_loop())
    ran: list[tuple[int, bool]] = []
    loop_thread = threading.get_ident()

    def run(i: int) -> None:
        ran.append((i, threading.get_ident() == loop_thread))

    def burst() -> None:
        for i in range(200):
            inbox.post(run, i)

    poster = threading.Thread(target=burst)
    poster.start()
    poster.join()  # the loop is held here, as it is while the agents step
    assert ran == []
    await asyncio.sleep(0)
    assert ran == [(i, True) for i in range(200)]
    assert (inbox.posted, inbox.wakeups) == (200, 1)


async def test_a_call_posted_while_the_inbox_drains_runs_once() -> None:
    inbox = LoopInbox(asyncio.get_running_loop())
    ran: list[str] = []

    def first(_: object) -> None:
        ran.append("first")
        inbox.post(ran.append, "second")

    inbox.post(first, None)
    for _ in range(3):
        await asyncio.sleep(0)
    assert ran == ["first", "second"]
    inbox.post(ran.append, "third")
    await asyncio.sleep(0)
    assert ran == ["first", "second", "third"]


def test_a_call_posted_after_the_loop_closed_is_dropped() -> None:
    loop = asyncio.new_event_loop()
    inbox = LoopInbox(loop)
    loop.close()
    ran: list[int] = []
    inbox.post(ran.append, 1)
    assert ran == []
    assert inbox.wakeups == 0


class CountingPool(ThreadPoolExecutor):
    """The loop's thread pool, counting what is handed to it."""

    def __init__(self) -> None:
        super().__init__(max_workers=4)
        self.calls: list[str] = []

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        self.calls.append(getattr(fn, "__qualname__", repr(fn)))
        return super().submit(fn, *args, **kwargs)


@pytest.mark.slow
async def test_setpoints_and_timesync_go_out_on_the_loop_and_messages_come_in_batches() -> None:
    east = CourseSpeedCommand(math.pi / 2, 15.0)
    config = sim_config(2, speedup=5.0)
    async with (
        asyncio.timeout(60.0),
        running_sim(config) as sim,
        hub_of(sim) as hub,
        hub.link(1, VELOCITY) as v1,
        hub.link(2, VELOCITY) as v2,
    ):
        await asyncio.gather(launch(v1, east), launch(v2, east))
        pool = CountingPool()
        asyncio.get_running_loop().set_default_executor(pool)
        inbox = hub.inbox
        assert inbox is not None
        posted, wakeups = inbox.posted, inbox.wakeups
        sent = v1.counters.setpoints + v2.counters.setpoints
        await asyncio.gather(fly(v1, east, 12.0), fly(v2, east, 12.0))
        # every frame was answered with a setpoint, none of them through the pool (MAVSDK's
        # asyncio wrapper hands each one to a pool thread), and neither was a TIMESYNC request
        assert v1.counters.setpoints + v2.counters.setpoints - sent > 2 * 12 * 5
        assert pool.calls == []
        # the vehicles flew what was sent
        for vehicle in sim.truth().vehicles:
            assert abs(wrap_pi(vehicle.state.course_rad - east.course_rad)) < 0.05
        # two vehicles' telemetry: more messages than wake-ups of the loop
        assert inbox.posted - posted > 100
        assert inbox.wakeups - wakeups < inbox.posted - posted
