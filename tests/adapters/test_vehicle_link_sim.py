"""The MAVSDK vehicle link flies the built-in simulator over real UDP: connect, arm, offboard,
commanded courses, telemetry, observations, link loss, a vehicle leaving offboard, refusals."""

import asyncio
import math
import socket
from collections.abc import AsyncIterator
from contextlib import aclosing

import pytest
from pymavlink.dialects.v20 import common as mavlink

from app.adapters.vehicle.autopilots.limits import SetpointLimits
from app.adapters.vehicle.autopilots.px4 import px4_mission_rates
from app.adapters.vehicle.mavsdk.hub import MavsdkHub
from app.adapters.vehicle.mavsdk.link import LinkConfig, MavsdkVehicleLink
from app.core.frames import wrap_pi
from app.core.plant import VehicleEnvelope
from app.errors import LinkError
from app.runtime.ports.clock import MissionClock
from app.runtime.ports.vehicle import (
    CourseSpeedCommand,
    GeodeticOrigin,
    LeftOffboard,
    LinkEvent,
    LinkLost,
    LinkRestored,
    OffboardLostError,
    SetpointLimited,
    VehicleLink,
    VehicleTelemetry,
)
from app.runtime.vehicle import BringUp, wait_for_handover
from sitl.server import SimulatorServer
from tests.support.sitl_fixtures import px4_of, running_sim, sim_config

SPEEDUP = 5.0
LIMITS = SetpointLimits(VehicleEnvelope(18.0, 12.0, 24.0, 2.0, 0.2))
VELOCITY = LinkConfig(LIMITS, autopilot="velocity")


def origin_of(sim: SimulatorServer) -> GeodeticOrigin:
    c = sim.config
    return GeodeticOrigin(c.origin_lat_deg, c.origin_lon_deg, c.origin_alt_m)


def urls_of(sim: SimulatorServer) -> list[str]:
    return [endpoint.mavsdk_url for endpoint in sim.endpoints]


def hub_of(sim: SimulatorServer) -> MavsdkHub:
    """A hub on the simulator's vehicles whose mission clock is the simulator's own time (as a
    mission's with an in-process simulator is): every vehicle's boot clock (they booted 3.7 s
    apart) mapped onto it."""
    clock = MissionClock(0.0, 1.0, lambda: sim.time_s)
    return MavsdkHub(urls_of(sim), origin_of(sim), mission_clock=clock)


async def fly(link: MavsdkVehicleLink, command: CourseSpeedCommand, duration_s: float) -> None:
    """Send ``command`` on every telemetry frame for ``duration_s`` of vehicle time."""
    latest = link.latest
    assert latest is not None
    until = latest.t_s + duration_s
    async with aclosing(link.telemetry()) as frames:
        async for frame in frames:
            await link.send(command)
            if frame.t_s >= until:
                return


async def next_event(events: AsyncIterator[LinkEvent], kind: type, timeout_s: float) -> LinkEvent:
    async with asyncio.timeout(timeout_s):
        async for event in events:
            if isinstance(event, kind):
                return event
    raise AssertionError(f"event stream ended before a {kind.__name__}")


class NoEvents:
    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        return None


#: the hand-over a mission waits for (the simulator takes off from a runway and climbs)
HANDOVER = BringUp(
    connect_timeout_s=10.0,
    take_off_timeout_s=30.0,
    altitude_m=None,
    cruise_speed_m_s=18.0,
    origin_lat_deg=0.0,
    origin_lon_deg=0.0,
    handover_min_height_m=30.0,
    handover_min_airspeed_m_s=12.0,
    handover_timeout_s=40.0,
)


async def launch(link: MavsdkVehicleLink, first: CourseSpeedCommand) -> VehicleTelemetry:
    ground = await link.wait_ready(10.0)
    await link.arm()
    await link.take_off(10.0)
    await wait_for_handover(link, HANDOVER, NoEvents())
    await link.start_offboard(first)
    return ground


@pytest.mark.slow
async def test_three_vehicles_connect_arm_and_follow_commanded_courses():
    commands = {
        1: CourseSpeedCommand(math.pi / 2, 15.0),  # east, slower than the 18 m/s start
        2: CourseSpeedCommand(-math.pi / 2, 20.0),  # west, faster
        3: CourseSpeedCommand(math.pi / 4, 13.0),  # north-east
    }
    config = sim_config(3, speedup=SPEEDUP)
    async with asyncio.timeout(60.0), running_sim(config) as sim:
        async with (
            hub_of(sim) as hub,
            hub.link(1, VELOCITY) as v1,
            hub.link(2, VELOCITY) as v2,
            hub.link(3, VELOCITY) as v3,
        ):
            links = {1: v1, 2: v2, 3: v3}
            assert await hub.system_ids() == [1, 2, 3]
            for sysid, link in links.items():
                assert isinstance(link, VehicleLink)
                assert link.vehicle_id == sysid
                assert link.autopilot_name == "velocity"
            grounds = {}
            async with asyncio.TaskGroup() as group:
                tasks = {
                    i: group.create_task(launch(link, commands[i]), name=f"launch-{i}")
                    for i, link in links.items()
                }
            grounds = {i: task.result() for i, task in tasks.items()}
            # on the ground, before arming: exactly at the launch points, in the mission frame
            for i, ground in grounds.items():
                start = config.vehicles[i - 1].start
                assert ground.vehicle_id == i
                assert ground.east_m == pytest.approx(start.east_m, abs=0.05)
                assert ground.north_m == pytest.approx(start.north_m, abs=0.05)
                assert (ground.armed, ground.in_air, ground.ground_speed_m_s) == (False, False, 0.0)
            async with asyncio.TaskGroup() as group:
                for i, link in links.items():
                    group.create_task(fly(link, commands[i], 25.0), name=f"fly-{i}")
            truth = sim.truth()
            for i, link in links.items():
                frame = link.latest
                assert frame is not None
                assert (frame.flight_mode, frame.armed, frame.in_air, frame.link_ok) == (
                    "OFFBOARD",
                    True,
                    True,
                    True,
                )
                assert abs(wrap_pi(frame.course_rad - commands[i].course_rad)) < 0.01
                assert frame.ground_speed_m_s == pytest.approx(commands[i].speed_m_s, abs=0.1)
                assert frame.relative_altitude_m == pytest.approx(100.0, abs=0.01)
                # telemetry is mission time (each vehicle's boot clock mapped onto the
                # simulator's time) and matches the truth
                assert 0.0 <= truth.t_s - frame.t_s < 1.0
                state = truth.vehicles[i - 1].state
                lag_s = truth.t_s - frame.t_s
                assert frame.east_m + lag_s * state.v_east_m_s == pytest.approx(
                    state.east_m, abs=0.5
                )
                assert frame.north_m + lag_s * state.v_north_m_s == pytest.approx(
                    state.north_m, abs=0.5
                )
                # the commanded 45-90 degree turns went out rate-limited, and were counted
                assert link.counters.limited_by.get("course_rate", 0) > 0
                assert link.counters.setpoints > 50
                assert link.counters.malformed == 0
        # leaving the links put every vehicle in hold
        assert [v.mode for v in sim.truth().vehicles] == ["hold", "hold", "hold"]


@pytest.mark.slow
async def test_every_setpoint_that_reached_the_vehicle_was_within_the_limits():
    config = sim_config(1, speedup=SPEEDUP)
    about_turn_too_fast = CourseSpeedCommand(math.pi, 40.0)
    async with (
        asyncio.timeout(40.0),
        running_sim(config) as sim,
        hub_of(sim) as hub,
        hub.link(1, VELOCITY) as link,
        aclosing(link.events()) as events,
    ):
        await launch(link, about_turn_too_fast)
        flown = asyncio.Event()
        received: list[tuple[float, float, float]] = []  # what the vehicle flies, in its time

        async def watch_vehicle() -> None:
            samples = sim.truth_samples(0.1)
            try:
                async for truth in samples:
                    command = truth.vehicles[0].command
                    assert type(command).__name__ == "VelocityCommand"
                    received.append((truth.t_s, command.course_rad, command.speed_m_s))  # type: ignore[union-attr]
                    if flown.is_set():
                        return
            finally:
                await samples.aclose()  # type: ignore[attr-defined]

        async def fly_then_stop() -> None:
            await fly(link, about_turn_too_fast, 10.0)
            flown.set()

        async with asyncio.TaskGroup() as group:
            group.create_task(watch_vehicle(), name="watch")
            group.create_task(fly_then_stop(), name="fly")
        limited = await next_event(events, SetpointLimited, 1.0)
        assert isinstance(limited, SetpointLimited)
        assert "above 24.0 m/s" in limited.reason
    assert all(speed == pytest.approx(24.0) for _, _, speed in received)
    assert len(received) > 50
    # the commanded course never turned faster than 0.2 rad/s of vehicle time (over 1 s
    # windows, with 0.5 s of slack for setpoints that arrive late or bunched)
    for k, (t0, c0, _) in enumerate(received):
        for t1, c1, _ in received[k + 1 :]:
            if t1 - t0 >= 1.0:
                assert abs(wrap_pi(c1 - c0)) <= 0.2 * (t1 - t0 + 0.5)
                break
    turned = abs(wrap_pi(received[-1][1] - received[0][1]))
    assert turned > 1.5  # and it did turn, at about the limit


@pytest.mark.slow
async def test_link_loss_then_failsafe_is_reported_and_offboard_can_be_retaken():
    config = sim_config(1, speedup=SPEEDUP)
    link_config = LinkConfig(LIMITS, autopilot="velocity", link_timeout_s=1.0)
    async with (
        asyncio.timeout(60.0),
        running_sim(config) as sim,
        hub_of(sim) as hub,
        hub.link(1, link_config) as link,
        aclosing(link.events()) as events,
        aclosing(link.telemetry()) as frames,
    ):
        east = CourseSpeedCommand(math.pi / 2, 16.0)
        await launch(link, east)
        await fly(link, east, 3.0)
        last_before = link.latest
        assert last_before is not None
        sim.set_link(0, False)  # radio cut: nothing in, nothing out
        lost = await next_event(events, LinkLost, 5.0)
        assert isinstance(lost, LinkLost)
        assert lost.vehicle_id == 1
        assert lost.silent_s > 1.0
        assert link.link_ok is False
        # the telemetry stream says so too, with the last frame marked
        async with asyncio.timeout(2.0):
            async for frame in frames:
                if not frame.link_ok:
                    break
        assert frame.t_s >= last_before.t_s
        # the vehicle's offboard-loss failsafe (1 s of vehicle time) puts it in hold
        await sim.wait_until(sim.time_s + 2.0)
        assert sim.truth().vehicles[0].mode == "hold"
        sim.set_link(0, True)
        # the mode change is known before the link is declared back (restored only on the first
        # HEARTBEAT after the loss): a returning vehicle is never taken for the mission's first
        left = await next_event(events, LeftOffboard, 5.0)
        assert isinstance(left, LeftOffboard)
        assert left.flight_mode == "HOLD"
        assert link.counters.left_offboard == 1
        restored = await next_event(events, LinkRestored, 5.0)
        assert isinstance(restored, LinkRestored)
        assert restored.t_s > lost.t_s
        with pytest.raises(OffboardLostError, match="left OFFBOARD"):
            await link.send(east)
        # the mission takes it back explicitly
        await link.start_offboard(east)
        await fly(link, east, 3.0)
        assert link.flight_mode == "OFFBOARD"
        assert sim.truth().vehicles[0].mode == "offboard"


async def test_a_mode_change_by_someone_else_is_reported_as_leaving_offboard():
    config = sim_config(1, speedup=SPEEDUP)
    async with (
        asyncio.timeout(40.0),
        running_sim(config) as sim,
        hub_of(sim) as hub,
        hub.link(1, VELOCITY) as link,
        aclosing(link.events()) as events,
    ):
        north = CourseSpeedCommand(0.0, 18.0)
        await launch(link, north)
        await fly(link, north, 2.0)
        # a second ground station (a pilot's) switches the vehicle to PX4 hold
        endpoint = sim.endpoints[0]
        other = mavlink.MAVLink(None, srcSystem=254, srcComponent=190)
        message = mavlink.MAVLink_command_long_message(1, 1, 176, 0, 1, 4, 3, 0, 0, 0, 0)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.sendto(message.pack(other), (endpoint.local_host, endpoint.local_port))
        left = await next_event(events, LeftOffboard, 5.0)
        assert isinstance(left, LeftOffboard)
        assert (left.vehicle_id, left.flight_mode) == (1, "HOLD")
        assert link.link_ok
        with pytest.raises(OffboardLostError):
            await link.send(north)


async def test_a_refused_mode_change_is_a_link_error_with_the_result():
    # launched on arming: the PX4-like simulator would refuse ArduPlane's TAKEOFF mode too
    config = sim_config(1, speedup=SPEEDUP, takeoff="launch")
    # the simulator is PX4-like: it refuses ArduPlane's GUIDED (custom mode 15); it has no
    # ArduPlane failsafe or airspeed parameters either, which the adapter would refuse it for
    arduplane = LinkConfig(
        LIMITS, autopilot="arduplane", arduplane_gcs_failsafe=False, arduplane_airspeed_check=False
    )
    async with asyncio.timeout(40.0), running_sim(config) as sim:
        async with hub_of(sim) as hub, hub.link(1, arduplane) as link:
            await link.wait_ready(10.0)
            await link.arm()
            await link.take_off(10.0)
            with pytest.raises(LinkError, match="mode change to GUIDED refused: MAV_RESULT_DENIED"):
                await link.start_offboard(CourseSpeedCommand(0.0, 18.0))
            with pytest.raises(LinkError, match="start_offboard before send"):
                await link.send(CourseSpeedCommand(0.0, 18.0))
        assert sim.truth().vehicles[0].mode == "hold"


async def test_a_refused_take_off_is_a_link_error_with_the_result():
    config = sim_config(1, speedup=SPEEDUP)
    async with asyncio.timeout(30.0), running_sim(config) as sim:
        async with hub_of(sim) as hub, hub.link(1, VELOCITY) as link:
            await link.wait_ready(10.0)
            # not armed: the vehicle refuses to take off
            with pytest.raises(LinkError, match="vehicle 1: take-off refused: COMMAND_DENIED"):
                await link.take_off(5.0)
        assert sim.truth().vehicles[0].in_air is False


async def test_camera_observations_arrive_in_the_mission_frame():
    config = sim_config(1, speedup=SPEEDUP)
    async with asyncio.timeout(40.0), running_sim(config) as sim:
        async with (
            # no mission clock: stamped with the vehicle's boot time, which for the first
            # vehicle is the simulator's, the observations match what it sent exactly
            MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
            hub.link(1, VELOCITY) as link,
            aclosing(link.observations()) as observations,
        ):
            await link.wait_ready(10.0)
            await link.arm()
            await link.take_off(20.0)  # the camera reports only in the air
            received = []
            async with asyncio.timeout(20.0):
                async for observation in observations:
                    received.append(observation)
                    if len(received) == 40:
                        break
        sent = {round(obs.t_s, 3): obs for sysid, obs in sim.observations if sysid == 1}
        sigma = math.sqrt(config.camera.sigma2_m2)
        for observation in received:
            assert observation.vehicle_id == 1
            assert observation.sigma_m == pytest.approx(sigma, rel=1e-6)
        times = [o.t_s for o in received]
        assert times == sorted(times)
        # each observation is a geolocated point the simulator sent, back in the local frame
        # within 5 cm, of about its time: a fix carries no time of its own and takes the newest
        # telemetry frame's, which on a loaded machine may be the frame before or after its
        # instant (matching by the nearest time alone then took a neighbour's noise)
        matched = 0
        for observation in received:
            near = [o for o in sent.values() if abs(o.t_s - observation.t_s) < 0.35]
            if any(
                abs(o.east_m - observation.east_m) < 0.05
                and abs(o.north_m - observation.north_m) < 0.05
                for o in near
            ):
                matched += 1
        assert matched >= 30
        # and they scatter about the stationary target at the origin
        n = len(received)
        assert abs(sum(o.east_m for o in received) / n) < 4.0 * sigma / math.sqrt(n)
        assert abs(sum(o.north_m for o in received) / n) < 4.0 * sigma / math.sqrt(n)


@pytest.mark.slow
async def test_px4_fixed_wing_adapter_is_chosen_and_flies_the_line_setpoints():
    config = sim_config(1, speedup=SPEEDUP)
    # the simulator reports PX4 + fixed wing, so the PX4 form is chosen; it has no parameters
    px4 = LinkConfig(LIMITS, px4_offboard_loss_action=None)
    async with (
        asyncio.timeout(40.0),
        running_sim(config) as sim,
        hub_of(sim) as hub,
        hub.link(1, px4) as link,
    ):
        assert link.autopilot_name == "px4-fixed-wing"
        east = CourseSpeedCommand(math.pi / 2, 16.0)
        await launch(link, east)
        await fly(link, east, 20.0)
        frame = link.latest
        assert frame is not None
        assert frame.flight_mode == "OFFBOARD"
        assert abs(wrap_pi(frame.course_rad - math.pi / 2)) < 0.02
        # PX4 v1.16 flies OFFBOARD at its trim airspeed (the vehicle's cruise speed here),
        # not the 16 m/s asked for, and the link says so
        assert not link.honours_speed
        assert frame.ground_speed_m_s == pytest.approx(config.vehicles[0].cruise_speed_m_s, abs=0.2)
        command = px4_of(sim.vehicles[0]).offboard_setpoint
        assert type(command).__name__ == "LineCommand"


async def test_px4_adapter_sets_the_offboard_loss_action_to_hold_before_take_off():
    # the simulator answers PX4's parameter protocol; set up to return on offboard loss, the
    # PX4 adapter reads COM_OBL_RC_ACT and sets it to hold (5) before anything flies
    config = sim_config(1, speedup=SPEEDUP, failsafe_action="return")
    async with asyncio.timeout(40.0), running_sim(config) as sim:
        action_before: str = px4_of(sim.vehicles[0]).failsafe_action
        assert action_before == "return"
        async with (
            hub_of(sim) as hub,
            hub.link(1, LinkConfig(LIMITS)) as link,
        ):
            await link.wait_ready(10.0)
            assert link.autopilot_name == "px4-fixed-wing"
            assert px4_of(sim.vehicles[0]).failsafe_action == "hold"
            assert sim.truth().vehicles[0].armed is False


async def test_px4_is_asked_for_the_missions_rates_and_given_its_own_back_at_the_end() -> None:
    """PX4's onboard link streams position at 50 Hz; with ``px4_telemetry_rates_hz`` the link
    asks for what it reads at 10 Hz and the fast streams it never reads at 1 Hz, over MAVLink,
    and puts every one back at the autopilot's own rate when it closes."""
    config = sim_config(1, speedup=SPEEDUP, telemetry_rate_hz=50.0)
    rates = LinkConfig(
        LIMITS, px4_offboard_loss_action=None, px4_telemetry_rates_hz=px4_mission_rates(10.0)
    )
    gpi, imu = mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mavlink.MAVLINK_MSG_ID_HIGHRES_IMU
    async with asyncio.timeout(40.0), running_sim(config) as sim:
        vehicle = sim.vehicles[0]
        assert vehicle.stream_interval_s(gpi) == pytest.approx(0.02)
        async with hub_of(sim) as hub, hub.link(1, rates) as link:
            await link.wait_ready(10.0)
            assert link.autopilot_name == "px4-fixed-wing"
            assert vehicle.stream_interval_s(gpi) == pytest.approx(0.1)
            assert vehicle.stream_interval_s(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED) == (
                pytest.approx(0.1)
            )
            assert vehicle.stream_interval_s(imu) == pytest.approx(1.0)
            frames = []
            async with aclosing(link.telemetry()) as stream:
                async for frame in stream:
                    frames.append(frame.t_s)
                    if frame.t_s - frames[0] >= 3.0:
                        break
            assert (len(frames) - 1) / (frames[-1] - frames[0]) == pytest.approx(10.0, rel=0.15)
        assert vehicle.stream_interval_s(gpi) == pytest.approx(0.02)  # PX4's own again
        assert vehicle.stream_interval_s(imu) < 0.0  # off, as it was (the simulator has none)


async def test_px4_whose_airspeed_range_misses_the_missions_speeds_is_refused_before_take_off():
    config = sim_config(1, speedup=SPEEDUP)  # FW_AIRSPD_MIN / _MAX: 12 / 24 m/s
    slow = SetpointLimits(VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.2))
    async with asyncio.timeout(40.0), running_sim(config) as sim:
        async with (
            hub_of(sim) as hub,
            hub.link(1, LinkConfig(slow)) as link,
        ):
            with pytest.raises(
                LinkError, match=r"of 12-24 m/s only \(FW_AIRSPD_MIN, FW_AIRSPD_MAX\)"
            ):
                await link.wait_ready(10.0)
        assert sim.truth().vehicles[0].armed is False


async def test_one_link_per_vehicle_and_missing_vehicles_time_out():
    config = sim_config(1, speedup=SPEEDUP)
    async with (
        asyncio.timeout(30.0),
        running_sim(config) as sim,
        hub_of(sim) as hub,
        hub.link(1, VELOCITY),
    ):
        with pytest.raises(LinkError, match="already has an open link"):
            async with hub.link(1, VELOCITY):
                pass
        with pytest.raises(LinkError, match="no autopilot with system id 7"):
            async with hub.link(7, VELOCITY, timeout_s=0.5):
                pass


async def test_cancelling_the_mission_puts_the_vehicle_in_hold():
    config = sim_config(1, speedup=SPEEDUP)
    east = CourseSpeedCommand(math.pi / 2, 16.0)
    async with (
        asyncio.timeout(40.0),
        running_sim(config) as sim,
        hub_of(sim) as hub,
    ):
        flying = asyncio.Event()

        async def mission() -> None:
            async with hub.link(1, VELOCITY) as link:
                await launch(link, east)
                flying.set()
                await fly(link, east, 1e6)  # until cancelled, as by Ctrl-C

        task = asyncio.create_task(mission(), name="mission")
        try:
            await flying.wait()
            await sim.wait_until(sim.time_s + 2.0)
            assert sim.truth().vehicles[0].mode == "offboard"
        finally:
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
        assert sim.truth().vehicles[0].mode == "hold"
