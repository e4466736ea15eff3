"""The link's transport delay, measured with TIMESYNC (``app.adapters.vehicle.mavsdk.timesync``),
and the frames' stamps moved back by it: the pure estimator, then over real UDP against the
built-in simulator with a delayed link."""

import asyncio
import contextlib
import dataclasses
import math
from collections.abc import AsyncIterator
from contextlib import aclosing

import pytest

from app.adapters.vehicle.mavsdk.hub import MavsdkHub
from app.adapters.vehicle.mavsdk.link import LinkConfig
from app.adapters.vehicle.mavsdk.relay import MavlinkRelay
from app.adapters.vehicle.mavsdk.timesync import LinkDelay, follow
from app.adapters.vehicle.mavsdk.urls import udp_endpoint_of_url
from app.runtime.ports.clock import MissionClock
from app.runtime.ports.vehicle import GeodeticOrigin
from sitl.server import SimulatorServer
from tests.adapters.test_vehicle_link_sim import LIMITS, hub_of
from tests.support.sitl_fixtures import running_sim, sim_config


def test_the_one_way_delay_is_half_the_least_round_trip_of_the_window():
    delay = LinkDelay(window_s=10.0)
    assert delay.one_way_s is None
    for k, trip in enumerate((0.50, 0.42, 0.61, 0.44)):
        delay.sent(k, float(k))
        assert delay.answered(k, k + trip) == pytest.approx(trip)
    assert delay.one_way_s == pytest.approx(0.21)
    # the least slides out of the window: the next least of what is left
    delay.sent(99, 11.5)
    delay.answered(99, 12.0)
    assert delay.one_way_s == pytest.approx(0.22)
    assert delay.answers == 5


def test_answers_that_are_not_ours_are_not_taken():
    delay = LinkDelay(max_pending=2, max_round_trip_s=2.0)
    delay.sent(1, 0.0)
    assert delay.answered(7, 0.3) is None  # another sender's request
    assert delay.answered(1, 0.3) == pytest.approx(0.3)
    assert delay.answered(1, 0.4) is None  # a duplicate
    delay.sent(2, 1.0)
    delay.sent(3, 1.1)
    delay.sent(4, 1.2)  # 2 is given up on: only two outstanding
    assert delay.answered(2, 1.3) is None
    assert delay.answered(3, 4.0) is None  # answered after 2.9 s: not believed
    assert delay.answered(4, math.nan) is None
    assert delay.answers == 1
    with pytest.raises(ValueError, match="window_s"):
        LinkDelay(window_s=0.0)


def test_the_correction_moves_by_at_most_a_step_per_frame():
    assert follow(0.0, 0.3, 0.005) == pytest.approx(0.005)
    assert follow(0.3, 0.0, 0.005) == pytest.approx(0.295)
    assert follow(0.1, 0.102, 0.005) == pytest.approx(0.102)


@pytest.mark.slow
@contextlib.asynccontextmanager
async def relayed_hub(sim: SimulatorServer) -> AsyncIterator[MavsdkHub]:
    """A hub on the simulator's vehicles through one relay each, as ``standoff fly`` connects
    (the relay passes PX4's TIMESYNC answers on as broadcasts), on the simulator's clock."""
    clock = MissionClock(0.0, 1.0, lambda: sim.time_s)
    c = sim.config
    origin = GeodeticOrigin(c.origin_lat_deg, c.origin_lon_deg, c.origin_alt_m)
    async with contextlib.AsyncExitStack() as stack:
        urls = []
        for i, vehicle in enumerate(sim.endpoints):
            endpoint = udp_endpoint_of_url(vehicle.mavsdk_url)
            assert endpoint is not None
            relay = MavlinkRelay(endpoint, system_ids=frozenset({i + 1}))
            urls.append((await stack.enter_async_context(relay)).app_url)
        yield await stack.enter_async_context(MavsdkHub(urls, origin, mission_clock=clock))


async def test_a_delayed_link_is_measured_and_its_frames_stamped_when_they_were_sampled():
    # vehicle 1 behind a 0.3 s radio (each way), vehicle 2 on loopback
    base = sim_config(2, speedup=5.0)
    vehicles = (dataclasses.replace(base.vehicles[0], link_delay_s=0.3), base.vehicles[1])
    config = dataclasses.replace(base, vehicles=vehicles)
    link_config = LinkConfig(LIMITS, autopilot="velocity", timesync_period_s=0.2)
    async with (
        asyncio.timeout(60.0),
        running_sim(config) as sim,
        relayed_hub(sim) as hub,
        hub.link(1, link_config) as slow,
        hub.link(2, link_config) as fast,
    ):
        await asyncio.sleep(25.0 / sim.speedup)
        ages = {}
        for name, link in (("slow", slow), ("fast", fast)):
            seen = []
            async with aclosing(link.telemetry()) as frames:
                async for frame in frames:
                    # the frame's age on the mission clock (the simulator's time) when it
                    # is handed over: its sample time, moved back by the link's delay
                    seen.append(sim.time_s - frame.t_s)
                    if len(seen) == 20:
                        break
            ages[name] = sorted(seen)[len(seen) // 2]
        assert slow.counters.timesync_answers >= 10
        assert slow.counters.round_trip_min_s == pytest.approx(0.6, abs=0.05)
        assert slow.counters.link_delay_s == pytest.approx(0.3, abs=0.03)
        assert fast.counters.link_delay_s < 0.03
    # stamped at arrival, both would be ~0 old; moved back, the slow link's are 0.3 s old
    assert ages["slow"] == pytest.approx(0.3, abs=0.06)
    assert ages["fast"] < 0.06


async def test_px4s_timesync_answers_reach_the_link_through_the_relay() -> None:
    """The built-in simulator's PX4 answers TIMESYNC as PX4 v1.16 does, with uninitialised
    target bytes; MAVSDK drops such an answer as another system's, so on a direct connection
    the link measures nothing, and through the mission's relay (which passes the answers on as
    broadcasts) it measures the loopback's delay."""
    config = sim_config(1, speedup=5.0)
    link_config = LinkConfig(LIMITS, px4_offboard_loss_action=None, timesync_period_s=0.2)
    async with asyncio.timeout(60.0), running_sim(config) as sim:
        async with hub_of(sim) as hub, hub.link(1, link_config) as direct:
            await direct.wait_ready(10.0)
            assert direct.autopilot_name == "px4-fixed-wing"
            await asyncio.sleep(3.0)
            assert direct.counters.timesync_answers == 0
        async with relayed_hub(sim) as hub, hub.link(1, link_config) as relayed:
            await relayed.wait_ready(10.0)
            await asyncio.sleep(3.0)
            assert relayed.counters.timesync_answers >= 5
            delay = relayed.counters.link_delay_s
            assert delay is not None
            assert 0.0 <= delay < 0.03
