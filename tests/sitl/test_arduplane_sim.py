"""The simulator's ArduPlane personality: its command handling (no sockets), and the app's
ArduPlane adapter flying it end to end through MAVSDK over real UDP."""

import asyncio
import math
import socket
from contextlib import aclosing
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink
from pymavlink.dialects.v20.ardupilotmega import (
    MAV_CMD_GUIDED_CHANGE_ALTITUDE,
    MAV_CMD_GUIDED_CHANGE_HEADING,
    MAV_CMD_GUIDED_CHANGE_SPEED,
)

from app.adapters.vehicle.autopilots.limits import SetpointLimits
from app.adapters.vehicle.mavsdk.hub import MavsdkHub
from app.adapters.vehicle.mavsdk.link import LinkConfig
from app.core.frames import wrap_pi
from app.core.plant import VehicleEnvelope, heading_for_ground_course
from app.errors import LinkError
from app.runtime.ports.vehicle import (
    CourseSpeedCommand,
    LeftOffboard,
    OffboardLostError,
    TurnLearned,
)
from sitl.arduplane import GUIDED, long_failsafe_mode
from sitl.camera import TrackingCamera
from sitl.config import SimConfig, default_vehicles
from sitl.geodesy import Geodesy
from sitl.server import autopilot_for
from sitl.vehicle import SimVehicle
from tests.adapters.test_vehicle_link_sim import fly, next_event, origin_of, urls_of
from tests.support.sitl_fixtures import arduplane_of, running_sim, sim_config

SPEEDUP = 8.0
LIMITS = SetpointLimits(VehicleEnvelope(18.0, 12.0, 24.0, 2.0, 0.2))
MAVSDK_GCS_ID = 245  # MAVSDK's ground-station system id (ArduPilot's SYSID_MYGCS default: 255)
ACCEPTED, DENIED = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_DENIED
FAILED, UNSUPPORTED = mavlink.MAV_RESULT_FAILED, mavlink.MAV_RESULT_UNSUPPORTED
REL_ALT = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT


# ---- the personality without sockets ---------------------------------------------------------


def plane(**overrides: object) -> SimVehicle:
    # TAKEOFF launches it (a catapult) unless a test flies the runway take-off
    overrides = {"takeoff": "launch", **overrides}
    sim = SimConfig(vehicles=default_vehicles(1), autopilot="arduplane", **overrides)  # type: ignore[arg-type]
    camera = TrackingCamera(sim.camera, np.random.default_rng(0))
    geodesy = Geodesy(sim.origin_lat_deg, sim.origin_lon_deg, sim.origin_alt_m)
    vc = sim.vehicles[0]
    return SimVehicle(0, vc, sim, camera, geodesy, autopilot_for(vc, sim))


def wire(msg: mavlink.MAVLink_message, src: int = MAVSDK_GCS_ID) -> mavlink.MAVLink_message:
    """The message as the vehicle receives it (packed by system ``src``, decoded)."""
    data = msg.pack(mavlink.MAVLink(None, src, 190))
    decoded = mavlink.MAVLink(None, 1, 1).parse_buffer(data)
    assert decoded is not None
    return decoded[0]


def ack_of(out: list[tuple[int, mavlink.MAVLink_message]], command: int) -> int:
    (result,) = [m.result for _, m in out if m.get_type() == "COMMAND_ACK" and m.command == command]
    return int(result)


def command_int(v: SimVehicle, command: int, *params: float, frame: int = 0, z: float = 0.0) -> int:
    p = [*params, *([0.0] * (4 - len(params)))]
    msg = mavlink.MAVLink_command_int_message(1, 1, frame, command, 0, 0, *p, 0, 0, z)
    return ack_of(v.handle(wire(msg), 0.0, 0.0), command)


def command_long(v: SimVehicle, command: int, *params: float) -> int:
    p = [*params, *([0.0] * (7 - len(params)))]
    msg = mavlink.MAVLink_command_long_message(1, 1, command, 0, *p)
    return ack_of(v.handle(wire(msg), 0.0, 0.0), command)


def heartbeat_of(v: SimVehicle) -> mavlink.MAVLink_message:
    (msg,) = [
        m for _, m in v.telemetry(1000.0, lambda: (0.0, 0.0, 0.0)) if m.get_type() == "HEARTBEAT"
    ]
    return msg


def flying(v: SimVehicle) -> bool:
    return v.in_air


def targets(v: SimVehicle) -> tuple[float | None, float | None, float | None]:
    return arduplane_of(v).guided_targets


def guided_in_the_air(**overrides: object) -> SimVehicle:
    v = plane(**overrides)
    assert command_long(v, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == ACCEPTED
    assert not flying(v)  # armed in MANUAL: the throttle is the pilot's
    assert command_long(v, mavlink.MAV_CMD_DO_SET_MODE, 1, 13) == ACCEPTED  # TAKEOFF launches
    assert flying(v)
    assert command_long(v, mavlink.MAV_CMD_DO_SET_MODE, 1, 15) == ACCEPTED
    assert v.mode == GUIDED
    return v


def test_heartbeat_is_arduplanes():
    v = plane()
    hb = heartbeat_of(v)
    assert (hb.type, hb.autopilot) == (
        mavlink.MAV_TYPE_FIXED_WING,
        mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
    )
    assert (hb.custom_mode, hb.system_status) == (0, mavlink.MAV_STATE_STANDBY)  # MANUAL, ground
    assert hb.base_mode == mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | 1  # + custom mode
    v = guided_in_the_air()
    hb = heartbeat_of(v)
    assert (hb.custom_mode, hb.system_status) == (15, mavlink.MAV_STATE_ACTIVE)
    assert hb.base_mode == 1 | 8 | 16 | 64 | 128  # custom, guided, stabilize, stick mixing, armed


def test_command_answers_follow_arduplane():
    v = plane()
    # guided slew commands outside GUIDED: MAV_RESULT_FAILED ("only valid in guided mode")
    assert command_int(v, MAV_CMD_GUIDED_CHANGE_HEADING, 0, 90.0, 3.0) == FAILED
    # only a QuadPlane takes off with NAV_TAKEOFF (MAVSDK's Action.takeoff sends it)
    assert command_long(v, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 30.0) == FAILED
    # a mode ArduPlane has not, or a QuadPlane mode: FAILED; no custom-mode flag: DENIED
    assert command_long(v, mavlink.MAV_CMD_DO_SET_MODE, 1, 18) == FAILED  # QHOVER
    assert command_long(v, mavlink.MAV_CMD_DO_SET_MODE, 1, 9) == FAILED
    assert command_long(v, mavlink.MAV_CMD_DO_SET_MODE, 0, 15) == DENIED
    v = guided_in_the_air()
    heading, speed, altitude = (
        MAV_CMD_GUIDED_CHANGE_HEADING,
        MAV_CMD_GUIDED_CHANGE_SPEED,
        MAV_CMD_GUIDED_CHANGE_ALTITUDE,
    )
    assert command_int(v, heading, 0, 360.0, 3.0) == DENIED  # outside [0, 360)
    assert command_int(v, heading, 7, 90.0, 3.0) == DENIED  # unknown heading type
    assert command_long(v, heading, 0, 90.0, 3.0) == UNSUPPORTED  # COMMAND_INT only
    assert command_int(v, speed, 1, 15.0, 2.0) == DENIED  # ground speed: not supported
    assert command_int(v, speed, 0, 30.0, 2.0) == FAILED  # above AIRSPEED_MAX (24)
    assert command_int(v, altitude, 0, 0, 3.0, frame=REL_ALT, z=0.0) == DENIED
    assert command_int(v, altitude, 0, 0, 3.0, frame=mavlink.MAV_FRAME_LOCAL_NED, z=80.0) == DENIED
    assert targets(v) == (None, None, 100.0)  # entered at 100 m: the guided WP's altitude
    assert command_int(v, heading, 0, 270.0, 3.0) == ACCEPTED
    assert command_int(v, speed, 0, 15.0, 2.0) == ACCEPTED
    assert command_int(v, altitude, 0, 0, 3.0, frame=REL_ALT, z=120.0) == ACCEPTED
    course, speed_m_s, altitude_m = targets(v)
    assert course == pytest.approx(-math.pi / 2)
    assert (speed_m_s, altitude_m) == (15.0, 120.0)
    # leaving GUIDED forgets the guided targets (Mode::enter)
    assert command_long(v, mavlink.MAV_CMD_NAV_LOITER_UNLIM) == ACCEPTED
    assert (v.mode.name, targets(v)) == ("loiter", (None, None, None))


def test_guided_turn_is_limited_by_the_lateral_acceleration_and_flies_the_targets():
    v = guided_in_the_air(arduplane_turn_efficiency=1.0)
    speed = v.state.speed_m_s
    assert speed == pytest.approx(18.0)
    # turn about at 1.8 m/s^2: at 18 m/s no faster than 0.1 rad/s (the vehicle could do 0.2)
    assert command_int(v, MAV_CMD_GUIDED_CHANGE_HEADING, 0, 180.0, 1.8) == ACCEPTED
    assert (
        command_int(v, MAV_CMD_GUIDED_CHANGE_ALTITUDE, 0, 0, 0.0, frame=REL_ALT, z=110.0)
        == ACCEPTED
    )
    rates, dt = [], 0.02
    for k in range(2500):
        v.advance(dt, k * dt, k * dt, 0.0, 0.0)
        rates.append(abs(v.state.course_rate_rad_s))
    assert max(rates) <= 1.8 / 18.0 + 1e-9
    assert max(rates) == pytest.approx(0.1)  # and it used all of it
    assert v.state.course_rad == pytest.approx(
        -math.pi, abs=1e-3
    ) or v.state.course_rad == pytest.approx(math.pi, abs=1e-3)
    assert v.altitude_m == pytest.approx(110.0, abs=0.1)  # 10 m with TECS's 5 s: within 50 s
    # param3 0 is taken as 0.05 m/s^2: a turn of a few thousandths of a rad/s (once the bank
    # has come down through the roll controller's lag)
    assert command_int(v, MAV_CMD_GUIDED_CHANGE_HEADING, 0, 90.0, 0.0) == ACCEPTED
    for k in range(200):
        v.advance(dt, 60.0 + k * dt, 60.0 + k * dt, 0.0, 0.0)
    assert abs(v.state.course_rate_rad_s) == pytest.approx(0.05 / 18.0, rel=1e-3)


@pytest.mark.parametrize("efficiency", [0.7, 0.5])
def test_the_guided_turn_is_that_fraction_of_the_coordinated_one_and_attitude_shows_the_bank(
    efficiency,
):
    """Real ArduPlane 4.6.2 SITL turned at 0.70 of g tan(bank) / V: the bank GUIDED is held
    to (atan(param3 / g)) turns at eta of the coordinated rate, and ATTITUDE's roll is that
    bank, not the coordinated bank of the rate flown."""
    v = guided_in_the_air(arduplane_turn_efficiency=efficiency)
    assert command_int(v, MAV_CMD_GUIDED_CHANGE_HEADING, 0, 180.0, 1.8) == ACCEPTED
    dt = 0.02
    for k in range(500):  # 10 s: the bank has settled at its limit, the turn not yet done
        v.advance(dt, k * dt, k * dt, 0.0, 0.0)
    speed = v.state.speed_m_s
    assert abs(v.state.course_rate_rad_s) == pytest.approx(efficiency * 1.8 / speed, rel=1e-3)
    (attitude,) = [
        m for _, m in v.telemetry(10.0, lambda: (0.0, 0.0, 0.0)) if m.get_type() == "ATTITUDE"
    ]
    assert abs(attitude.roll) == pytest.approx(math.atan(1.8 / 9.80665), rel=1e-3)


@pytest.mark.parametrize("tau", [4.0, 0.0])
def test_the_guided_airspeed_follows_the_command_through_tecs_lag(tau):
    """Real ArduPlane 4.6.2's airspeed followed GUIDED_CHANGE_SPEED about 3 s late: here a
    first-order lag of ``arduplane_speed_time_constant_s`` (0: the airframe's acceleration
    limit alone)."""
    v = guided_in_the_air(arduplane_speed_time_constant_s=tau)
    assert v.state.speed_m_s == pytest.approx(18.0)
    assert command_int(v, MAV_CMD_GUIDED_CHANGE_SPEED, 0, 12.0, 0.0) == ACCEPTED
    dt = 0.02
    for k in range(200):  # 4 s
        v.advance(dt, k * dt, k * dt, 0.0, 0.0)
    # the airframe's own speed loop is first order too (1 /s, within its 2 m/s^2): in series,
    # 6 m/s of step decays as (tau e^(-t/tau) - e^(-t)) / (tau - 1)
    assert v.config.limits.speed_gain_per_s == 1.0
    if tau:
        left = 6.0 * (tau * math.exp(-4.0 / tau) - math.exp(-4.0)) / (tau - 1.0)
    else:
        left = 6.0 * math.exp(-4.0)  # (its first second is at the 2 m/s^2 limit: a little more)
    assert v.state.speed_m_s == pytest.approx(12.0 + left, abs=0.2)


def test_turn_efficiency_must_be_a_fraction():
    for bad in (0.0, -0.5, 1.2, math.nan):
        with pytest.raises(ValueError, match="arduplane_turn_efficiency"):
            plane(arduplane_turn_efficiency=bad)


def test_a_guided_altitude_slew_rate_re_bases_on_the_current_altitude_and_hardly_climbs():
    """ModeGuided::update_target_altitude (4.6.2): every 0.1 s TECS is given the current
    altitude moved rate x 0.1 s toward the command. At 3 m/s that is 0.3 m of error, which
    TECS closes with its 5 s time constant: 0.06 m/s (real SITL: 0.05 m/s, alt_error 0.3 m).
    param3 0 (the maximum rate) gives TECS the command: it climbs at its 5 m/s limit."""
    v = guided_in_the_air()
    assert v.altitude_m == pytest.approx(100.0)
    assert (
        command_int(v, MAV_CMD_GUIDED_CHANGE_ALTITUDE, 0, 0, 3.0, frame=REL_ALT, z=170.0)
        == ACCEPTED
    )
    dt = 0.02
    for k in range(3000):  # 60 s
        v.advance(dt, k * dt, k * dt, 0.0, 0.0)
    assert v.altitude_m - 100.0 == pytest.approx(60.0 * 0.3 / 5.0, rel=0.05)  # 3.6 m, not 60
    assert (
        command_int(v, MAV_CMD_GUIDED_CHANGE_ALTITUDE, 0, 0, 0.0, frame=REL_ALT, z=170.0)
        == ACCEPTED
    )
    climbs = []
    for k in range(1500):  # 30 s more
        v.advance(dt, 60.0 + k * dt, 60.0 + k * dt, 0.0, 0.0)
        climbs.append(v.climb_m_s)
    assert max(climbs) == pytest.approx(5.0)  # TECS's limit
    assert v.altitude_m == pytest.approx(170.0, abs=0.5)


def test_course_over_ground_is_held_in_a_cross_wind():
    # closed form: 5 m/s from the west (blowing east), course north at 15 m/s airspeed
    heading = heading_for_ground_course(0.0, 15.0, 5.0, 0.0)
    assert heading == pytest.approx(-math.asin(5.0 / 15.0))
    ground_east = 15.0 * math.sin(heading) + 5.0
    assert ground_east == pytest.approx(0.0, abs=1e-12)
    assert heading_for_ground_course(0.0, 4.0, 5.0, 0.0) == pytest.approx(-math.pi / 2)
    assert heading_for_ground_course(1.0, 0.0, 5.0, 0.0) == 1.0


def hb(src: int) -> mavlink.MAVLink_message:
    return wire(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3), src)


def test_gcs_failsafe_counts_only_sysid_mygcs_heartbeats():
    v = plane(gcs_failsafe="return", gcs_system_id=255)
    v.handle(hb(MAVSDK_GCS_ID), 0.0, 0.0)  # MAVSDK's id: not the GCS this ArduPlane knows
    # the boot counts as 255's last heartbeat (init_ardupilot), 245's do not: it trips
    out = v.advance(0.02, 60.0, 60.0, 0.0, 0.0)
    assert [m.text for _, m in out if m.get_type() == "STATUSTEXT"] == ["GCS Failsafe On: RTL"]
    v = plane(gcs_failsafe="return", gcs_system_id=255, arduplane_gcs_seen_at_boot=False)
    v.handle(hb(MAVSDK_GCS_ID), 0.0, 0.0)
    assert v.advance(0.02, 60.0, 60.0, 0.0, 0.0) == []  # no 255 heartbeat ever: never trips
    assert arduplane_of(v).gcs_failsafe_active is False
    v = guided_in_the_air()
    arduplane_of(v).params.update(FS_GCS_ENABL=1, FS_LONG_ACTN=0)  # heartbeat; continue
    v.handle(hb(255), 10.0, 10.0)
    assert v.advance(0.02, 14.0, 14.0, 0.0, 0.0) == []  # FS_LONG_TIMEOUT 5 s not yet over
    out = v.advance(0.02, 15.1, 15.1, 0.0, 0.0)
    texts = [m.text for _, m in out if m.get_type() == "STATUSTEXT"]
    assert texts == ["GCS Failsafe On: GUIDED"]
    assert v.mode == GUIDED  # FS_LONG_ACTN 0: GUIDED continues
    assert heartbeat_of(v).system_status == mavlink.MAV_STATE_CRITICAL
    out = v.handle(hb(255), 16.0, 16.0)
    assert [m.text for _, m in out] == ["GCS Failsafe Off"]
    assert arduplane_of(v).gcs_failsafe_active is False


def param_values(
    out: list[tuple[int, mavlink.MAVLink_message]],
) -> list[tuple[str, float, int, int]]:
    return [
        (m.param_id, m.param_value, m.param_type, m.param_index)
        for _, m in out
        if m.get_type() == "PARAM_VALUE"
    ]


def param_set(v: SimVehicle, name: str, value: float, kind: int) -> list[tuple[int, Any]]:
    msg = mavlink.MAVLink_param_set_message(1, 1, name.encode(), value, kind)
    return v.handle(wire(msg), 0.0, 0.0)


INT8, INT16, REAL32 = (
    mavlink.MAV_PARAM_TYPE_INT8,
    mavlink.MAV_PARAM_TYPE_INT16,
    mavlink.MAV_PARAM_TYPE_REAL32,
)


def test_failsafe_parameters_are_served_as_arduplane_serves_them():
    v = plane()  # stock: SYSID_MYGCS 255, FS_GCS_ENABL 0, FS_LONG_ACTN 0, FS_LONG_TIMEOUT 5
    listed = v.handle(wire(mavlink.MAVLink_param_request_list_message(1, 1)), 0.0, 0.0)
    # each with the type it is stored as and the value C-cast into the float field
    assert param_values(listed) == [
        ("SYSID_MYGCS", 255.0, INT16, 0),
        ("FS_GCS_ENABL", 0.0, INT8, 1),
        ("FS_LONG_ACTN", 0.0, INT8, 2),
        ("FS_LONG_TIMEOUT", 5.0, REAL32, 3),
        ("AIRSPEED_MIN", 12.0, INT16, 4),  # the vehicle's speed range, whole m/s
        ("AIRSPEED_MAX", 24.0, INT16, 5),
        ("GUIDED_P", 5000.0, REAL32, 6),  # GUIDED's heading loop: bank cdeg per rad of error
        ("ROLL_LIMIT_DEG", 45.0, REAL32, 7),
    ]
    by_name = mavlink.MAVLink_param_request_read_message(1, 1, b"SYSID_MYGCS", -1)
    assert param_values(v.handle(wire(by_name), 0.0, 0.0)) == [("SYSID_MYGCS", 255.0, INT16, 65535)]
    by_index = mavlink.MAVLink_param_request_read_message(1, 1, b"", 3)
    assert param_values(v.handle(wire(by_index), 0.0, 0.0)) == [("FS_LONG_TIMEOUT", 5.0, REAL32, 3)]
    unknown = mavlink.MAVLink_param_request_read_message(1, 1, b"COM_OBL_RC_ACT", -1)
    assert v.handle(wire(unknown), 0.0, 0.0) == []  # ArduPilot does not answer it
    # PARAM_SET: stored as its own type whatever the sender says, confirmed with index -1
    assert param_values(param_set(v, "SYSID_MYGCS", 245.0, REAL32)) == [
        ("SYSID_MYGCS", 245.0, INT16, 65535)
    ]
    assert param_values(param_set(v, "FS_GCS_ENABL", 0.996, INT8)) == [
        ("FS_GCS_ENABL", 1.0, INT8, 65535)  # AP_Param::set_float adds 0.01, then truncates
    ]
    assert param_set(v, "FS_LONG_ACTN", math.nan, INT8) == []
    arduplane_of(v).param_write_denied = frozenset({"FS_LONG_ACTN"})
    out = param_set(v, "FS_LONG_ACTN", 1.0, INT8)
    assert [m.text for _, m in out if m.get_type() == "STATUSTEXT"] == [
        "Param write denied (FS_LONG_ACTN)"
    ]
    assert param_values(out) == [("FS_LONG_ACTN", 0.0, INT8, 65535)]  # the value in force


def test_gcs_failsafe_follows_its_parameters_live():
    # stock parameters: FS_GCS_ENABL 0; the boot is not counted as a heartbeat here (the race
    # it opens has its own test)
    v = guided_in_the_air(arduplane_gcs_seen_at_boot=False)
    v.handle(hb(MAVSDK_GCS_ID), 10.0, 10.0)
    param_set(v, "FS_GCS_ENABL", 1.0, INT8)
    param_set(v, "FS_LONG_ACTN", 1.0, INT8)
    assert v.advance(0.02, 30.0, 30.0, 0.0, 0.0) == []  # 245's heartbeats do not count
    param_set(v, "SYSID_MYGCS", MAVSDK_GCS_ID, INT16)
    v.handle(hb(MAVSDK_GCS_ID), 40.0, 40.0)
    param_set(v, "FS_LONG_TIMEOUT", 2.0, REAL32)
    assert v.advance(0.02, 42.5, 42.5, 0.0, 0.0) == []  # 2.5 s of wall time not yet over
    param_set(v, "FS_GCS_ENABL", 0.0, INT8)
    assert v.advance(0.02, 43.0, 43.0, 0.0, 0.0) == []  # switched off again: nothing
    param_set(v, "FS_GCS_ENABL", 1.0, INT8)
    out = v.advance(0.02, 43.1, 43.1, 0.0, 0.0)
    texts = [m.text for _, m in out if m.get_type() == "STATUSTEXT"]
    assert texts == ["GCS Failsafe On: RTL"]
    assert v.mode.name == "rtl"  # FS_LONG_ACTN 1


def test_ardupilot_4_7_names_the_gcs_by_mav_gcs_sysid_and_a_range():
    v = plane(gcs_sysid_param="MAV_GCS_SYSID")  # ArduPilot 4.7: SYSID_MYGCS renamed
    listed = v.handle(wire(mavlink.MAVLink_param_request_list_message(1, 1)), 0.0, 0.0)
    assert [(name, value) for name, value, _, _ in param_values(listed)][:2] == [
        ("MAV_GCS_SYSID", 255.0),
        ("MAV_GCS_SYSID_HI", 0.0),
    ]
    old_name = mavlink.MAVLink_param_request_read_message(1, 1, b"SYSID_MYGCS", -1)
    assert v.handle(wire(old_name), 0.0, 0.0) == []  # no longer there: no answer
    assert arduplane_of(v).is_gcs(255)
    assert not arduplane_of(v).is_gcs(MAVSDK_GCS_ID)
    param_set(v, "MAV_GCS_SYSID_HI", 250.0, INT16)  # below MAV_GCS_SYSID: still 255 alone
    assert not arduplane_of(v).is_gcs(250)
    param_set(v, "MAV_GCS_SYSID", 240.0, INT16)  # 240..250: a range of ground stations
    assert arduplane_of(v).is_gcs(MAVSDK_GCS_ID)
    assert arduplane_of(v).is_gcs(240)
    assert not arduplane_of(v).is_gcs(251)


def test_long_failsafe_action_by_mode_follows_failsafe_long_on_event():
    guided, auto, loiter, rtl, manual = 15, 10, 12, 11, 0
    assert long_failsafe_mode(guided, 0) is None  # continue: GUIDED flies its course on
    assert long_failsafe_mode(auto, 0) is None
    assert long_failsafe_mode(loiter, 0) == rtl  # every other mode returns on 0
    assert long_failsafe_mode(manual, 0) == rtl
    assert long_failsafe_mode(guided, 1) == rtl
    assert long_failsafe_mode(guided, 2) == 5  # glide: FBWA
    assert long_failsafe_mode(guided, 3) is None  # parachute: not imitated, the mode stays
    assert long_failsafe_mode(guided, 4) == auto
    assert long_failsafe_mode(rtl, 1) is None
    assert long_failsafe_mode(rtl, 4) == auto


# ---- the app's ArduPlane adapter over MAVSDK and UDP -----------------------------------------


@pytest.mark.slow
async def test_arduplane_joined_between_heartbeats_is_still_flown_as_arduplane():
    """ArduPlane sends HEARTBEAT at 1 Hz and its other streams faster: a link opened while the
    vehicle is already streaming sees it before its first heartbeat, when MAVSDK still reports a
    generic autopilot (the velocity form, whose NAV_TAKEOFF ArduPlane refuses). The link waits
    for the heartbeat before it chooses."""
    config = sim_config(1, speedup=1.0, autopilot="arduplane", takeoff="launch")
    async with asyncio.timeout(30.0), running_sim(config) as sim:
        await asyncio.sleep(2.5)  # streaming for a while: the link joins between heartbeats
        for _ in range(3):
            await asyncio.sleep(0.35)  # a different place in the heartbeat period each time
            async with (
                MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
                hub.link(1, LinkConfig(LIMITS)) as link,
            ):
                assert link.autopilot_name == "arduplane"


@pytest.mark.slow
async def test_arduplane_adapter_is_chosen_takes_off_flies_courses_and_stops_in_loiter():
    config = sim_config(1, speedup=SPEEDUP, autopilot="arduplane", takeoff="launch")
    async with asyncio.timeout(40.0), running_sim(config) as sim:
        async with (
            MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
            hub.link(1, LinkConfig(LIMITS)) as link,
        ):
            assert link.autopilot_name == "arduplane"  # chosen from the heartbeat
            events = link.events()
            ground = await link.wait_ready(10.0)
            assert (ground.flight_mode, ground.armed, ground.in_air) == ("MANUAL", False, False)
            await link.arm()
            await link.take_off(10.0)  # TAKEOFF mode (ArduPlane refuses NAV_TAKEOFF)
            assert sim.truth().vehicles[0].mode == "takeoff"
            east = CourseSpeedCommand(math.pi / 2, 16.0, altitude_m=110.0)
            await link.start_offboard(east)
            assert link.flight_mode == "GUIDED"
            await fly(link, east, 20.0)
            frame = link.latest
            assert frame is not None
            assert abs(wrap_pi(frame.course_rad - math.pi / 2)) < 0.02
            assert frame.ground_speed_m_s == pytest.approx(16.0, abs=0.1)
            # TECS closes the last metres with its 5 s time constant
            assert frame.relative_altitude_m == pytest.approx(110.0, abs=0.5)
            # an about-turn: the vehicle never turns faster than 0.2 rad/s
            rates: list[float] = []

            async def watch() -> None:
                async for truth in sim.truth_samples(0.1):
                    rates.append(abs(truth.vehicles[0].state.course_rate_rad_s))

            watcher = asyncio.create_task(watch(), name="watch-rates")
            west = CourseSpeedCommand(-math.pi / 2, 20.0)
            await fly(link, west, 25.0)
            watcher.cancel()
            frame = link.latest
            assert frame is not None
            assert abs(wrap_pi(frame.course_rad + math.pi / 2)) < 0.02
            assert frame.ground_speed_m_s == pytest.approx(20.0, abs=0.1)
            assert max(rates) <= 0.2 + 1e-9
            # the airframe turns at 0.7 of the coordinated rate for its bank (as real ArduPlane
            # SITL): the adapter learned that from ATTITUDE in the turn and widened the bank
            # limit, so the envelope's 0.2 rad/s was flown, not 0.14
            learned = await next_event(aiter(events), TurnLearned, 1.0)
            assert isinstance(learned, TurnLearned)
            assert learned.efficiency == pytest.approx(0.7, abs=0.05)
            assert link.counters.turn_efficiency == pytest.approx(learned.efficiency, abs=1e-3)
            assert max(rates) > 0.19
        # leaving the link stops it: LOITER
        assert sim.truth().vehicles[0].mode == "loiter"


async def test_refused_mode_change_and_refused_speed_are_link_errors_with_the_result():
    config = sim_config(1, speedup=SPEEDUP, autopilot="arduplane", takeoff="launch")
    wide = SetpointLimits(VehicleEnvelope(21.0, 12.0, 30.0, 2.0, 0.2))
    async with asyncio.timeout(40.0), running_sim(config) as sim:
        vehicle = sim.vehicles[0]
        autopilot = arduplane_of(vehicle)
        autopilot.params["AIRSPEED_MAX"] = 30.0  # so that the mission's 12-30 m/s is taken
        async with (
            MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
            hub.link(1, LinkConfig(wide)) as link,
        ):
            await link.wait_ready(10.0)
            autopilot.params["AIRSPEED_MAX"] = 24.0  # and then narrowed behind its back
            await link.arm()
            await link.take_off(10.0)
            autopilot.gcs_blocked_modes = frozenset({15})  # FLTMODE_GCSBLOCK: no GUIDED from a GCS
            with pytest.raises(LinkError, match="mode change to GUIDED refused: MAV_RESULT_FAILED"):
                await link.start_offboard(CourseSpeedCommand(0.0, 18.0))
            autopilot.gcs_blocked_modes = frozenset()
            await link.start_offboard(CourseSpeedCommand(0.0, 18.0))
            # 28 m/s is within the app's limits but above the vehicle's AIRSPEED_MAX (now 24)
            with pytest.raises(LinkError, match="GUIDED_CHANGE_SPEED refused: MAV_RESULT_FAILED"):
                await link.send(CourseSpeedCommand(0.0, 28.0))
            assert autopilot.guided_targets[1] == 18.0


async def test_a_mission_faster_than_the_airspeed_range_is_refused_before_take_off():
    config = sim_config(
        1, speedup=SPEEDUP, autopilot="arduplane", takeoff="launch"
    )  # AIRSPEED 12-24 m/s
    wide = SetpointLimits(VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.2))
    async with asyncio.timeout(30.0), running_sim(config) as sim:
        async with (
            MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
            hub.link(1, LinkConfig(wide)) as link,
        ):
            with pytest.raises(
                LinkError, match=r"takes airspeeds of 12-24 m/s only \(AIRSPEED_MIN, AIRSPEED_MAX\)"
            ):
                await link.wait_ready(10.0)
        assert not sim.truth().vehicles[0].armed


async def test_leaving_guided_by_someone_else_is_reported():
    config = sim_config(1, speedup=SPEEDUP, autopilot="arduplane", takeoff="launch")
    async with (
        asyncio.timeout(40.0),
        running_sim(config) as sim,
        MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
        hub.link(1, LinkConfig(LIMITS)) as link,
        aclosing(link.events()) as events,
    ):
        north = CourseSpeedCommand(0.0, 18.0)
        await link.wait_ready(10.0)
        await link.arm()
        await link.take_off(10.0)
        await link.start_offboard(north)
        await fly(link, north, 2.0)
        # a pilot's ground station switches it to RTL
        endpoint = sim.endpoints[0]
        other = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        message = mavlink.MAVLink_command_long_message(1, 1, 176, 0, 1, 11, 0, 0, 0, 0, 0)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.sendto(message.pack(other), (endpoint.local_host, endpoint.local_port))
        left = await next_event(events, LeftOffboard, 5.0)
        assert isinstance(left, LeftOffboard)
        assert (left.vehicle_id, left.flight_mode) == (1, "RTL")
        with pytest.raises(OffboardLostError, match="left GUIDED"):
            await link.send(north)
        assert sim.truth().vehicles[0].mode == "rtl"


@pytest.mark.slow
async def test_stock_arduplane_is_made_to_return_when_mavsdk_heartbeats_stop():
    # stock ArduPlane: SYSID_MYGCS 255 (not MAVSDK's 245), FS_GCS_ENABL 0, FS_LONG_ACTN 0;
    # left so, it would fly its last GUIDED course for ever once the app goes silent
    config = sim_config(1, speedup=SPEEDUP, autopilot="arduplane", takeoff="launch")
    link_config = LinkConfig(LIMITS, link_timeout_s=1.0)
    async with (
        asyncio.timeout(40.0),
        running_sim(config) as sim,
        MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
        hub.link(1, link_config) as link,
        aclosing(link.events()) as events,
    ):
        vehicle = sim.vehicles[0]
        autopilot = arduplane_of(vehicle)
        east = CourseSpeedCommand(math.pi / 2, 16.0)
        await link.wait_ready(10.0)  # prepare() sets the three over MAVLink
        assert autopilot.params["SYSID_MYGCS"] == MAVSDK_GCS_ID
        assert (autopilot.params["FS_GCS_ENABL"], autopilot.params["FS_LONG_ACTN"]) == (1, 1)
        await link.arm()
        await link.take_off(10.0)
        await link.start_offboard(east)
        # MAVSDK heartbeats at 1 Hz wall: fly 2 s wall first (no failsafe before one is seen)
        await fly(link, east, 2.0 * SPEEDUP)
        sim.set_link(0, False)
        async with asyncio.timeout(10.0):
            while sim.truth().vehicles[0].mode != "rtl":
                await sim.wait_until(sim.time_s + 0.5)
        sim.set_link(0, True)
        left = await next_event(events, LeftOffboard, 5.0)
        assert isinstance(left, LeftOffboard)
        assert left.flight_mode == "RTL"


@pytest.mark.slow
async def test_arduplane_4_7_gets_its_gcs_id_under_the_new_name():
    # SYSID_MYGCS goes unanswered (MAVSDK times out on it); MAV_GCS_SYSID is set instead
    config = sim_config(
        1, speedup=SPEEDUP, autopilot="arduplane", gcs_sysid_param="MAV_GCS_SYSID", takeoff="launch"
    )
    async with (
        asyncio.timeout(30.0),
        running_sim(config) as sim,
        MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
        hub.link(1, LinkConfig(LIMITS)) as link,
    ):
        vehicle = sim.vehicles[0]
        autopilot = arduplane_of(vehicle)
        await link.wait_ready(20.0)
        assert autopilot.params["MAV_GCS_SYSID"] == MAVSDK_GCS_ID
        assert autopilot.is_gcs(MAVSDK_GCS_ID)
        assert (autopilot.params["FS_GCS_ENABL"], autopilot.params["FS_LONG_ACTN"]) == (1, 1)


async def test_failsafe_parameters_already_right_are_not_written():
    config = sim_config(
        1, speedup=SPEEDUP, autopilot="arduplane", gcs_failsafe="return", gcs_system_id=245
    )
    async with (
        asyncio.timeout(20.0),
        running_sim(config) as sim,
        MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
        hub.link(1, LinkConfig(LIMITS)) as link,
    ):
        vehicle = sim.vehicles[0]
        autopilot = arduplane_of(vehicle)
        before = dict(autopilot.params)
        autopilot.param_write_denied = frozenset(before)  # any write would fail prepare()
        await link.wait_ready(10.0)
        assert autopilot.params == before


async def test_refused_failsafe_parameter_write_refuses_the_vehicle_before_take_off():
    config = sim_config(1, speedup=SPEEDUP, autopilot="arduplane", takeoff="launch")
    async with (
        asyncio.timeout(20.0),
        running_sim(config) as sim,
        MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
        hub.link(1, LinkConfig(LIMITS)) as link,
    ):
        vehicle = sim.vehicles[0]
        autopilot = arduplane_of(vehicle)
        autopilot.param_write_denied = frozenset({"FS_GCS_ENABL"})
        # ArduPlane answers "Param write denied" with the old value; MAVSDK resends, then gives up
        with pytest.raises(LinkError, match="cannot set FS_GCS_ENABL from 0 to 1: TIMEOUT"):
            await link.wait_ready(10.0)
        assert autopilot.params["FS_GCS_ENABL"] == 0
        assert not vehicle.armed
