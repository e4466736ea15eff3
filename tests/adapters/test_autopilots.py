"""Autopilot adapters and the setpoint limiter: the exact messages each adapter produces,
checked against recorders of MAVSDK's Offboard / MavlinkDirect / Param plugins."""

import json
import math
from dataclasses import replace
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st
from mavsdk.autopilot import Autopilot
from mavsdk.plugins.mavlink_direct import MavlinkDirectError, MavlinkDirectResult, MavlinkMessage
from mavsdk.plugins.offboard import OffboardError, OffboardResult
from mavsdk.plugins.param import ParamError, ParamResult
from mavsdk.vehicle import Vehicle
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega

from app.adapters.vehicle.autopilots.arduplane import ArduPlaneAdapter, arduplane_mode_name
from app.adapters.vehicle.autopilots.base import (
    VehicleState,
    choose_autopilot,
    command_long,
    course_deg_0_360,
)
from app.adapters.vehicle.autopilots.limits import SentSetpoint, SetpointLimits, limit_setpoint
from app.adapters.vehicle.autopilots.px4 import Px4FixedWingAdapter, px4_mode_name
from app.adapters.vehicle.autopilots.velocity import VelocityAdapter
from app.core.frames import wrap_pi
from app.core.plant import VehicleEnvelope
from app.errors import LinkError
from app.runtime.ports.vehicle import CourseSpeedCommand, UnsupportedVehicleError

LIMITS = SetpointLimits(VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.2))
STATE = VehicleState(t_s=12.0, course_rad=0.0, relative_altitude_m=100.0)


class OffboardRecorder:
    def __init__(self, refuse: OffboardResult | None = None) -> None:
        self.calls: list[tuple[Any, ...]] = []
        self.refuse = refuse

    async def set_velocity_ned(self, velocity_ned_yaw: Any) -> None:
        self.calls.append(("velocity", velocity_ned_yaw))

    async def set_position_velocity_ned(self, position_ned_yaw: Any, velocity_ned_yaw: Any) -> None:
        self.calls.append(("position+velocity", position_ned_yaw, velocity_ned_yaw))

    async def set_position_velocity_acceleration_ned(
        self, position_ned_yaw: Any, velocity_ned_yaw: Any, acceleration_ned: Any
    ) -> None:
        self.calls.append(
            ("position+velocity+acceleration", position_ned_yaw, velocity_ned_yaw, acceleration_ned)
        )

    async def start(self) -> None:
        if self.refuse is not None:
            raise OffboardError(self.refuse, "start()")
        self.calls.append(("start",))

    async def stop(self) -> None:
        self.calls.append(("stop",))


class CommandRecorder:
    """MavlinkDirect.send_command: records (message name, target ids, fields), acks ``result``."""

    def __init__(self, result: int = 0, error: MavlinkDirectResult | None = None) -> None:
        self.sent: list[tuple[str, int, int, dict[str, Any]]] = []
        self.result = result
        self.error = error

    async def send_command(self, command: MavlinkMessage) -> MavlinkMessage:
        fields = json.loads(command.fields_json)
        self.sent.append(
            (command.message_name, command.target_system_id, command.target_component_id, fields)
        )
        if self.error is not None:
            raise MavlinkDirectError(self.error, "send_command()", command)
        ack = {"command": fields["command"], "result": self.result}
        return MavlinkMessage(message_name="COMMAND_ACK", fields_json=json.dumps(ack))


class ParamRecorder:
    """Param plugin: ``fail`` refuses every read, ``refuse`` the writes of those names;
    ``sets`` records every write (int or float) in order."""

    def __init__(
        self,
        values: dict[str, int | float],
        fail: ParamResult | None = None,
        refuse: dict[str, ParamResult] | None = None,
    ) -> None:
        self.values: dict[str, int | float] = dict(values)
        self.sets: list[tuple[str, int | float]] = []
        self.fail = fail
        self.refuse = refuse or {}

    async def get_param_int(self, name: str) -> int:
        if self.fail is not None:
            raise ParamError(self.fail, "get_param_int()", name)
        if name not in self.values:  # ArduPilot does not answer for a name it does not have
            raise ParamError(ParamResult.TIMEOUT, "get_param_int()", name)
        value = self.values[name]
        if isinstance(value, float):  # stored as a float: MAVSDK will not read it as an int
            raise ParamError(ParamResult.WRONG_TYPE, "get_param_int()", name)
        return value

    async def get_param_float(self, name: str) -> float:
        if self.fail is not None:
            raise ParamError(self.fail, "get_param_float()", name)
        value = self.values.get(name)
        if not isinstance(value, float):
            result = ParamResult.TIMEOUT if value is None else ParamResult.WRONG_TYPE
            raise ParamError(result, "get_param_float()", name)
        return value

    async def set_param_int(self, name: str, value: int) -> None:
        self.sets.append((name, value))
        if name in self.refuse:
            raise ParamError(self.refuse[name], "set_param_int()", name, value)
        self.values[name] = value

    async def set_param_float(self, name: str, value: float) -> None:
        self.sets.append((name, value))
        if name in self.refuse:
            raise ParamError(self.refuse[name], "set_param_float()", name, value)
        self.values[name] = value


class NoSleep:
    """``sleep`` for adapters that wait: records how long, takes no time."""

    def __init__(self) -> None:
        self.waits: list[float] = []

    async def __call__(self, seconds: float) -> None:
        self.waits.append(seconds)


def params_of(fields: dict[str, Any]) -> list[float]:
    return [fields[f"param{i}"] for i in range(1, 8) if f"param{i}" in fields]


# ---- values ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("course", "speed", "altitude"),
    [(math.nan, 12.0, None), (0.0, math.inf, None), (0.0, -1.0, None), (0.0, 12.0, math.nan)],
)
def test_command_rejects_non_finite_or_negative_values(course, speed, altitude):
    with pytest.raises(ValueError, match="must be"):
        CourseSpeedCommand(course, speed, altitude)


def test_limits_reject_inverted_speeds():
    # the speeds are the envelope's, which refuses them when built
    with pytest.raises(ValueError, match="min_speed_m_s <= cruise_speed_m_s <= max_speed_m_s"):
        SetpointLimits(VehicleEnvelope(19.0, 20.0, 18.0, 2.0, 0.2))


def test_limits_reject_a_setpoint_only_limit_that_is_not_positive():
    with pytest.raises(ValueError, match="max_climb_rate_m_s must be finite and > 0"):
        SetpointLimits(LIMITS.envelope, max_climb_rate_m_s=0.0)
    with pytest.raises(ValueError, match="altitude_gain_per_s must be finite and > 0"):
        SetpointLimits(LIMITS.envelope, altitude_gain_per_s=math.nan)


# ---- limiter ---------------------------------------------------------------------------------


def test_speed_is_clamped_into_the_limits_with_a_reason():
    low, why_low = limit_setpoint(CourseSpeedCommand(0.0, 3.0), 1.0, None, LIMITS)
    high, why_high = limit_setpoint(CourseSpeedCommand(0.0, 30.0), 1.0, None, LIMITS)
    assert (low.speed_m_s, high.speed_m_s) == (10.0, 18.0)
    assert [r.kind for r in why_low] == ["speed_below_min"]
    assert [r.kind for r in why_high] == ["speed_above_max"]
    assert "3.000 m/s below 10.0 m/s" in str(why_low[0])


def test_a_setpoint_within_limits_passes_unchanged():
    previous = SentSetpoint(t_s=1.0, course_rad=0.5, speed_m_s=14.0)
    out, why = limit_setpoint(CourseSpeedCommand(0.55, 14.0, 80.0), 1.5, previous, LIMITS)
    assert why == ()
    assert out == CourseSpeedCommand(0.55, 14.0, 80.0)


def test_course_turns_no_faster_than_the_rate_limit():
    previous = SentSetpoint(t_s=10.0, course_rad=0.0, speed_m_s=14.0)
    out, why = limit_setpoint(CourseSpeedCommand(1.0, 14.0), 10.5, previous, LIMITS)
    assert out.course_rad == pytest.approx(0.1)  # 0.2 rad/s * 0.5 s
    assert [r.kind for r in why] == ["course_rate"]
    left, _ = limit_setpoint(CourseSpeedCommand(-1.0, 14.0), 10.5, previous, LIMITS)
    assert left.course_rad == pytest.approx(-0.1)


def test_course_limit_takes_the_short_way_across_pi():
    previous = SentSetpoint(t_s=0.0, course_rad=3.1, speed_m_s=14.0)
    # -3.1 is only 0.083 rad away from 3.1, through pi: allowed in 1 s
    out, why = limit_setpoint(CourseSpeedCommand(-3.1, 14.0), 1.0, previous, LIMITS)
    assert why == ()
    assert out.course_rad == pytest.approx(-3.1)
    # half a turn away: moves 0.2 rad the short way (through pi, increasing)
    out, _ = limit_setpoint(CourseSpeedCommand(3.1 - math.pi + 0.5, 14.0), 1.0, previous, LIMITS)
    assert out.course_rad == pytest.approx(wrap_pi(3.1 - 0.2))


def test_time_running_backwards_allows_no_course_change():
    previous = SentSetpoint(t_s=5.0, course_rad=0.3, speed_m_s=14.0)
    out, why = limit_setpoint(CourseSpeedCommand(0.5, 14.0), 4.0, previous, LIMITS)
    assert out.course_rad == pytest.approx(0.3)
    assert why


def test_no_course_rate_limit_leaves_course_free():
    free = SetpointLimits(VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.2), limit_course_change=False)
    previous = SentSetpoint(t_s=0.0, course_rad=0.0, speed_m_s=14.0)
    out, why = limit_setpoint(CourseSpeedCommand(2.0, 14.0), 0.0, previous, free)
    assert (out.course_rad, why) == (2.0, ())


@given(
    course=st.floats(-20.0, 20.0),
    speed=st.floats(0.0, 100.0),
    previous_course=st.floats(-math.pi, math.pi),
    dt=st.floats(-1.0, 5.0),
)
def test_limited_setpoints_are_always_within_the_envelope(course, speed, previous_course, dt):
    previous = SentSetpoint(t_s=10.0, course_rad=previous_course, speed_m_s=14.0)
    out, _ = limit_setpoint(CourseSpeedCommand(course, speed), 10.0 + dt, previous, LIMITS)
    assert math.isfinite(out.course_rad)
    assert -math.pi <= out.course_rad < math.pi
    assert LIMITS.envelope.min_speed_m_s <= out.speed_m_s <= LIMITS.envelope.max_speed_m_s
    turned = abs(wrap_pi(out.course_rad - previous_course))
    assert turned <= 0.2 * max(dt, 0.0) + 1e-6


# ---- mode names and adapter choice -----------------------------------------------------------


def test_px4_and_arduplane_mode_names():
    assert px4_mode_name(6 << 16) == "OFFBOARD"
    assert px4_mode_name((4 << 16) | (3 << 24)) == "HOLD"
    assert px4_mode_name((4 << 16) | (5 << 24)) == "RETURN_TO_LAUNCH"
    assert px4_mode_name(99 << 16).startswith("UNKNOWN")
    assert arduplane_mode_name(15) == "GUIDED"
    assert arduplane_mode_name(12) == "LOITER"


def test_the_mode_tables_know_every_mode_pymavlinks_dialects_name():
    # ArduPlane: every PLANE_MODE of the ardupilotmega dialect, INITIALISING and AUTOLAND too
    # (a hand-typed table once lacked them: a vehicle booting or landing read as UNKNOWN)
    plane = {
        name: getattr(ardupilotmega, name)
        for name in dir(ardupilotmega)
        if name.startswith("PLANE_MODE_") and name != "PLANE_MODE_ENUM_END"
    }
    assert len(plane) >= 26
    assert all(not arduplane_mode_name(n).startswith("UNKNOWN") for n in plane.values())
    assert arduplane_mode_name(ardupilotmega.PLANE_MODE_INITIALIZING) == "INITIALISING"
    assert arduplane_mode_name(ardupilotmega.PLANE_MODE_AUTOLAND) == "AUTOLAND"
    # PX4: every (main, sub) mode pymavlink maps
    for _base, main, sub in mavutil.px4_map.values():
        name = px4_mode_name((main << 16) | (sub << 24))
        assert not name.startswith(("UNKNOWN", "AUTO_")), (main, sub, name)


@pytest.mark.parametrize(
    ("autopilot", "vehicle", "expected"),
    [
        (Autopilot.PX4, Vehicle.FIXED_WING, "px4-fixed-wing"),
        (Autopilot.PX4, Vehicle.MULTICOPTER, "velocity"),
        (Autopilot.ARDUPILOT, Vehicle.FIXED_WING, "arduplane"),
        (Autopilot.GENERIC, Vehicle.FIXED_WING, "velocity"),
    ],
)
def test_adapter_is_chosen_from_what_the_vehicle_reports(autopilot, vehicle, expected):
    assert choose_autopilot(autopilot, vehicle, None, 1) == expected


def test_configured_adapter_wins_over_the_report():
    assert choose_autopilot(Autopilot.PX4, Vehicle.FIXED_WING, "velocity", 1) == "velocity"


@pytest.mark.parametrize(
    ("autopilot", "vehicle"),
    [
        (Autopilot.ARDUPILOT, Vehicle.MULTICOPTER),
        (Autopilot.UNKNOWN, Vehicle.FIXED_WING),
        (Autopilot.PX4, Vehicle.SUBMARINE),
    ],
)
def test_a_vehicle_without_a_supported_form_is_refused_clearly(autopilot, vehicle):
    with pytest.raises(UnsupportedVehicleError) as info:
        choose_autopilot(autopilot, vehicle, None, 3)
    message = str(info.value)
    assert "vehicle 3" in message
    assert autopilot.name in message
    assert vehicle.name in message
    assert "before take-off" in message
    assert isinstance(info.value, LinkError)


def test_unknown_configured_adapter_is_refused():
    with pytest.raises(UnsupportedVehicleError, match="unknown autopilot adapter 'dji'"):
        choose_autopilot(Autopilot.PX4, Vehicle.FIXED_WING, "dji", 1)  # type: ignore[arg-type]


def test_course_in_degrees_wraps_into_0_360():
    assert course_deg_0_360(-math.pi / 2) == pytest.approx(270.0)
    assert course_deg_0_360(2 * math.pi) == 0.0
    assert 0.0 <= course_deg_0_360(-1e-18) < 360.0


def test_non_finite_command_parameter_is_never_built():
    with pytest.raises(LinkError, match="non-finite"):
        command_long(1, 1, 178, (0.0, math.nan))


# ---- velocity --------------------------------------------------------------------------------


async def test_velocity_adapter_sends_course_as_velocity_and_yaw_then_starts():
    offboard = OffboardRecorder()
    adapter = VelocityAdapter(vehicle_id=2, offboard=offboard, limits=LIMITS)
    await adapter.start(CourseSpeedCommand(math.pi / 2, 15.0), 100.0, STATE)
    (kind, velocity), start = offboard.calls
    assert (kind, start) == ("velocity", ("start",))
    assert velocity.north_m_s == pytest.approx(0.0, abs=1e-12)
    assert velocity.east_m_s == pytest.approx(15.0)
    assert velocity.down_m_s == 0.0
    assert velocity.yaw_deg == pytest.approx(90.0)
    await adapter.stop()
    assert offboard.calls[-1] == ("stop",)


async def test_velocity_adapter_climbs_towards_the_altitude_saturated():
    offboard = OffboardRecorder()
    adapter = VelocityAdapter(vehicle_id=2, offboard=offboard, limits=LIMITS)
    await adapter.send(CourseSpeedCommand(math.pi, 12.0), 102.0, STATE)  # 2 m low
    await adapter.send(CourseSpeedCommand(math.pi, 12.0), 40.0, STATE)  # 60 m high
    (_, climb), (_, descend) = offboard.calls
    assert climb.down_m_s == pytest.approx(-1.0)  # 0.5 /s * 2 m, up
    assert descend.down_m_s == pytest.approx(3.0)  # saturated at 3 m/s
    assert climb.north_m_s == pytest.approx(-12.0)
    assert climb.yaw_deg == pytest.approx(-180.0)


async def test_refused_offboard_start_is_a_link_error_with_the_result():
    adapter = VelocityAdapter(
        vehicle_id=4, offboard=OffboardRecorder(OffboardResult.COMMAND_DENIED), limits=LIMITS
    )
    with pytest.raises(
        LinkError, match="vehicle 4: offboard start refused: COMMAND_DENIED"
    ) as info:
        await adapter.start(CourseSpeedCommand(0.0, 14.0), 100.0, STATE)
    assert isinstance(info.value.__cause__, OffboardError)


# ---- PX4 fixed-wing ----------------------------------------------------------------------------


# PX4's defaults (FW_AIRSPD_MIN / _MAX are floats)
STOCK_PX4: dict[str, int | float] = {
    "COM_OBL_RC_ACT": 0,
    "FW_AIRSPD_MIN": 10.0,
    "FW_AIRSPD_MAX": 20.0,
}


def px4(
    commands: CommandRecorder | None = None,
    params: ParamRecorder | None = None,
    offboard_loss_action: int | None = 5,
) -> tuple[Px4FixedWingAdapter, OffboardRecorder, CommandRecorder, ParamRecorder]:
    offboard = OffboardRecorder()
    commands = commands or CommandRecorder()
    params = params or ParamRecorder(STOCK_PX4)
    adapter = Px4FixedWingAdapter(
        vehicle_id=3,
        offboard=offboard,
        commands=commands,
        params=params,
        limits=LIMITS,
        offboard_loss_action=offboard_loss_action,
    )
    return adapter, offboard, commands, params


PX4_STATE = VehicleState(
    t_s=3.0, course_rad=0.0, relative_altitude_m=100.0, local_ned_m=(100.0, 50.0, -80.0)
)


async def test_px4_sends_a_point_ahead_on_the_course_with_the_course_as_velocity():
    adapter, offboard, commands, _ = px4()
    await adapter.start(CourseSpeedCommand(math.pi / 2, 15.0), 110.0, PX4_STATE)
    (kind, position, velocity, acceleration), start = offboard.calls
    assert (kind, start) == ("position+velocity+acceleration", ("start",))
    # a straight course: no curvature to feed forward
    assert (acceleration.north_m_s2, acceleration.east_m_s2, acceleration.down_m_s2) == (
        pytest.approx(0.0, abs=1e-12),
        pytest.approx(0.0, abs=1e-12),
        0.0,
    )
    # 15 m/s * 4 s = 60 m ahead, due east of the vehicle's local position
    assert position.north_m == pytest.approx(100.0)
    assert position.east_m == pytest.approx(110.0)
    assert position.down_m == pytest.approx(-90.0)  # 10 m higher than now
    assert position.yaw_deg == pytest.approx(90.0)
    assert (velocity.north_m_s, velocity.east_m_s) == (pytest.approx(0.0, abs=1e-12), 15.0)
    assert velocity.down_m_s == 0.0
    # airspeed by MAV_CMD_DO_CHANGE_SPEED, exact fields
    ((name, target_system, target_component, fields),) = commands.sent
    assert (name, target_system, target_component) == ("COMMAND_LONG", 3, 1)
    assert fields["command"] == 178
    assert (fields["target_system"], fields["target_component"]) == (3, 1)
    assert params_of(fields) == [0.0, 15.0, -1.0, 0.0, 0.0, 0.0, 0.0]


async def test_px4_lookahead_has_a_floor():
    adapter, offboard, _, _ = px4()
    await adapter.send(CourseSpeedCommand(0.0, 5.0), 100.0, PX4_STATE)
    _, position, _, _ = offboard.calls[0]
    assert position.north_m == pytest.approx(140.0)  # 40 m floor, not 5 * 4 = 20 m


async def test_px4_sends_the_airspeed_once_per_start_as_v1_16_ignores_it_in_offboard():
    adapter, _, commands, _ = px4()
    assert adapter.honours_speed is False
    await adapter.start(CourseSpeedCommand(0.0, 15.0), 100.0, PX4_STATE)
    for speed in (15.05, 16.0, 12.0, 17.5):
        await adapter.send(CourseSpeedCommand(0.0, speed), 100.0, PX4_STATE)
    assert [f["param2"] for *_, f in commands.sent] == [15.0]
    # taken back after a hand-over: once again, the new first speed
    await adapter.start(CourseSpeedCommand(0.0, 13.0), 100.0, PX4_STATE)
    await adapter.send(CourseSpeedCommand(0.0, 14.0), 100.0, PX4_STATE)
    assert [f["param2"] for *_, f in commands.sent] == [15.0, 13.0]


async def test_px4_refused_airspeed_is_a_link_error():
    adapter, _, _, _ = px4(commands=CommandRecorder(result=2))
    with pytest.raises(LinkError, match="DO_CHANGE_SPEED refused: MAV_RESULT_DENIED"):
        await adapter.send(CourseSpeedCommand(0.0, 15.0), 100.0, PX4_STATE)


async def test_px4_unanswered_command_is_a_link_error():
    adapter, _, _, _ = px4(commands=CommandRecorder(error=MavlinkDirectResult.TIMEOUT))
    with pytest.raises(LinkError, match="no answer \\(TIMEOUT\\)") as info:
        await adapter.send(CourseSpeedCommand(0.0, 15.0), 100.0, PX4_STATE)
    assert isinstance(info.value.__cause__, MavlinkDirectError)


async def test_px4_without_local_position_refuses_to_guess():
    adapter, offboard, _, _ = px4()
    with pytest.raises(LinkError, match="LOCAL_POSITION_NED"):
        await adapter.send(CourseSpeedCommand(0.0, 15.0), 100.0, STATE)
    assert offboard.calls == []


async def test_px4_sets_the_offboard_loss_action_to_hold():
    adapter, _, _, params = px4()
    await adapter.prepare()
    assert params.sets == [("COM_OBL_RC_ACT", 5)]


async def test_px4_leaves_a_correct_offboard_loss_action_alone():
    adapter, _, _, params = px4(params=ParamRecorder(STOCK_PX4 | {"COM_OBL_RC_ACT": 5}))
    await adapter.prepare()
    assert params.sets == []


async def test_px4_whose_airspeed_range_misses_the_missions_speeds_is_refused():
    params = ParamRecorder(STOCK_PX4 | {"FW_AIRSPD_MAX": 16.0})
    adapter, _, _, _ = px4(params=params)
    with pytest.raises(
        LinkError,
        match=r"vehicle 3: the mission commands 10-18 m/s, but this PX4 flies airspeeds \(and "
        r"holds a setpoint within them\) of 10-16 m/s only \(FW_AIRSPD_MIN, FW_AIRSPD_MAX\)",
    ):
        await adapter.prepare()
    assert params.sets == []  # refused before anything was changed


async def test_px4_offboard_loss_action_unset_means_not_touched():
    adapter, _, _, params = px4(params=ParamRecorder({}), offboard_loss_action=None)
    await adapter.prepare()
    assert params.sets == []


async def test_px4_parameter_failure_is_a_link_error():
    adapter, _, _, _ = px4(params=ParamRecorder({}, fail=ParamResult.TIMEOUT))
    with pytest.raises(LinkError, match="COM_OBL_RC_ACT: TIMEOUT"):
        await adapter.prepare()


# ---- ArduPlane -------------------------------------------------------------------------------

# ArduPlane's defaults (the airspeed range: 9-22 m/s, AP_Int16)
STOCK_ARDUPLANE: dict[str, int | float] = {
    "SYSID_MYGCS": 255,
    "FS_GCS_ENABL": 0,
    "FS_LONG_ACTN": 0,
    "AIRSPEED_MIN": 9,
    "AIRSPEED_MAX": 22,
    "GUIDED_P": 5000.0,  # AC_PID, a float
}


def arduplane(
    commands: CommandRecorder | None = None,
    params: ParamRecorder | None = None,
    limits: SetpointLimits = LIMITS,
    gcs_system_id: int | None = 245,
    sleep: NoSleep | None = None,
) -> ArduPlaneAdapter:
    return ArduPlaneAdapter(
        vehicle_id=5,
        commands=commands or CommandRecorder(),
        params=params or ParamRecorder(STOCK_ARDUPLANE),
        limits=limits,
        gcs_system_id=gcs_system_id,
        sleep=sleep or NoSleep(),
    )


async def test_arduplane_makes_a_stock_gcs_failsafe_return_it_and_says_so(caplog):
    params = ParamRecorder(STOCK_ARDUPLANE)
    with caplog.at_level("WARNING"):
        await arduplane(params=params).prepare()
    # the failsafe is enabled last, once it will return the aircraft (see test_autopilot_gcs.py)
    assert params.sets == [("SYSID_MYGCS", 245), ("FS_LONG_ACTN", 1), ("FS_GCS_ENABL", 1)]
    assert params.values == STOCK_ARDUPLANE | {
        "SYSID_MYGCS": 245,
        "FS_GCS_ENABL": 1,
        "FS_LONG_ACTN": 1,
    }
    changes = [r.getMessage() for r in caplog.records]
    assert changes[0].startswith("vehicle 5: set SYSID_MYGCS from 255 to 245 so that")
    assert changes[1].startswith("vehicle 5: set FS_LONG_ACTN from 0 to 1 so that")
    assert changes[2].startswith("vehicle 5: set FS_GCS_ENABL from 0 to 1 so that")
    assert all(change.endswith("(restored at the end)") for change in changes)


async def test_arduplane_leaves_a_failsafe_that_already_returns_it_alone():
    # FS_GCS_ENABL 2 (heartbeat and REMRSSI) and FS_LONG_ACTN 2 (glide) are operators' choices
    params = ParamRecorder({"SYSID_MYGCS": 245, "FS_GCS_ENABL": 2, "FS_LONG_ACTN": 2})
    await arduplane(params=params).prepare()
    assert params.sets == []


async def test_arduplane_failsafe_in_auto_only_does_not_protect_guided():
    params = ParamRecorder({"SYSID_MYGCS": 245, "FS_GCS_ENABL": 3, "FS_LONG_ACTN": 1})
    await arduplane(params=params).prepare()
    assert params.sets == [("FS_GCS_ENABL", 1)]


async def test_arduplane_gcs_system_id_is_the_one_given():
    params = ParamRecorder(STOCK_ARDUPLANE)
    await arduplane(params=params, gcs_system_id=17).prepare()
    assert params.sets[0] == ("SYSID_MYGCS", 17)


async def test_arduplane_refused_parameter_write_is_a_link_error_naming_it():
    params = ParamRecorder(STOCK_ARDUPLANE, refuse={"FS_GCS_ENABL": ParamResult.TIMEOUT})
    with pytest.raises(LinkError, match="vehicle 5: cannot set FS_GCS_ENABL from 0 to 1: TIMEOUT"):
        await arduplane(params=params).prepare()
    assert params.sets == [("SYSID_MYGCS", 245), ("FS_LONG_ACTN", 1), ("FS_GCS_ENABL", 1)]


async def test_arduplane_unreadable_parameter_is_a_link_error_naming_it():
    params = ParamRecorder({}, fail=ParamResult.WRONG_TYPE)
    with pytest.raises(
        LinkError,
        match=r"vehicle 5: cannot read SYSID_MYGCS \(WRONG_TYPE\) or MAV_GCS_SYSID \(WRONG_TYPE\)",
    ):
        await arduplane(params=params).prepare()
    # the failsafe parameters are named as they are
    no_fs = ParamRecorder({"SYSID_MYGCS": 245})
    with pytest.raises(LinkError, match="vehicle 5: cannot read FS_LONG_ACTN: TIMEOUT"):
        await arduplane(params=no_fs).prepare()
    no_enable = ParamRecorder({"SYSID_MYGCS": 245, "FS_LONG_ACTN": 1})
    with pytest.raises(LinkError, match="vehicle 5: cannot read FS_GCS_ENABL: TIMEOUT"):
        await arduplane(params=no_enable).prepare()


async def test_arduplane_4_7_has_its_gcs_id_set_under_the_new_name():
    # ArduPilot 4.7 renamed SYSID_MYGCS to MAV_GCS_SYSID (and added MAV_GCS_SYSID_HI)
    params = ParamRecorder(
        {"MAV_GCS_SYSID": 255, "MAV_GCS_SYSID_HI": 0, "FS_GCS_ENABL": 0, "FS_LONG_ACTN": 0}
    )
    await arduplane(params=params).prepare()
    assert params.sets == [("MAV_GCS_SYSID", 245), ("FS_LONG_ACTN", 1), ("FS_GCS_ENABL", 1)]


@pytest.mark.parametrize(
    ("low", "high", "changed"),
    [(240, 250, False), (245, 0, False), (200, 240, True), (250, 0, True), (255, 250, True)],
)
async def test_arduplane_4_7_keeps_a_gcs_id_range_that_holds_ours(low, high, changed):
    values = {"MAV_GCS_SYSID": low, "MAV_GCS_SYSID_HI": high, "FS_GCS_ENABL": 1, "FS_LONG_ACTN": 1}
    params = ParamRecorder(values)
    await arduplane(params=params).prepare()
    assert params.sets == ([("MAV_GCS_SYSID", 245)] if changed else [])


async def test_arduplane_without_gcs_system_id_touches_no_parameter(caplog):
    params = ParamRecorder({}, fail=ParamResult.TIMEOUT)  # any read would raise
    with caplog.at_level("WARNING"):
        await arduplane(params=params, gcs_system_id=None).prepare()
    assert params.sets == []
    assert "left unchecked" in caplog.text


async def test_arduplane_switches_to_guided_then_sends_heading_speed_altitude():
    commands = CommandRecorder()
    adapter = arduplane(commands, limits=LIMITS)
    await adapter.start(CourseSpeedCommand(-math.pi / 2, 15.0), 120.0, STATE)
    mode, heading, speed, altitude = commands.sent
    assert mode[:3] == ("COMMAND_LONG", 5, 1)
    assert mode[3]["command"] == 176
    assert params_of(mode[3]) == [1.0, 15.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    assert heading[:3] == ("COMMAND_INT", 5, 1)
    assert heading[3]["command"] == 43002
    assert heading[3]["param1"] == 0.0  # course over ground
    assert heading[3]["param2"] == pytest.approx(270.0)
    assert heading[3]["param3"] == pytest.approx(3.0)  # 15 m/s * 0.2 rad/s
    assert speed[3]["command"] == 43000
    # param3: ArduPlane slews its target at the envelope's 2 m/s^2 (the speed is not led)
    assert (speed[3]["param1"], speed[3]["param2"], speed[3]["param3"]) == (0.0, 15.0, 2.0)
    assert altitude[3]["command"] == 43001
    assert altitude[3]["frame"] == 3  # MAV_FRAME_GLOBAL_RELATIVE_ALT
    assert altitude[3]["z"] == 120.0
    # 0: TECS's own climb rate (4.6's slew at 3 m/s left TECS 0.3 m of error: no climb)
    assert altitude[3]["param3"] == 0.0


async def test_arduplane_sends_only_what_changed():
    commands = CommandRecorder()
    adapter = arduplane(commands, limits=LIMITS)
    await adapter.send(CourseSpeedCommand(0.0, 15.0), 100.0, STATE)
    await adapter.send(CourseSpeedCommand(math.radians(0.2), 15.05, None), 100.2, STATE)
    assert len(commands.sent) == 3
    await adapter.send(CourseSpeedCommand(math.radians(5.0), 15.05), 100.2, STATE)
    assert [f["command"] for *_, f in commands.sent[3:]] == [43002]
    assert commands.sent[3][3]["param2"] == pytest.approx(5.0)


async def test_arduplane_refusal_names_the_command_and_result():
    adapter = arduplane(CommandRecorder(result=4), limits=LIMITS)
    with pytest.raises(
        LinkError, match="vehicle 5: mode change to GUIDED refused: MAV_RESULT_FAILED"
    ):
        await adapter.start(CourseSpeedCommand(0.0, 15.0), 100.0, STATE)


async def test_arduplane_stop_loiters():
    commands = CommandRecorder()
    adapter = arduplane(commands, limits=LIMITS)
    await adapter.stop()
    ((_, _, _, fields),) = commands.sent
    assert (fields["command"], fields["param1"], fields["param2"]) == (176, 1.0, 12.0)


@pytest.mark.parametrize("limit_course_change", [True, False])
async def test_arduplane_heading_limits_the_turn_to_the_envelopes_rate(limit_course_change):
    # param3 is the lateral acceleration ArduPlane may use (bank <= atan(param3 / g)): the
    # envelope's course rate at the commanded speed, a = v * W, whether or not the setpoints'
    # course change is limited (the mission files turn that off); not 1000 (no limit)
    commands = CommandRecorder()
    limits = SetpointLimits(
        VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.2), limit_course_change=limit_course_change
    )
    adapter = arduplane(commands, limits=limits)
    await adapter.send(CourseSpeedCommand(0.0, 15.0), 100.0, STATE)
    await adapter.send(CourseSpeedCommand(1.0, 12.0), 100.0, STATE)
    first, second = (f for *_, f in commands.sent if f["command"] == 43002)
    assert first["param3"] == pytest.approx(15.0 * 0.2)
    assert second["param3"] == pytest.approx(12.0 * 0.2)
    # the coordinated turn at that bank is the envelope's rate: g tan(bank) / v = W
    bank = math.atan(second["param3"] / 9.80665)
    assert 9.80665 * math.tan(bank) / 12.0 == pytest.approx(0.2)


async def test_arduplane_sizes_the_turn_limit_on_the_speed_flown_when_it_is_faster():
    # still 18 m/s while slowing to a commanded 10: sized on 10 m/s the bank limit would hold
    # the turn to 0.2 * 10 / 18 = 0.11 rad/s; sized on 18 it is the envelope's 0.2 rad/s
    commands = CommandRecorder()
    adapter = arduplane(commands, limits=LIMITS)
    fast = VehicleState(t_s=12.0, course_rad=0.0, relative_altitude_m=100.0, flying_speed_m_s=18.0)
    await adapter.send(CourseSpeedCommand(0.0, 10.0), 100.0, fast)
    # the same course, the aircraft now at 16 m/s: the limit moved by 11 %, sent again
    slower = replace(fast, flying_speed_m_s=16.0)
    await adapter.send(CourseSpeedCommand(0.0, 10.0), 100.0, slower)
    # 15.5 m/s: 3 % from the last sent, not sent
    await adapter.send(CourseSpeedCommand(0.0, 10.0), 100.0, replace(fast, flying_speed_m_s=15.5))
    # slower than commanded, or unknown, or not finite: the commanded speed
    for flying in (8.0, None, math.nan):
        await adapter.send(
            CourseSpeedCommand(0.0, 10.0), 100.0, replace(fast, flying_speed_m_s=flying)
        )
    sent = [f["param3"] for *_, f in commands.sent if f["command"] == 43002]
    assert sent == [pytest.approx(3.6), pytest.approx(3.2), pytest.approx(2.0)]


async def test_arduplane_linearises_the_heading_command_to_the_assumed_course_loop():
    """GUIDED banks GUIDED_P x error and turns at g tan(bank) / V; the course sent makes that
    k e (k = 1 /s, the envelope's) at the speed flown, so the loop's gain no longer halves
    from 10 to 20 m/s."""
    commands = CommandRecorder()
    adapter = arduplane(commands, limits=LIMITS)
    await adapter.prepare()
    p = math.radians(5000.0 / 100.0)  # rad of bank per rad of error
    for speed in (10.0, 14.0, 20.0):
        state = replace(STATE, course_rad=0.3, flying_speed_m_s=speed)
        error = 0.1  # wanted: a turn of k e = 0.1 rad/s
        sent = adapter.linearised_course(0.3 + error, state, 14.0)
        bank = p * (sent - 0.3)
        assert 9.80665 * math.tan(bank) / speed == pytest.approx(1.0 * error, rel=1e-9)
    # 14 m/s: 1.6 times the error asked; the course goes out as that, in degrees
    fourteen = replace(STATE, course_rad=0.0, flying_speed_m_s=14.0)
    await adapter.send(CourseSpeedCommand(0.1, 14.0), 100.0, fourteen)
    (heading,) = [f for *_, f in commands.sent if f["command"] == 43002]
    assert math.radians(heading["param2"]) == pytest.approx(
        math.atan(0.1 * 14.0 / 9.80665) / p, rel=1e-6
    )
    # across the wrap: a wanted left turn from 359 deg stays a left turn
    north = replace(STATE, course_rad=math.radians(359.0), flying_speed_m_s=14.0)
    left = adapter.linearised_course(math.radians(357.0), north, 14.0)
    assert -0.1 < wrap_pi(left - math.radians(359.0)) < math.radians(-2.0)


async def test_arduplane_re_sends_the_linearised_course_as_the_vehicle_turns_onto_it():
    # one wanted course, east; the vehicle turns from north onto it: the course sent moves
    # with it (ArduPlane holds the last one sent) and ends at the wanted course itself
    commands = CommandRecorder()
    adapter = arduplane(commands, limits=LIMITS)
    await adapter.prepare()
    for course in (0.0, 0.5, 1.0, 1.4, math.pi / 2):
        state = replace(STATE, course_rad=course, flying_speed_m_s=14.0)
        await adapter.send(CourseSpeedCommand(math.pi / 2, 14.0), 100.0, state)
    sent = [math.radians(f["param2"]) for *_, f in commands.sent if f["command"] == 43002]
    assert len(sent) == 5
    assert sent[-1] == pytest.approx(math.pi / 2)


async def test_arduplane_without_guided_p_sends_the_course_as_wanted(caplog):
    params = ParamRecorder({k: v for k, v in STOCK_ARDUPLANE.items() if k != "GUIDED_P"})
    adapter = arduplane(params=params)
    with caplog.at_level("WARNING"):
        await adapter.prepare()
    assert "GUIDED_P unreadable: heading commands sent as the course wanted" in caplog.text
    state = replace(STATE, flying_speed_m_s=14.0)
    assert adapter.linearised_course(0.1, state, 14.0) == 0.1


async def test_arduplane_takes_off_in_takeoff_mode():
    commands = CommandRecorder()
    adapter = arduplane(commands, limits=LIMITS)
    await adapter.take_off()
    ((name, _, _, fields),) = commands.sent
    assert (name, fields["command"], fields["param1"], fields["param2"]) == (
        "COMMAND_LONG",
        176,
        1.0,
        13.0,
    )


@pytest.mark.parametrize(
    "airspeeds",
    [
        {"AIRSPEED_MIN": 9, "AIRSPEED_MAX": 22},
        {"AIRSPEED_MIN": 9.0, "AIRSPEED_MAX": 22.0},  # a build that stores them as floats
        {"ARSPD_FBW_MIN": 9, "ARSPD_FBW_MAX": 22},  # their names before ArduPilot 4.5
    ],
)
async def test_arduplane_takes_a_mission_within_its_airspeed_range(airspeeds):
    params = ParamRecorder({"SYSID_MYGCS": 245, "FS_GCS_ENABL": 1, "FS_LONG_ACTN": 1} | airspeeds)
    await arduplane(params=params).prepare()  # 10-18 m/s within 9-22
    assert params.sets == []


async def test_arduplane_whose_airspeed_range_misses_the_missions_speeds_is_refused():
    values = STOCK_ARDUPLANE | {"AIRSPEED_MIN": 12}
    params = ParamRecorder(values)
    with pytest.raises(
        LinkError,
        match=r"vehicle 5: the mission commands 10-18 m/s, but this ArduPlane takes airspeeds of "
        r"12-22 m/s only \(AIRSPEED_MIN, AIRSPEED_MAX\)",
    ):
        await arduplane(params=params).prepare()
    assert params.sets == []  # refused before anything was changed


async def test_arduplane_with_an_unreadable_airspeed_range_is_warned_about(caplog):
    values: dict[str, int | float] = {"SYSID_MYGCS": 245, "FS_GCS_ENABL": 1, "FS_LONG_ACTN": 1}
    with caplog.at_level("WARNING"):
        await arduplane(params=ParamRecorder(values)).prepare()
    assert "its speed range (AIRSPEED_MIN, AIRSPEED_MAX) cannot be read" in caplog.text
