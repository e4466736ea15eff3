"""The PX4 and ArduPlane personalities do what the real autopilots do, over real UDP MAVLink.

Each test names the source it holds the simulator to (see the docstrings of sitl.px4,
sitl.arduplane and sitl.vehicle).
"""

import asyncio
import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm
from pymavlink.dialects.v20 import common as mavlink

from sitl.arduplane import GUIDED, RTL
from sitl.guidance import CourseCommand, LineCommand
from sitl.px4 import HOLD, OFFBOARD
from sitl.telemetry import GRAVITY_M_S2
from tests.support.sitl_fixtures import RawClient, arduplane_of, running_sim, sim_config

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
SPEEDUP = 5.0
#: position + velocity, acceleration used (ignore yaw and yaw rate only)
POS_VEL_ACCEL = 1024 | 2048
#: position + velocity, acceleration ignored
POS_VEL = 64 | 128 | 256 | 1024 | 2048


def _setpoint(
    client: RawClient, north: float, east: float, vn: float, ve: float, an=0.0, ae=0.0, mask=POS_VEL
) -> None:
    client.send(
        mavlink.MAVLink_set_position_target_local_ned_message(
            0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, mask,
            north, east, -100.0, vn, ve, 0.0, an, ae, 0.0, 0.0, 0.0,
        )
    )  # fmt: skip


async def _offboard(sim, client: RawClient, send) -> None:
    await client.heartbeat()
    assert await client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target_system=1) == 0
    send()
    await asyncio.sleep(0.05)
    mode = (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6.0, 0.0)
    assert await client.command(mavlink.MAV_CMD_DO_SET_MODE, *mode, target_system=1) == ACCEPTED
    assert sim.vehicles[0].mode is OFFBOARD


async def _stream(sim, until_s: float, send) -> None:
    while sim.time_s < until_s:
        send()
        await asyncio.sleep(0.05)


async def test_px4_do_change_speed_is_accepted_but_ignored_in_offboard_and_applied_in_hold():
    config = sim_config(1, speedup=SPEEDUP, takeoff="launch")  # cruise = FW_AIRSPD_TRIM 18 m/s
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:

        def send() -> None:
            _setpoint(client, 0.0, 300.0, -16.0, 0.0)  # asks 16 m/s: flown at trim

        await _offboard(sim, client, send)
        change = mavlink.MAV_CMD_DO_CHANGE_SPEED
        assert await client.command(change, 0.0, 22.0, -1.0, target_system=1) == ACCEPTED
        await _stream(sim, sim.time_s + 10.0, send)
        assert sim.truth().vehicles[0].state.speed_m_s == pytest.approx(18.0, abs=0.01)
        hold = (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4.0, 3.0)
        assert await client.command(mavlink.MAV_CMD_DO_SET_MODE, *hold, target_system=1) == 0
        assert sim.vehicles[0].mode is HOLD
        assert await client.command(change, 0.0, 22.0, -1.0, target_system=1) == ACCEPTED
        await sim.wait_until(sim.time_s + 10.0)
        assert sim.truth().vehicles[0].state.speed_m_s == pytest.approx(22.0, abs=0.05)


@pytest.mark.parametrize(("sign", "turn"), [("v1.16.0", -1.0), ("ned", 1.0)])
async def test_px4_acceleration_normal_to_the_velocity_is_fed_forward_as_curvature(sign, turn):
    # at 1x: setpoints resent at 20 Hz track the turn the way MAVSDK's would
    config = sim_config(1, speedup=1.0, takeoff="launch", px4_curvature_sign=sign)
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:
        start = sim.vehicles[0].state  # flying north at 18 m/s

        def send() -> None:  # along its course at 18 m/s, 2.7 m/s^2 to its right (r = 120 m)
            s = sim.vehicles[0].state
            c, n = math.cos(s.course_rad), math.sin(s.course_rad)
            an, ae = 0.5 * c - 2.7 * n, 0.5 * n + 2.7 * c
            _setpoint(client, s.north_m, s.east_m, 18.0 * c, 18.0 * n, an, ae, mask=POS_VEL_ACCEL)

        await _offboard(sim, client, send)
        command = sim.vehicles[0].command
        assert isinstance(command, LineCommand)
        # PX4 v1.16.0: radius = -sign(v x a) v^2 / a_n: the right turn asked is fed forward left
        assert command.curvature_per_m == pytest.approx(turn * 2.7 / 18.0**2, rel=0.01)
        await _stream(sim, sim.time_s + 2.0, send)
        rate = sim.truth().vehicles[0].state.course_rate_rad_s
        assert rate == pytest.approx(turn * 18.0 * 2.7 / 18.0**2, rel=0.1)  # V / r
        assert start.north_m < sim.vehicles[0].state.north_m


@pytest.mark.parametrize("roll_limit_deg", [50.0, None])
async def test_px4_follows_an_offboard_line_banking_up_to_fw_r_lim(roll_limit_deg):
    # a 40 m radius at 18 m/s is 0.45 rad/s, 40 deg of bank: within FW_R_LIM, beyond the envelope
    config = sim_config(
        1,
        speedup=1.0,
        takeoff="launch",
        px4_curvature_sign="ned",
        px4_roll_limit_deg=roll_limit_deg,
    )
    envelope_rate = config.vehicles[0].limits.max_course_rate_rad_s
    assert envelope_rate < 0.3
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:

        def send() -> None:
            s = sim.vehicles[0].state
            c, n = math.cos(s.course_rad), math.sin(s.course_rad)
            a = 18.0**2 / 40.0
            an, ae = -a * n, a * c
            _setpoint(client, s.north_m, s.east_m, 18.0 * c, 18.0 * n, an, ae, mask=POS_VEL_ACCEL)

        await _offboard(sim, client, send)
        await _stream(sim, sim.time_s + 2.0, send)
        rate = abs(sim.truth().vehicles[0].state.course_rate_rad_s)
        if roll_limit_deg is None:
            assert rate == pytest.approx(envelope_rate, rel=0.02)
        else:
            assert rate == pytest.approx(18.0 / 40.0, rel=0.1)


async def test_px4_reports_in_air_during_the_ground_roll():
    config = sim_config(1, speedup=SPEEDUP)  # runway take-off (the default)
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:
        await client.heartbeat()
        assert await client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target_system=1) == 0
        await sim.wait_until(sim.time_s + 2.0)
        assert not sim.vehicles[0].in_air
        assert not sim.vehicles[0].rolling
        assert await client.command(mavlink.MAV_CMD_NAV_TAKEOFF, target_system=1) == ACCEPTED
        huds = []  # what the ground station saw up to the first in-air report

        def first_in_air(m) -> bool:
            if m.get_type() == "VFR_HUD":
                huds.append(m)
            return (
                m.get_type() == "EXTENDED_SYS_STATE"
                and m.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR
            )

        state = await client.wait_for(first_in_air, timeout_s=10.0)
        assert state is not None
        assert huds, "no VFR_HUD before the in-air report"
        hud = huds[-1]  # the HUD of the moment PX4 first says in air (not one read later)
        v = sim.vehicles[0]
        assert 7.0 <= hud.airspeed <= 10.5
        assert hud.alt == pytest.approx(config.origin_alt_m, abs=0.01)  # no height
        await sim.wait_until(sim.time_s + 30.0)
        assert v.mode is HOLD
        assert v.air_altitude_m == pytest.approx(100.0, abs=1.0)


async def test_vehicles_report_their_own_boot_clocks():
    config = sim_config(3, speedup=SPEEDUP)
    async with running_sim(config) as sim:
        clients = [RawClient(e.gcs_port) for e in sim.endpoints]
        for c in clients:
            await c.__aenter__()
        try:
            t0 = sim.time_s
            stamps = []
            for c in clients:
                msg = await c.wait_for(lambda m: m.get_type() == "ATTITUDE", timeout_s=2.0)
                stamps.append(msg.time_boot_ms / 1000.0)
            t1 = sim.time_s
        finally:
            for c in clients:
                await c.__aexit__()
    for i, stamp in enumerate(stamps):  # vehicle i booted 3.7 i s before the simulation
        assert t0 - 0.2 <= stamp - 3.7 * i <= t1 + 0.2


async def test_arduplane_streams_at_1_hz_until_a_message_interval_is_set():
    config = sim_config(1, speedup=SPEEDUP, autopilot="arduplane", takeoff="launch")
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:
        await client.heartbeat()

        async def rate_of(name: str, seconds: float) -> float:
            start, t0 = len(client.inbox.messages), sim.time_s
            await sim.wait_until(t0 + seconds)
            got = [m for m in client.inbox.messages[start:] if m.get_type() == name]
            return len(got) / seconds

        assert await rate_of("GLOBAL_POSITION_INT", 10.0) == pytest.approx(1.0, abs=0.15)
        assert await rate_of("EXTENDED_SYS_STATE", 3.0) == 0.0  # only on request
        interval = mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
        gpi = mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT
        assert await client.command(interval, gpi, 50_000.0, 0.0, target_system=1) == ACCEPTED
        assert await rate_of("GLOBAL_POSITION_INT", 5.0) == pytest.approx(20.0, rel=0.1)
        assert await rate_of("ATTITUDE", 5.0) == pytest.approx(1.0, abs=0.25)  # others stay
        client.send(
            mavlink.MAVLink_request_data_stream_message(1, 1, mavlink.MAV_DATA_STREAM_EXTRA1, 10, 1)
        )
        await asyncio.sleep(0.1)
        assert await rate_of("ATTITUDE", 5.0) == pytest.approx(10.0, rel=0.1)


async def _command_int(client: RawClient, command: int, *p: float) -> int:
    full = [*p, *([0.0] * (4 - len(p)))]
    start = len(client.inbox.messages)
    client.send(apm.MAVLink_command_int_message(1, 1, 0, command, 0, 0, *full, 0, 0, 0.0))
    ack = await client.wait_for(
        lambda m: m.get_type() == "COMMAND_ACK" and m.command == command, start=start
    )
    return int(ack.result)


async def _guided_in_the_air(sim, client: RawClient) -> None:
    await client.heartbeat()
    assert await client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target_system=1) == 0
    mode = (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,)
    assert await client.command(mavlink.MAV_CMD_DO_SET_MODE, *mode, 13.0, target_system=1) == 0
    await sim.wait_until(sim.time_s + 1.0)
    assert await client.command(mavlink.MAV_CMD_DO_SET_MODE, *mode, 15.0, target_system=1) == 0
    assert sim.vehicles[0].mode == GUIDED


async def test_arduplane_guided_heading_gain_is_guided_p_and_param3_limits_the_bank():
    config = sim_config(1, speedup=SPEEDUP, autopilot="arduplane", takeoff="launch")
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:
        await _guided_in_the_air(sim, client)
        v = sim.vehicles[0]
        heading = apm.MAV_CMD_GUIDED_CHANGE_HEADING
        cog = apm.HEADING_TYPE_COURSE_OVER_GROUND
        # straight and level first (GUIDED was entered in a loiter's bank)
        course = math.degrees(v.state.course_rad) % 360.0
        assert await _command_int(client, heading, cog, course, 1000.0) == ACCEPTED
        await sim.wait_until(sim.time_s + 12.0)
        course = math.degrees(v.state.course_rad) % 360.0
        assert abs(v.state.course_rate_rad_s) < 0.002
        # 5 degrees to the right, no lateral limit: bank 50 deg/rad * error, rate
        # eta g tan(bank) / V (eta 0.70, real 4.6.2's turn at a bank), the bank reached through
        # the roll controller's first-order lag (tau 0.5 s)
        assert await _command_int(client, heading, cog, course + 5.0, 1000.0) == ACCEPTED
        await sim.wait_until(sim.time_s + 0.04)
        eta = config.arduplane_turn_efficiency
        assert eta == pytest.approx(0.70)
        gain = eta * GRAVITY_M_S2 * math.tan(math.radians(50.0 * math.radians(5.0))) / 18.0
        gain /= math.radians(5.0)

        def rate_per_error() -> float:
            error = math.remainder(math.radians(course + 5.0) - v.state.course_rad, math.tau)
            return v.state.course_rate_rad_s / error

        assert rate_per_error() < 0.2 * gain  # the bank has only begun to build
        await sim.wait_until(sim.time_s + 0.46)
        assert 0.5 * gain < rate_per_error() < 0.8 * gain  # ~1 - 1/e of it after tau
        assert 0.3 < gain < 0.4  # ~0.34 /s at 18 m/s, not the k = 1 /s assumed
        await sim.wait_until(sim.time_s + 12.0)  # settled on the course (tau 1/gain + the lag)
        error = math.remainder(math.radians(course + 5.0) - v.state.course_rad, math.tau)
        assert abs(math.degrees(error)) < 0.5
        # 60 degrees off, param3 0.5 m/s^2: bank atan(0.5 / g), course rate eta a / V
        target = (math.degrees(v.state.course_rad) + 60.0) % 360.0
        assert await _command_int(client, heading, cog, target, 0.5) == ACCEPTED
        await sim.wait_until(sim.time_s + 3.0)  # six roll time constants
        assert isinstance(v.command, CourseCommand) or v.mode == GUIDED
        assert v.state.course_rate_rad_s == pytest.approx(eta * 0.5 / 18.0, rel=0.02)


async def test_arduplane_gcs_failsafe_trips_when_enabled_before_the_gcs_heartbeat_is_counted():
    config = sim_config(1, speedup=SPEEDUP, autopilot="arduplane", takeoff="launch")
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:
        await _guided_in_the_air(sim, client)
        await sim.wait_until(6.0)  # more than FS_LONG_TIMEOUT after boot

        def param_set(name: str, value: float, kind: int) -> None:
            client.send(apm.MAVLink_param_set_message(1, 1, name.encode(), value, kind))

        # the race: SYSID_MYGCS to this client's id, then FS_GCS_ENABL at once, no heartbeat
        param_set("SYSID_MYGCS", 255.0, apm.MAV_PARAM_TYPE_INT16)
        param_set("FS_LONG_ACTN", 1.0, apm.MAV_PARAM_TYPE_INT8)
        param_set("FS_GCS_ENABL", 1.0, apm.MAV_PARAM_TYPE_INT8)
        text = await client.wait_for(
            lambda m: m.get_type() == "STATUSTEXT" and "GCS Failsafe" in m.text, timeout_s=5.0
        )
        assert text.text == "GCS Failsafe On: RTL"
        assert sim.vehicles[0].mode == RTL


async def test_arduplane_gcs_failsafe_holds_off_when_the_heartbeat_comes_first():
    config = sim_config(1, speedup=SPEEDUP, autopilot="arduplane", takeoff="launch")
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:
        await _guided_in_the_air(sim, client)
        await sim.wait_until(6.0)
        stop = asyncio.Event()

        async def heartbeats() -> None:
            while not stop.is_set():
                client.send(apm.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
                await asyncio.sleep(0.2)

        async with asyncio.TaskGroup() as group:
            group.create_task(heartbeats(), name="heartbeats")
            await asyncio.sleep(0.5)  # the heartbeat is counted first, then the failsafe set
            client.send(apm.MAVLink_param_set_message(1, 1, b"FS_LONG_ACTN", 1.0, 2))
            client.send(apm.MAVLink_param_set_message(1, 1, b"FS_GCS_ENABL", 1.0, 2))
            await sim.wait_until(sim.time_s + 10.0)
            stop.set()
        assert not arduplane_of(sim.vehicles[0]).gcs_failsafe_active
        assert sim.vehicles[0].mode == GUIDED


async def test_arduplane_guided_entered_on_the_climb_holds_the_low_altitude():
    config = sim_config(1, speedup=SPEEDUP, autopilot="arduplane")  # runway take-off
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:
        await client.heartbeat()
        assert await client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target_system=1) == 0
        mode = (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,)
        assert await client.command(mavlink.MAV_CMD_DO_SET_MODE, *mode, 13.0, target_system=1) == 0
        v = sim.vehicles[0]
        while not (v.in_air and v.air_altitude_m > 3.0):
            await sim.wait_until(sim.time_s + 0.1)
        assert await client.command(mavlink.MAV_CMD_DO_SET_MODE, *mode, 15.0, target_system=1) == 0
        entered_m = v.air_altitude_m
        assert entered_m < 10.0
        await sim.wait_until(sim.time_s + 20.0)
        assert v.air_altitude_m == pytest.approx(entered_m, abs=0.01)  # not 100 m
        assert arduplane_of(v).guided_targets[2] == pytest.approx(entered_m)
