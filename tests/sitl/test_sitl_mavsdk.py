"""A real MAVSDK 4.x client flies three simulated vehicles over real UDP."""

import asyncio
import json
import math
import time

import pytest
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, VelocityNedYaw
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync

from app.core.frames import wrap_pi
from tests.support.sitl_fixtures import px4_of, running_sim, sim_config

COMMANDED_COURSES_DEG = (90.0, -90.0, 180.0)  # every vehicle starts flying north


async def _systems_by_id(mavsdk: Mavsdk, count: int) -> dict[int, object]:
    found: dict[int, object] = {}
    while len(found) < count:
        for system in await mavsdk.get_systems():
            if await system.has_autopilot():
                found[await system.get_system_id()] = system
        if len(found) < count:
            await asyncio.sleep(0.05)
    return found


@pytest.mark.slow
async def test_mavsdk_connects_arms_and_flies_offboard_courses_within_limits():
    config = sim_config(3, speedup=10.0, takeoff="launch")
    async with running_sim(config) as sim:
        gcs = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        async with Mavsdk(gcs) as mavsdk:
            started = time.monotonic()
            for endpoint in sim.endpoints:
                await mavsdk.add_any_connection(endpoint.mavsdk_url)
            async with asyncio.timeout(5.0):
                systems = await _systems_by_id(mavsdk, 3)
            assert sorted(systems) == [1, 2, 3]
            assert time.monotonic() - started < 5.0
            # one plugin instance per system: MAVSDK 4.1 resets the cached values of an
            # instance when another instance of the same plugin on that system goes away
            # (and an OffboardAsync that is garbage-collected stops resending its setpoint)
            telemetry = {sysid: TelemetryAsync(system) for sysid, system in systems.items()}
            offboard = {sysid: OffboardAsync(system) for sysid, system in systems.items()}

            for sysid, course_deg in zip((1, 2, 3), COMMANDED_COURSES_DEG, strict=True):
                system = systems[sysid]
                await ActionAsync(system).arm()
                speed = 20.0
                course = math.radians(course_deg)
                await offboard[sysid].set_velocity_ned(
                    VelocityNedYaw(
                        speed * math.cos(course), speed * math.sin(course), 0.0, course_deg
                    )
                )
                await offboard[sysid].start()

            for sysid in (1, 2, 3):
                tel = telemetry[sysid]
                async with asyncio.timeout(3.0):
                    async for mode in tel.subscribe_flight_mode():
                        if FlightMode(mode) is FlightMode.OFFBOARD:
                            break
                    async for armed in tel.subscribe_armed():
                        if armed:
                            break
                    async for in_air in tel.subscribe_in_air():
                        if in_air:
                            break

            # fly 25 simulated seconds: a 180 degree turn at 0.2 rad/s takes about 16 s
            previous = sim.truth()
            t_end = previous.t_s + 25.0
            while previous.t_s < t_end:
                now = await sim.wait_until(previous.t_s + 0.1)
                dt = now.t_s - previous.t_s
                for before, after in zip(previous.vehicles, now.vehicles, strict=True):
                    limits = config.vehicles[after.index].limits
                    rate = abs(wrap_pi(after.state.course_rad - before.state.course_rad)) / dt
                    assert rate <= 1.01 * limits.max_course_rate_rad_s
                    assert limits.min_speed_m_s <= after.state.speed_m_s <= limits.max_speed_m_s
                    assert after.mode == "offboard"
                previous = now

            for sysid, course_deg in zip((1, 2, 3), COMMANDED_COURSES_DEG, strict=True):
                truth = previous.vehicles[sysid - 1]
                assert abs(wrap_pi(truth.state.course_rad - math.radians(course_deg))) < 0.01
                assert abs(truth.state.speed_m_s - 20.0) < 0.1
                heading = await telemetry[sysid].heading()
                assert abs(wrap_pi(math.radians(heading.heading_deg - course_deg))) < 0.05
                velocity = await telemetry[sysid].velocity_ned()
                assert math.hypot(velocity.north_m_s, velocity.east_m_s) == pytest.approx(
                    20.0, abs=0.2
                )
                assert await telemetry[sysid].health_all_ok()
                position = await telemetry[sysid].position()
                assert position.relative_altitude_m == pytest.approx(100.0, abs=0.01)
                truth_now = sim.truth().vehicles[sysid - 1].state
                east, north, _ = sim.geodesy.to_local(
                    position.latitude_deg, position.longitude_deg, position.absolute_altitude_m
                )
                # the latest telemetry is at most a couple of 0.1 s periods (2 m each) old
                assert math.hypot(east - truth_now.east_m, north - truth_now.north_m) < 10.0

            # the camera component's CAMERA_TRACKING_GEO_STATUS reaches MAVSDK
            direct = MavlinkDirectAsync(systems[1])
            async with asyncio.timeout(3.0):
                async for message in direct.subscribe_message("CAMERA_TRACKING_GEO_STATUS"):
                    assert message.message_name == "CAMERA_TRACKING_GEO_STATUS"
                    assert message.component_id == 100
                    fields = json.loads(message.fields_json)
                    # the stationary target stands at the origin; 10 m^2 noise: within 20 m
                    east, north, _ = sim.geodesy.to_local(
                        fields["lat"] / 1e7, fields["lon"] / 1e7, config.origin_alt_m
                    )
                    assert math.hypot(east, north) < 20.0
                    break


async def test_mavsdk_reads_and_sets_the_px4_failsafe_parameters():
    config = sim_config(1, speedup=10.0, takeoff="launch")
    async with running_sim(config) as sim:
        gcs = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        async with Mavsdk(gcs) as mavsdk:
            await mavsdk.add_any_connection(sim.endpoints[0].mavsdk_url)
            system = await mavsdk.first_autopilot(timeout_s=5.0)
            assert system is not None
            params = ParamAsync(system)
            assert await params.get_param_int("COM_OBL_RC_ACT") == 5  # hold
            assert await params.get_param_float("COM_OF_LOSS_T") == pytest.approx(1.0)
            await params.set_param_int("COM_OBL_RC_ACT", 3)  # return
            await params.set_param_float("COM_OF_LOSS_T", 2.5)
            assert await params.get_param_int("COM_OBL_RC_ACT") == 3
            vehicle = sim.vehicles[0]
            assert (px4_of(vehicle).failsafe_action, px4_of(vehicle).offboard_timeout_s) == (
                "return",
                2.5,
            )
            everything = await params.get_all_params()
            names = {p.name for p in everything.int_params} | {
                p.name for p in everything.float_params
            }
            assert names == {
                "COM_OBL_RC_ACT",
                "COM_OF_LOSS_T",
                "FW_AIRSPD_TRIM",
                "NAV_LOITER_RAD",
                "FW_AIRSPD_MIN",
                "FW_AIRSPD_MAX",
            }
