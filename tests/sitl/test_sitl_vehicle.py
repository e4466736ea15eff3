"""The simulated vehicle's state machine and flight, without sockets: modes, arming, commands,
setpoints, failsafe, telemetry consistency."""

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink

from app.core.frames import wrap_pi
from app.core.plant import FixedWingState
from sitl.camera import TrackingCamera
from sitl.config import CameraConfig, SimConfig, VehicleConfig, default_limits, default_vehicles
from sitl.geodesy import Geodesy
from sitl.guidance import LineCommand, LoiterCommand, VelocityCommand
from sitl.px4 import HOLD, OFFBOARD, RETURN, TAKEOFF
from sitl.server import autopilot_for
from sitl.vehicle import CAMERA_COMPONENT, SimVehicle
from tests.support.sitl_fixtures import px4_of

DT = 0.02
GCS = mavlink.MAVLink(None, 255, 190)
DECODER = mavlink.MAVLink(None, 0, 0)


def _wire(msg):
    """The message as the vehicle receives it: packed by a GCS (255/190) and decoded."""
    packet = msg.pack(GCS)
    DECODER.buf, DECODER.buf_index = bytearray(), 0
    return DECODER.parse_buffer(packet)[0]


class Rig:
    """One vehicle with its own simulated (and wall) clock."""

    def __init__(self, **sim_overrides):
        # arming launches it (a catapult) unless a test flies the runway take-off
        sim_overrides = {"takeoff": "launch", **sim_overrides}
        self.sim = SimConfig(vehicles=default_vehicles(1), **sim_overrides)
        self.geodesy = Geodesy(
            self.sim.origin_lat_deg, self.sim.origin_lon_deg, self.sim.origin_alt_m
        )
        camera = TrackingCamera(CameraConfig(), np.random.default_rng(0))
        vc = self.sim.vehicles[0]
        self.vehicle = SimVehicle(
            0, vc, self.sim, camera, self.geodesy, autopilot_for(vc, self.sim)
        )
        self.t = 0.0
        self.sent = []

    def send(self, msg):
        return self.vehicle.handle(_wire(msg), self.t, self.t)

    def command(self, command, *params, component=1, target=1):
        full = [*params, *([math.nan] * (7 - len(params)))]
        return self.send(mavlink.MAVLink_command_long_message(target, component, command, 0, *full))

    def ack(self, command, *params, **kw):
        (_component, ack), *_rest = self.command(command, *params, **kw)
        assert ack.get_type() == "COMMAND_ACK"
        assert ack.command == command
        assert ack.target_system == 255
        assert ack.target_component == 190
        return ack.result

    def setpoint(self, mask, x=0.0, y=0.0, vx=0.0, vy=0.0, yaw=0.0):
        return self.send(
            mavlink.MAVLink_set_position_target_local_ned_message(
                0,
                1,
                1,
                mavlink.MAV_FRAME_LOCAL_NED,
                mask,
                x,
                y,
                0.0,
                vx,
                vy,
                0.0,
                0,
                0,
                0,
                yaw,
                0.0,
            )
        )

    def fly(self, seconds, setpoint=None, check=None):
        """Fly ``seconds``, resending ``setpoint`` at 10 Hz (every 5th step)."""
        for k in range(round(seconds / DT)):
            if setpoint is not None and k % 5 == 0:
                setpoint()
            before = self.vehicle.state
            self.t += DT
            self.sent.extend(self.vehicle.advance(DT, self.t, self.t, 0.0, 0.0))
            self.sent.extend(
                self.vehicle.telemetry(
                    self.t,
                    lambda: self.geodesy.to_geodetic(
                        self.vehicle.state.east_m,
                        self.vehicle.state.north_m,
                        self.vehicle.altitude_m,
                    ),
                )
            )
            if check is not None:
                check(before, self.vehicle.state)

    def arm_offboard(self, setpoint):
        assert self.ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == mavlink.MAV_RESULT_ACCEPTED
        setpoint()
        assert self.ack(mavlink.MAV_CMD_DO_SET_MODE, 1.0, 6.0, 0.0) == mavlink.MAV_RESULT_ACCEPTED


VELOCITY = 1 | 2 | 4 | 64 | 128 | 256 | 1024 | 2048
POSITION = 4 | 8 | 16 | 32 | 64 | 128 | 256 | 2048
POSITION_VELOCITY = 4 | 32 | 64 | 128 | 256 | 2048


def test_boots_disarmed_on_the_ground_in_hold_and_arming_launches_it():
    rig = Rig()
    v = rig.vehicle
    assert (v.armed, v.in_air, v.mode) == (False, False, HOLD)
    rig.fly(1.0)
    assert v.state.speed_m_s == 0.0
    beats = [m for _, m in rig.sent if m.get_type() == "HEARTBEAT"]
    assert beats[-1].custom_mode == (4 << 16) | (3 << 24)
    assert not beats[-1].base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert rig.ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == mavlink.MAV_RESULT_ACCEPTED
    start = rig.sim.vehicles[0].start
    assert (v.armed, v.in_air) == (True, True)
    assert v.state.speed_m_s == start.speed_m_s
    assert v.state.course_rad == start.course_rad
    # in the air a plain disarm is refused; a forced one (21196) is not
    assert rig.ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0) == mavlink.MAV_RESULT_DENIED
    assert (
        rig.ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0, 21196.0) == mavlink.MAV_RESULT_ACCEPTED
    )
    assert (v.armed, v.in_air) == (False, False)


def test_offboard_needs_setpoints_and_shows_in_the_heartbeat():
    rig = Rig()
    rig.ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    assert rig.ack(mavlink.MAV_CMD_DO_SET_MODE, 1.0, 6.0, 0.0) == mavlink.MAV_RESULT_DENIED
    rig.setpoint(VELOCITY, vx=18.0)
    replies = rig.command(mavlink.MAV_CMD_DO_SET_MODE, 1.0, 6.0, 0.0)
    assert replies[0][1].result == mavlink.MAV_RESULT_ACCEPTED
    beat = replies[1][1]
    assert beat.get_type() == "HEARTBEAT"
    assert beat.custom_mode == OFFBOARD.custom_mode == 6 << 16
    assert beat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    # a mode the simulator does not fly (manual) is refused
    assert rig.ack(mavlink.MAV_CMD_DO_SET_MODE, 1.0, 1.0, 0.0) == mavlink.MAV_RESULT_DENIED


@pytest.mark.parametrize("course_deg", [90.0, -135.0, 180.0])
def test_velocity_setpoint_is_a_course_and_speed_within_limits(course_deg):
    rig = Rig()
    limits = rig.sim.vehicles[0].limits
    course = math.radians(course_deg)

    def setpoint():
        rig.setpoint(VELOCITY, vx=30.0 * math.cos(course), vy=30.0 * math.sin(course))

    def check(before, after):
        rate = abs(wrap_pi(after.course_rad - before.course_rad)) / DT
        assert rate <= limits.max_course_rate_rad_s * (1 + 1e-9)
        assert limits.min_speed_m_s <= after.speed_m_s <= limits.max_speed_m_s
        assert abs(after.speed_m_s - before.speed_m_s) <= limits.max_accel_m_s2 * DT + 1e-9

    rig.arm_offboard(setpoint)
    rig.fly(30.0, setpoint, check)
    assert isinstance(rig.vehicle.command, VelocityCommand)
    assert abs(wrap_pi(rig.vehicle.state.course_rad - course)) < 1e-3
    assert rig.vehicle.state.speed_m_s == pytest.approx(limits.max_speed_m_s)  # 30 is clamped


def test_yaw_only_setpoint_flies_the_yaw_at_cruise_speed():
    rig = Rig()
    mask = 1 | 2 | 4 | 8 | 16 | 32 | 64 | 128 | 256 | 2048

    def setpoint():
        rig.setpoint(mask, yaw=math.radians(-90.0))

    rig.arm_offboard(setpoint)
    rig.fly(20.0, setpoint)
    assert rig.vehicle.state.course_rad == pytest.approx(math.radians(-90.0), abs=1e-3)
    assert rig.vehicle.state.speed_m_s == pytest.approx(18.0)


@pytest.mark.slow
def test_position_setpoint_flies_to_the_point_and_loiters_on_the_radius():
    rig = Rig()
    target_east, target_north = 400.0, 300.0

    def setpoint():
        rig.setpoint(POSITION, x=target_north, y=target_east)

    rig.arm_offboard(setpoint)
    rig.fly(120.0, setpoint)
    radius = rig.vehicle.loiter_radius_m
    worst = 0.0

    def check(_before, after):
        nonlocal worst
        worst = max(
            worst,
            abs(math.hypot(after.east_m - target_east, after.north_m - target_north) - radius),
        )

    rig.fly(60.0, setpoint, check)
    assert isinstance(rig.vehicle.command, LoiterCommand)
    assert worst < 2.0


def test_position_and_velocity_setpoint_flies_the_line_through_the_point():
    rig = Rig()

    def setpoint():  # the north-south line 300 m east of the origin, flown southward
        rig.setpoint(POSITION_VELOCITY, x=0.0, y=300.0, vx=-16.0, vy=0.0)

    rig.arm_offboard(setpoint)
    rig.fly(120.0, setpoint)
    assert isinstance(rig.vehicle.command, LineCommand)
    assert rig.vehicle.state.east_m == pytest.approx(300.0, abs=1.0)
    assert abs(wrap_pi(rig.vehicle.state.course_rad - math.pi)) < 0.01
    # PX4 v1.16 flies it at FW_AIRSPD_TRIM (the cruise speed here), not the velocity's 16 m/s
    assert rig.vehicle.state.speed_m_s == pytest.approx(18.0)


@pytest.mark.parametrize(("action", "mode"), [("hold", HOLD), ("return", RETURN)])
def test_failsafe_when_setpoints_stop(action, mode):
    rig = Rig(failsafe_action=action)

    def setpoint():
        rig.setpoint(VELOCITY, vx=0.0, vy=18.0)

    rig.arm_offboard(setpoint)
    rig.fly(5.0, setpoint)
    setpoint()  # the last one
    t_last = rig.t
    rig.sent.clear()
    rig.fly(0.98)
    assert rig.vehicle.mode is OFFBOARD
    rig.fly(0.06)
    assert rig.vehicle.mode is mode
    texts = [m for _, m in rig.sent if m.get_type() == "STATUSTEXT"]
    assert len(texts) == 1
    assert f"switching to {action}" in texts[0].text
    beats = [m for _, m in rig.sent if m.get_type() == "HEARTBEAT"]
    assert beats[-1].custom_mode == mode.custom_mode
    assert rig.t - t_last <= 1.5
    command = rig.vehicle.command
    assert isinstance(command, LoiterCommand)
    if mode is RETURN:
        start = rig.sim.vehicles[0].start
        assert (command.center_east_m, command.center_north_m) == (start.east_m, start.north_m)


def test_failsafe_waits_for_wall_time_too():
    """At a high speed-up a client resending at 20 Hz wall is seconds apart in simulated time."""
    rig = Rig(offboard_timeout_min_wall_s=0.25)

    def setpoint():
        rig.setpoint(VELOCITY, vx=18.0)

    rig.arm_offboard(setpoint)
    for _ in range(200):  # 2 s simulated between setpoints, 0.1 s wall: not a loss
        setpoint()
        for _ in range(100):
            rig.t += DT
            rig.vehicle.advance(DT, rig.t, rig.t / 20.0, 0.0, 0.0)
        assert rig.vehicle.mode is OFFBOARD


def test_unsupported_and_misaddressed_commands():
    rig = Rig()
    assert rig.ack(mavlink.MAV_CMD_NAV_LAND) == mavlink.MAV_RESULT_UNSUPPORTED
    assert rig.ack(31337) == mavlink.MAV_RESULT_UNSUPPORTED
    ((component, ack),) = rig.command(
        mavlink.MAV_CMD_REQUEST_MESSAGE, 259.0, component=CAMERA_COMPONENT
    )
    assert component == CAMERA_COMPONENT
    assert ack.result == mavlink.MAV_RESULT_UNSUPPORTED
    assert rig.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, component=42) == []
    assert not rig.vehicle.armed


def test_request_message_and_message_intervals():
    rig = Rig()
    replies = rig.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 242.0)
    assert replies[0][1].result == mavlink.MAV_RESULT_ACCEPTED
    home = replies[1][1]
    start = rig.sim.vehicles[0].start
    lat, lon, _ = rig.geodesy.to_geodetic(start.east_m, start.north_m, 0.0)
    assert (home.latitude, home.longitude) == (round(lat * 1e7), round(lon * 1e7))
    replies = rig.command(mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1.0)
    version = replies[1][1]
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    assert rig.ack(mavlink.MAV_CMD_REQUEST_MESSAGE, 12345.0) == mavlink.MAV_RESULT_UNSUPPORTED

    assert (
        rig.ack(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 30.0, 20_000.0) == mavlink.MAV_RESULT_ACCEPTED
    )
    assert rig.ack(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 74.0, -1.0) == mavlink.MAV_RESULT_ACCEPTED
    assert (
        rig.ack(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 9999.0, 1e5) == mavlink.MAV_RESULT_UNSUPPORTED
    )
    rig.fly(2.0)
    count = {
        name: sum(m.get_type() == name for _, m in rig.sent)
        for name in ("ATTITUDE", "VFR_HUD", "GLOBAL_POSITION_INT", "HEARTBEAT")
    }
    # every stream fires at t = 0.02 (due since boot), then on its own grid up to t = 2.0
    assert count == {"ATTITUDE": 100, "VFR_HUD": 0, "GLOBAL_POSITION_INT": 21, "HEARTBEAT": 3}


def test_telemetry_is_consistent_with_the_motion_in_a_turn():
    rig = Rig()

    def setpoint():
        rig.setpoint(VELOCITY, vx=-18.0, vy=0.0)  # north to south: a turn at the rate limit

    rig.arm_offboard(setpoint)
    rig.fly(0.5, setpoint)
    rig.sent.clear()
    rig.fly(2.0, setpoint)
    state = rig.vehicle.state
    assert abs(state.course_rate_rad_s) == pytest.approx(0.2)
    attitude = [m for _, m in rig.sent if m.get_type() == "ATTITUDE"][-1]
    expected_roll = math.atan(state.speed_m_s * state.course_rate_rad_s / 9.80665)
    assert attitude.roll == pytest.approx(expected_roll, abs=1e-6)
    assert math.copysign(1.0, attitude.roll) == math.copysign(1.0, attitude.yawspeed)
    assert attitude.time_boot_ms == round(rig.t * 1000)
    position = [m for _, m in rig.sent if m.get_type() == "GLOBAL_POSITION_INT"][-1]
    east, north, up = rig.geodesy.to_local(
        position.lat / 1e7, position.lon / 1e7, position.alt / 1000.0
    )
    assert (east, north) == pytest.approx((state.east_m, state.north_m), abs=0.02)
    assert up == pytest.approx(100.0, abs=0.01)
    assert position.relative_alt == 100_000
    assert position.vx == round(state.v_north_m_s * 100)
    local = [m for _, m in rig.sent if m.get_type() == "LOCAL_POSITION_NED"][-1]
    assert (local.x, local.y, local.z) == pytest.approx(
        (state.north_m, state.east_m, -100.0), abs=1e-3
    )
    hud = [m for _, m in rig.sent if m.get_type() == "VFR_HUD"][-1]
    assert hud.airspeed == pytest.approx(state.speed_m_s)
    landed = [m for _, m in rig.sent if m.get_type() == "EXTENDED_SYS_STATE"][-1]
    assert landed.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR


@pytest.mark.slow
def test_takeoff_return_hold_and_change_speed():
    rig = Rig()
    assert rig.ack(mavlink.MAV_CMD_NAV_TAKEOFF) == mavlink.MAV_RESULT_DENIED  # disarmed
    rig.ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    assert rig.ack(mavlink.MAV_CMD_NAV_TAKEOFF) == mavlink.MAV_RESULT_ACCEPTED
    assert rig.vehicle.mode is TAKEOFF
    rig.fly(5.1)
    assert rig.vehicle.mode is HOLD
    assert rig.ack(mavlink.MAV_CMD_DO_CHANGE_SPEED, 0.0, 22.0) == mavlink.MAV_RESULT_ACCEPTED
    rig.fly(10.0)
    assert rig.vehicle.state.speed_m_s == pytest.approx(22.0, abs=0.01)
    assert rig.ack(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH) == mavlink.MAV_RESULT_ACCEPTED
    assert rig.vehicle.mode is RETURN
    rig.fly(200.0)
    start = rig.sim.vehicles[0].start
    d = math.hypot(
        rig.vehicle.state.east_m - start.east_m, rig.vehicle.state.north_m - start.north_m
    )
    assert d == pytest.approx(rig.vehicle.loiter_radius_m, abs=2.0)


def test_non_finite_setpoints_are_dropped():
    rig = Rig()
    rig.setpoint(VELOCITY, vx=18.0)
    kept = px4_of(rig.vehicle).offboard_setpoint
    rig.setpoint(VELOCITY, vx=math.nan, vy=1.0)
    rig.setpoint(POSITION, x=math.inf)
    assert px4_of(rig.vehicle).offboard_setpoint is kept


def test_loiter_radius_tighter_than_the_vehicle_can_turn_is_refused():
    with pytest.raises(ValueError, match="tighter than the vehicle can turn"):
        VehicleConfig(
            limits=default_limits(),
            start=FixedWingState(0, 0, 0, 18),
            cruise_speed_m_s=18.0,
            loiter_radius_m=80.0,
        )
    with pytest.raises(ValueError, match="cruise_speed_m_s 30"):
        VehicleConfig(
            limits=default_limits(), start=FixedWingState(0, 0, 0, 18), cruise_speed_m_s=30.0
        )


def test_attitude_quaternion_on_request_matches_the_euler_attitude():
    rig = Rig()
    assert (
        rig.ack(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 31.0, 100_000.0)
        == mavlink.MAV_RESULT_ACCEPTED
    )

    def setpoint():
        rig.setpoint(VELOCITY, vx=0.0, vy=18.0)

    rig.arm_offboard(setpoint)
    rig.fly(3.0, setpoint)
    euler = [m for _, m in rig.sent if m.get_type() == "ATTITUDE"][-1]
    q = [m for _, m in rig.sent if m.get_type() == "ATTITUDE_QUATERNION"][-1]
    assert q.time_boot_ms == euler.time_boot_ms
    roll = math.atan2(2 * (q.q1 * q.q2 + q.q3 * q.q4), 1 - 2 * (q.q2**2 + q.q3**2))
    yaw = math.atan2(2 * (q.q1 * q.q4 + q.q2 * q.q3), 1 - 2 * (q.q3**2 + q.q4**2))
    assert roll == pytest.approx(euler.roll, abs=1e-6)
    assert yaw == pytest.approx(euler.yaw, abs=1e-6)
    assert abs(euler.roll) > 0.3  # turning at 0.2 rad/s and 18 m/s banks about 20 degrees


def test_in_a_cross_wind_px4_crabs_to_hold_the_ground_course_and_reports_it():
    # NPFG follows the path over the ground in the wind its EKF estimates (navigateLine and
    # navigateBearing take the wind): a cross wind turns the nose into it, it does not drift
    rig = Rig()

    def setpoint():
        rig.setpoint(VELOCITY, vx=18.0, vy=0.0)  # north

    rig.arm_offboard(setpoint)
    v = rig.vehicle

    def fly(seconds):
        for _ in range(round(seconds / DT)):
            setpoint()
            rig.t += DT
            rig.sent.extend(v.advance(DT, rig.t, rig.t, 5.0, 0.0))
            rig.sent.extend(v.telemetry(rig.t, lambda: (47.0, 8.0, 500.0)))

    fly(20.0)  # turn into the wind
    east0, north0 = v.state.east_m, v.state.north_m
    fly(10.0)
    assert v.state.east_m - east0 == pytest.approx(0.0, abs=0.5)  # no drift across the course
    along = math.sqrt(18.0**2 - 5.0**2)
    assert v.state.north_m - north0 == pytest.approx(10.0 * along, rel=0.01)
    crab = math.asin(5.0 / 18.0)
    assert wrap_pi(v.state.course_rad + crab) == pytest.approx(0.0, abs=0.01)  # nose upwind
    position = [m for _, m in rig.sent if m.get_type() == "GLOBAL_POSITION_INT"][-1]
    hud = [m for _, m in rig.sent if m.get_type() == "VFR_HUD"][-1]
    assert position.vx == pytest.approx(100.0 * along, abs=3.0)
    assert abs(position.vy) <= 3
    assert hud.airspeed == pytest.approx(18.0)
    assert hud.groundspeed == pytest.approx(along, abs=0.05)


@pytest.mark.slow
def test_reposition_holds_at_a_geodetic_point():
    rig = Rig()
    lat, lon, _ = rig.geodesy.to_geodetic(500.0, 800.0, 0.0)
    assert (
        rig.send(
            mavlink.MAVLink_command_int_message(
                1,
                1,
                mavlink.MAV_FRAME_GLOBAL,
                mavlink.MAV_CMD_DO_REPOSITION,
                0,
                0,
                -1.0,
                1.0,
                0.0,
                math.nan,
                round(lat * 1e7),
                round(lon * 1e7),
                100.0,
            )
        )[0][1].result
        == mavlink.MAV_RESULT_DENIED
    )  # on the ground
    rig.ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    replies = rig.send(
        mavlink.MAVLink_command_int_message(
            1,
            1,
            mavlink.MAV_FRAME_GLOBAL,
            mavlink.MAV_CMD_DO_REPOSITION,
            0,
            0,
            -1.0,
            1.0,
            0.0,
            math.nan,
            round(lat * 1e7),
            round(lon * 1e7),
            100.0,
        )
    )
    assert replies[0][1].result == mavlink.MAV_RESULT_ACCEPTED
    command = rig.vehicle.command
    assert isinstance(command, LoiterCommand)
    assert (command.center_east_m, command.center_north_m) == pytest.approx(
        (500.0, 800.0), abs=0.05
    )
    rig.fly(240.0)
    d = math.hypot(rig.vehicle.state.east_m - 500.0, rig.vehicle.state.north_m - 800.0)
    assert d == pytest.approx(rig.vehicle.loiter_radius_m, abs=2.0)


def test_px4_parameters_set_the_failsafe_cruise_speed_and_loiter_radius():
    rig = Rig()

    def param_set(name, value):
        ((_, reply),) = rig.send(mavlink.MAVLink_param_set_message(1, 1, name.encode(), value, 0))
        assert reply.get_type() == "PARAM_VALUE"
        assert reply.param_id == name
        return reply.param_value

    def as_int32(value):
        return struct.unpack("<f", struct.pack("<i", value))[0]

    listed = rig.send(mavlink.MAVLink_param_request_list_message(1, 1))
    assert [m.param_id for _, m in listed] == [
        "COM_OF_LOSS_T",
        "COM_OBL_RC_ACT",
        "FW_AIRSPD_TRIM",
        "NAV_LOITER_RAD",
        "FW_AIRSPD_MIN",
        "FW_AIRSPD_MAX",
    ]
    assert param_set("COM_OBL_RC_ACT", as_int32(3)) == as_int32(3)
    assert px4_of(rig.vehicle).failsafe_action == "return"
    assert param_set("COM_OF_LOSS_T", 3.0) == 3.0
    assert param_set("COM_OF_LOSS_T", -1.0) == 3.0  # refused, unchanged
    assert param_set("NAV_LOITER_RAD", 50.0) == pytest.approx(135.0)  # tighter than it can turn
    assert param_set("NAV_LOITER_RAD", 200.0) == 200.0
    assert param_set("FW_AIRSPD_TRIM", 99.0) == 24.0  # clamped to the speed limit
    assert param_set("FW_AIRSPD_MIN", 5.0) == 12.0  # the vehicle's speed range: read-only
    assert rig.send(mavlink.MAVLink_param_set_message(1, 1, b"NO_SUCH", 1.0, 9)) == []
    ((_, read),) = rig.send(mavlink.MAVLink_param_request_read_message(1, 1, b"", 1))
    assert read.param_id == "COM_OBL_RC_ACT"


ANY_FLOAT = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=32),
    st.sampled_from([0.0, -1.0, 1e30, -1e30, math.nan, math.inf]),
)
COMMANDS = st.sampled_from(
    [
        mavlink.MAV_CMD_COMPONENT_ARM_DISARM,
        mavlink.MAV_CMD_DO_SET_MODE,
        mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
        mavlink.MAV_CMD_REQUEST_MESSAGE,
        mavlink.MAV_CMD_DO_CHANGE_SPEED,
        mavlink.MAV_CMD_DO_REPOSITION,
        mavlink.MAV_CMD_NAV_TAKEOFF,
        mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH,
        mavlink.MAV_CMD_GET_HOME_POSITION,
        0,
        65535,
    ]
)


@settings(max_examples=30, deadline=None)
@given(
    command=COMMANDS,
    params=st.lists(ANY_FLOAT, min_size=7, max_size=7),
    mask=st.integers(0, 0xFFFF),
    frame=st.sampled_from([mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_NED, 0, 255]),
    setpoint=st.lists(ANY_FLOAT, min_size=5, max_size=5),
)
def test_no_input_breaks_the_vehicle(command, params, mask, frame, setpoint):
    """Whatever a client sends, the vehicle answers or ignores it and keeps flying sanely."""
    rig = Rig()
    rig.ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    x, y, vx, vy, yaw = setpoint
    rig.send(
        mavlink.MAVLink_set_position_target_local_ned_message(
            0, 1, 1, frame, mask, x, y, 0.0, vx, vy, 0.0, 0, 0, 0, yaw, 0.0
        )
    )
    rig.send(mavlink.MAVLink_command_long_message(1, 1, command, 0, *params))
    rig.ack(mavlink.MAV_CMD_DO_SET_MODE, 1.0, 6.0, 0.0)  # offboard, if the setpoint was usable
    rig.fly(3.0)
    state = rig.vehicle.state
    limits = rig.sim.vehicles[0].limits
    assert all(math.isfinite(v) for v in (state.east_m, state.north_m, state.course_rad))
    if rig.vehicle.in_air:
        assert limits.min_speed_m_s <= state.speed_m_s <= limits.max_speed_m_s


def test_any_stream_can_be_requested_once():
    rig = Rig()
    rig.ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    for msg_id, name in (
        (33, "GLOBAL_POSITION_INT"),
        (24, "GPS_RAW_INT"),
        (31, "ATTITUDE_QUATERNION"),
    ):
        (_, ack), (_, message) = rig.command(mavlink.MAV_CMD_REQUEST_MESSAGE, float(msg_id))
        assert ack.result == mavlink.MAV_RESULT_ACCEPTED
        assert message.get_type() == name
    (_, ack), (_, position) = rig.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 33.0)
    start = rig.sim.vehicles[0].start
    east, north, up = rig.geodesy.to_local(
        position.lat / 1e7, position.lon / 1e7, position.alt / 1000.0
    )
    assert up == pytest.approx(100.0, abs=0.01)
    assert (east, north) == pytest.approx((start.east_m, start.north_m), abs=0.02)
