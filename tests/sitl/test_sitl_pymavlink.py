"""A raw pymavlink client (no MAVSDK) flies the simulator through the same messages; failsafe."""

import asyncio
import itertools
import math
import time

import pytest
from pymavlink.dialects.v20 import common as mavlink

from app.core.frames import wrap_pi
from sitl.guidance import LoiterCommand
from sitl.px4 import HOLD, OFFBOARD
from tests.support.sitl_fixtures import RawClient, running_sim, sim_config, stream_setpoints

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
DENIED = mavlink.MAV_RESULT_DENIED


def _offboard_mode_params() -> tuple[float, float, float]:
    return float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), 6.0, 0.0


async def _arm_and_start_offboard(client: RawClient, sysid: int) -> None:
    assert (
        await client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target_system=sysid)
        == ACCEPTED
    )
    # PX4 refuses offboard before setpoints flow; so does the simulator
    assert (
        await client.command(
            mavlink.MAV_CMD_DO_SET_MODE, *_offboard_mode_params(), target_system=sysid
        )
        == DENIED
    )


@pytest.mark.slow
async def test_raw_pymavlink_client_connects_arms_and_flies_courses_within_limits():
    config = sim_config(3, speedup=10.0, takeoff="launch")
    courses_deg = (90.0, -90.0, 180.0)
    async with running_sim(config) as sim, asyncio.TaskGroup() as group:
        clients = [RawClient(endpoint.gcs_port) for endpoint in sim.endpoints]
        stop = asyncio.Event()
        try:
            for client in clients:
                await client.__aenter__()
            for sysid, client in enumerate(clients, start=1):
                beat = await client.heartbeat(timeout_s=5.0)
                assert beat.get_srcSystem() == sysid
                assert beat.type == mavlink.MAV_TYPE_FIXED_WING
                assert beat.autopilot == mavlink.MAV_AUTOPILOT_PX4
                start = len(client.inbox.messages)
                result = await client.command(
                    mavlink.MAV_CMD_REQUEST_MESSAGE, 148.0, target_system=sysid
                )
                assert result == ACCEPTED
                await client.wait_for(lambda m: m.get_type() == "AUTOPILOT_VERSION", start=start)
                await _arm_and_start_offboard(client, sysid)
                course = math.radians(courses_deg[sysid - 1])
                group.create_task(
                    stream_setpoints(
                        client, sysid, 20.0 * math.cos(course), 20.0 * math.sin(course), 20.0, stop
                    ),
                    name=f"setpoints-{sysid}",
                )
            await asyncio.sleep(0.2)
            for sysid, client in enumerate(clients, start=1):
                assert (
                    await client.command(
                        mavlink.MAV_CMD_DO_SET_MODE, *_offboard_mode_params(), target_system=sysid
                    )
                    == ACCEPTED
                )
                await client.wait_for(
                    lambda m: (
                        m.get_type() == "HEARTBEAT"
                        and m.custom_mode == OFFBOARD.custom_mode
                        and m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
                    )
                )
            marks = [len(c.inbox.messages) for c in clients]
            wall_start = time.monotonic()
            await sim.wait_until(sim.time_s + 25.0)
            wall_s = time.monotonic() - wall_start
        finally:
            stop.set()
            for client in clients:
                await client.__aexit__()

    # judge by the telemetry the client received, in simulated time (ATTITUDE.time_boot_ms)
    for sysid, (client, mark) in enumerate(zip(clients, marks, strict=True), start=1):
        limits = config.vehicles[sysid - 1].limits
        attitude = [m for m in client.inbox.messages[mark:] if m.get_type() == "ATTITUDE"]
        hud = [m for m in client.inbox.messages[mark:] if m.get_type() == "VFR_HUD"]
        assert len(attitude) > 200  # 10 Hz over 25 simulated seconds
        # time fields are simulated time: 25 s of it went by in about 2.5 s of wall time
        span_s = (attitude[-1].time_boot_ms - attitude[0].time_boot_ms) / 1000.0
        assert 24.0 <= span_s <= 26.0
        assert wall_s < 0.5 * span_s
        for before, after in itertools.pairwise(attitude):
            dt = (after.time_boot_ms - before.time_boot_ms) / 1000.0
            assert dt > 0.0
            rate = abs(wrap_pi(after.yaw - before.yaw)) / dt
            assert rate <= 1.01 * limits.max_course_rate_rad_s
        assert max(abs(m.yawspeed) for m in attitude) > 0.99 * limits.max_course_rate_rad_s
        for m in hud:
            assert limits.min_speed_m_s - 1e-3 <= m.airspeed <= limits.max_speed_m_s + 1e-3
        assert abs(wrap_pi(attitude[-1].yaw - math.radians(courses_deg[sysid - 1]))) < 0.01
        assert abs(hud[-1].airspeed - 20.0) < 0.1


@pytest.mark.slow
async def test_failsafe_holds_within_1_5_s_and_loiters_on_the_radius():
    config = sim_config(1, speedup=4.0, takeoff="launch")
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:
        await client.heartbeat()
        stop = asyncio.Event()
        async with asyncio.TaskGroup() as group:
            assert (
                await client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target_system=1)
                == ACCEPTED
            )
            group.create_task(stream_setpoints(client, 1, 0.0, 22.0, 20.0, stop), name="setpoints")
            await asyncio.sleep(0.1)
            assert (
                await client.command(
                    mavlink.MAV_CMD_DO_SET_MODE, *_offboard_mode_params(), target_system=1
                )
                == ACCEPTED
            )
            await sim.wait_until(sim.time_s + 3.0)
            mark = len(client.inbox.messages)
            stop.set()
        t_stop = sim.time_s
        switched_at = None
        async for truth in sim.truth_samples(config.physics_dt_s):
            if truth.vehicles[0].mode == HOLD.name:
                switched_at = truth.t_s
                break
            assert truth.t_s - t_stop < 3.0, "no failsafe"
        assert switched_at is not None
        assert 0.75 <= switched_at - t_stop <= 1.5
        await client.wait_for(
            lambda m: m.get_type() == "HEARTBEAT" and m.custom_mode == HOLD.custom_mode, start=mark
        )
        text = await client.wait_for(lambda m: m.get_type() == "STATUSTEXT", start=mark)
        assert "Failsafe" in text.text
        assert text.severity == mavlink.MAV_SEVERITY_WARNING

        # one full circle and more, fast
        sim.set_speedup(50.0)
        loiter = sim.truth().vehicles[0].command
        assert isinstance(loiter, LoiterCommand)
        worst = 0.0
        t_end = sim.time_s + 70.0
        async for truth in sim.truth_samples(0.5):
            state = truth.vehicles[0].state
            d = math.hypot(
                state.east_m - loiter.center_east_m, state.north_m - loiter.center_north_m
            )
            worst = max(worst, abs(d - loiter.radius_m))
            assert truth.vehicles[0].mode == HOLD.name
            if truth.t_s >= t_end:
                break
        assert worst <= 10.0
