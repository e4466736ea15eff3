"""Autopilot adapters: turn a (course, speed[, altitude]) command into what an autopilot accepts.

Three forms (design.md section 5):

- ``velocity``: velocity + yaw offboard setpoints (the built-in simulator, PX4 multicopters);
- ``px4-fixed-wing``: a point ahead on the course with the course as velocity
  (``set_position_velocity_ned``; PX4 fixed-wing ignores velocity-only setpoints) and the airspeed
  by MAV_CMD_DO_CHANGE_SPEED whenever it changes; COM_OBL_RC_ACT checked (and set if asked);
- ``arduplane``: GUIDED mode with MAV_CMD_GUIDED_CHANGE_HEADING / _SPEED / _ALTITUDE
  (ardupilotmega dialect) sent as COMMAND_INT through MavlinkDirect; SYSID_MYGCS, FS_GCS_ENABL
  and FS_LONG_ACTN checked and set so that ArduPlane's GCS failsafe returns it if we go silent.

Every setpoint passes ``limit_setpoint`` first (speed within limits, course changing no faster
than the course-rate limit) and every number that leaves is checked finite.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Final, Literal, Protocol

from mavsdk.autopilot import Autopilot
from mavsdk.plugins.mavlink_direct import MavlinkDirectError, MavlinkMessage
from mavsdk.plugins.offboard import OffboardError, PositionNedYaw, VelocityNedYaw
from mavsdk.plugins.param import ParamError, ParamResult
from mavsdk.vehicle import Vehicle

from app.adapters.vehicle.link import CourseSpeedCommand, UnsupportedVehicleError
from app.core.frames import wrap_pi
from app.errors import LinkError

log = logging.getLogger(__name__)

AutopilotName = Literal["velocity", "px4-fixed-wing", "arduplane"]
AUTOPILOT_NAMES: Final[tuple[AutopilotName, ...]] = ("velocity", "px4-fixed-wing", "arduplane")

# MAVLink numbers used here (common and ardupilotmega dialects).
MAV_CMD_DO_SET_MODE: Final = 176
MAV_CMD_DO_CHANGE_SPEED: Final = 178
MAV_CMD_GUIDED_CHANGE_SPEED: Final = 43000
MAV_CMD_GUIDED_CHANGE_ALTITUDE: Final = 43001
MAV_CMD_GUIDED_CHANGE_HEADING: Final = 43002
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED: Final = 1
MAV_MODE_FLAG_SAFETY_ARMED: Final = 128
MAV_FRAME_GLOBAL: Final = 0
MAV_FRAME_GLOBAL_RELATIVE_ALT: Final = 3
SPEED_TYPE_AIRSPEED: Final = 0
HEADING_TYPE_COURSE_OVER_GROUND: Final = 0
MAV_RESULT_ACCEPTED: Final = 0
MAV_RESULT_NAMES: Final = {
    0: "ACCEPTED",
    1: "TEMPORARILY_REJECTED",
    2: "DENIED",
    3: "UNSUPPORTED",
    4: "FAILED",
    5: "IN_PROGRESS",
    6: "CANCELLED",
}
ARDUPLANE_GUIDED: Final = 15
ARDUPLANE_LOITER: Final = 12
ARDUPLANE_TAKEOFF: Final = 13
#: GUIDED_CHANGE_HEADING param3 when the course rate is unlimited: ArduPlane takes at least
#: 0.05 m/s^2 (``MAX(param3, 0.05f)``, so 0 would barely turn) and banks no more than its own
#: roll limit, so a value this large leaves the turn to the airframe
UNLIMITED_LATERAL_ACCEL_M_S2: Final = 1000.0

PX4_MAIN_MODES: Final = {
    1: "MANUAL",
    2: "ALTCTL",
    3: "POSCTL",
    5: "ACRO",
    6: "OFFBOARD",
    7: "STABILIZED",
    8: "RATTITUDE",
    9: "TERMINATION",
}
PX4_AUTO_SUB_MODES: Final = {
    1: "READY",
    2: "TAKEOFF",
    3: "HOLD",
    4: "MISSION",
    5: "RETURN_TO_LAUNCH",
    6: "LAND",
    7: "RETURN_TO_GROUND_STATION",
    8: "FOLLOW_ME",
    9: "PRECISION_LAND",
    10: "VTOL_TAKEOFF",
}
ARDUPLANE_MODES: Final = {
    0: "MANUAL",
    1: "CIRCLE",
    2: "STABILIZE",
    3: "TRAINING",
    4: "ACRO",
    5: "FBWA",
    6: "FBWB",
    7: "CRUISE",
    8: "AUTOTUNE",
    10: "AUTO",
    11: "RTL",
    12: "LOITER",
    13: "TAKEOFF",
    14: "AVOID_ADSB",
    15: "GUIDED",
    17: "QSTABILIZE",
    18: "QHOVER",
    19: "QLOITER",
    20: "QLAND",
    21: "QRTL",
    22: "QAUTOTUNE",
    23: "QACRO",
    24: "THERMAL",
    25: "LOITER_ALT_QLAND",
}


def px4_mode_name(custom_mode: int) -> str:
    """PX4's flight mode name from HEARTBEAT.custom_mode (main mode in byte 2, sub in byte 3)."""
    main = (custom_mode >> 16) & 0xFF
    sub = (custom_mode >> 24) & 0xFF
    if main == 4:
        return PX4_AUTO_SUB_MODES.get(sub, f"AUTO_{sub}")
    return PX4_MAIN_MODES.get(main, f"UNKNOWN_{custom_mode}")


def arduplane_mode_name(custom_mode: int) -> str:
    """ArduPlane's flight mode name from HEARTBEAT.custom_mode."""
    return ARDUPLANE_MODES.get(custom_mode, f"UNKNOWN_{custom_mode}")


# ---------------------------------------------------------------------------------------------
# Setpoint limits
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SetpointLimits:
    """The envelope every outgoing setpoint is held to (Table 2: 10..18 m/s, 0.2 rad/s).

    ``max_course_rate_rad_s`` bounds how fast the *commanded* course may turn between two
    setpoints (vehicle time); ``None`` leaves the course unconstrained.
    """

    min_speed_m_s: float
    max_speed_m_s: float
    max_course_rate_rad_s: float | None = None
    max_accel_m_s2: float = 2.0
    max_climb_rate_m_s: float = 3.0
    altitude_gain_per_s: float = 0.5

    def __post_init__(self) -> None:
        for name in (
            "min_speed_m_s",
            "max_speed_m_s",
            "max_accel_m_s2",
            "max_climb_rate_m_s",
            "altitude_gain_per_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if self.min_speed_m_s > self.max_speed_m_s:
            raise ValueError(
                f"min_speed_m_s ({self.min_speed_m_s}) exceeds max_speed_m_s ({self.max_speed_m_s})"
            )
        rate = self.max_course_rate_rad_s
        if rate is not None and not (math.isfinite(rate) and rate > 0.0):
            raise ValueError(f"max_course_rate_rad_s must be finite and > 0, got {rate!r}")


@dataclass(frozen=True, slots=True)
class SentSetpoint:
    """The last setpoint that left, with the vehicle time it left at."""

    t_s: float
    course_rad: float
    speed_m_s: float


COURSE_TOLERANCE_RAD: Final = 1e-9

LimitKind = Literal["speed_below_min", "speed_above_max", "course_rate"]


@dataclass(frozen=True, slots=True)
class Limited:
    """Why a setpoint was changed before it left: ``kind`` for counting, ``detail`` for logs."""

    kind: LimitKind
    detail: str

    def __str__(self) -> str:
        return self.detail


def limit_setpoint(
    command: CourseSpeedCommand,
    t_s: float,
    previous: SentSetpoint | None,
    limits: SetpointLimits,
) -> tuple[CourseSpeedCommand, tuple[Limited, ...]]:
    """The command brought within the limits, and why it had to be (empty when it was not).

    Speed is clamped into [min, max]. When a previous setpoint is known, the course moves
    towards the requested one by at most ``max_course_rate_rad_s * (t_s - previous.t_s)``
    (the shorter way round); time running backwards counts as no time.
    """
    reasons: list[Limited] = []
    speed = command.speed_m_s
    if speed < limits.min_speed_m_s:
        reasons.append(
            Limited("speed_below_min", f"speed {speed:.3f} m/s below {limits.min_speed_m_s} m/s")
        )
        speed = limits.min_speed_m_s
    elif speed > limits.max_speed_m_s:
        reasons.append(
            Limited("speed_above_max", f"speed {speed:.3f} m/s above {limits.max_speed_m_s} m/s")
        )
        speed = limits.max_speed_m_s
    course = command.course_rad
    if not -math.pi <= course < math.pi:
        course = wrap_pi(course)
    if previous is not None and limits.max_course_rate_rad_s is not None:
        dt = max(t_s - previous.t_s, 0.0)
        allowed = limits.max_course_rate_rad_s * dt
        delta = wrap_pi(course - previous.course_rad)
        if abs(delta) > allowed + COURSE_TOLERANCE_RAD:
            reasons.append(
                Limited(
                    "course_rate",
                    f"course change {delta:+.4f} rad in {dt:.3f} s exceeds "
                    f"{limits.max_course_rate_rad_s} rad/s",
                )
            )
            course = wrap_pi(previous.course_rad + math.copysign(allowed, delta))
    if not reasons:
        return replace(command, course_rad=course), ()
    return CourseSpeedCommand(course, speed, command.altitude_m), tuple(reasons)


# ---------------------------------------------------------------------------------------------
# Ports: the part of MAVSDK's plugins the adapters use (so tests can pass recorders)
# ---------------------------------------------------------------------------------------------


class OffboardPort(Protocol):
    async def set_velocity_ned(self, velocity_ned_yaw: VelocityNedYaw) -> Any: ...

    async def set_position_velocity_ned(
        self, position_ned_yaw: PositionNedYaw, velocity_ned_yaw: VelocityNedYaw
    ) -> Any: ...

    async def start(self) -> Any: ...

    async def stop(self) -> Any: ...


class CommandPort(Protocol):
    """MavlinkDirectAsync.send_command: a COMMAND_LONG/COMMAND_INT in, its final ack out."""

    async def send_command(self, command: MavlinkMessage) -> MavlinkMessage: ...


class ParamPort(Protocol):
    async def get_param_int(self, name: str) -> int: ...

    async def get_param_float(self, name: str) -> float: ...

    async def set_param_int(self, name: str, value: int) -> Any: ...


@dataclass(frozen=True, slots=True)
class VehicleState:
    """What an adapter needs of the vehicle's state to place a setpoint.

    ``local_ned_m`` is the vehicle's own local position (LOCAL_POSITION_NED), which only the
    PX4 adapter needs; ``None`` when the vehicle sends none.
    """

    t_s: float
    course_rad: float
    relative_altitude_m: float
    local_ned_m: tuple[float, float, float] | None = None


def _finite(values: Mapping[str, float], what: str) -> None:
    bad = {k: v for k, v in values.items() if not math.isfinite(v)}
    if bad:
        raise LinkError(f"refusing to send a non-finite {what}: {bad}")


def course_deg_0_360(course_rad: float) -> float:
    """A course in degrees in [0, 360), as MAVLink headings are sent."""
    deg = math.degrees(course_rad) % 360.0
    return 0.0 if deg >= 360.0 else deg


def _altitude_rate(target_altitude_m: float, state: VehicleState, limits: SetpointLimits) -> float:
    """Climb rate (m/s, up positive) towards the target altitude, saturated."""
    error = target_altitude_m - state.relative_altitude_m
    rate = limits.altitude_gain_per_s * error
    return max(-limits.max_climb_rate_m_s, min(limits.max_climb_rate_m_s, rate))


class AutopilotAdapter(Protocol):
    """Turns checked (course, speed, altitude) setpoints into one autopilot's commands."""

    name: AutopilotName

    def mode_name(self, custom_mode: int) -> str:
        """The flight mode name from HEARTBEAT.custom_mode."""
        ...

    @property
    def control_mode(self) -> str:
        """The mode name in which the vehicle follows this adapter's commands."""
        ...

    async def prepare(self) -> None:
        """Checks and settings before take-off; raises ``LinkError`` on a refusal."""
        ...

    async def start(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        """Send the first setpoint and switch the vehicle to the control mode."""
        ...

    async def send(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        """Send one setpoint (already limited)."""
        ...

    async def stop(self) -> None:
        """Stop following commands: hold / loiter."""
        ...


async def _offboard_call(what: str, vehicle_id: int, call: Any) -> None:
    try:
        await call
    except OffboardError as exc:
        raise LinkError(f"vehicle {vehicle_id}: {what} refused: {exc.result.name}") from exc


async def send_checked_command(
    port: CommandPort, message: MavlinkMessage, vehicle_id: int, what: str
) -> None:
    """Send a command through MavlinkDirect and require MAV_RESULT_ACCEPTED."""
    try:
        ack = await port.send_command(message)
    except MavlinkDirectError as exc:
        raise LinkError(f"vehicle {vehicle_id}: {what}: no answer ({exc.result.name})") from exc
    try:
        result = int(json.loads(ack.fields_json)["result"])
    except (ValueError, KeyError, TypeError) as exc:
        raise LinkError(f"vehicle {vehicle_id}: {what}: malformed COMMAND_ACK {ack}") from exc
    if result != MAV_RESULT_ACCEPTED:
        name = MAV_RESULT_NAMES.get(result, str(result))
        raise LinkError(f"vehicle {vehicle_id}: {what} refused: MAV_RESULT_{name}")


def command_long(
    target_system: int, target_component: int, command: int, params: tuple[float, ...]
) -> MavlinkMessage:
    """A COMMAND_LONG for MavlinkDirect; ``params`` are param1.. (the rest are 0)."""
    values = list(params) + [0.0] * (7 - len(params))
    fields: dict[str, float | int] = {
        "target_system": target_system,
        "target_component": target_component,
        "command": command,
        "confirmation": 0,
    }
    fields.update({f"param{i + 1}": float(v) for i, v in enumerate(values)})
    _finite({k: float(v) for k, v in fields.items()}, "COMMAND_LONG")
    return MavlinkMessage(
        message_name="COMMAND_LONG",
        target_system_id=target_system,
        target_component_id=target_component,
        fields_json=json.dumps(fields),
    )


def command_int(
    target_system: int,
    target_component: int,
    command: int,
    params: tuple[float, float, float, float],
    *,
    frame: int = MAV_FRAME_GLOBAL,
    x: int = 0,
    y: int = 0,
    z: float = 0.0,
) -> MavlinkMessage:
    """A COMMAND_INT for MavlinkDirect (ArduPilot handles the guided slew commands only so)."""
    fields: dict[str, float | int] = {
        "target_system": target_system,
        "target_component": target_component,
        "frame": frame,
        "command": command,
        "current": 0,
        "autocontinue": 0,
        "param1": float(params[0]),
        "param2": float(params[1]),
        "param3": float(params[2]),
        "param4": float(params[3]),
        "x": x,
        "y": y,
        "z": float(z),
    }
    _finite({k: float(v) for k, v in fields.items()}, "COMMAND_INT")
    return MavlinkMessage(
        message_name="COMMAND_INT",
        target_system_id=target_system,
        target_component_id=target_component,
        fields_json=json.dumps(fields),
    )


# ---------------------------------------------------------------------------------------------
# Adapters
# ---------------------------------------------------------------------------------------------


@dataclass(slots=True)
class VelocityAdapter:
    """Velocity + yaw setpoints (SET_POSITION_TARGET_LOCAL_NED, resent by MAVSDK at 20 Hz).

    The horizontal velocity is the course at the commanded speed, the yaw is the course, and the
    vertical velocity closes the altitude error (saturated climb rate).
    """

    vehicle_id: int
    offboard: OffboardPort
    limits: SetpointLimits
    name: AutopilotName = "velocity"

    def mode_name(self, custom_mode: int) -> str:
        return px4_mode_name(custom_mode)

    @property
    def control_mode(self) -> str:
        return "OFFBOARD"

    async def prepare(self) -> None:
        return None

    def setpoint(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> VelocityNedYaw:
        north = setpoint.speed_m_s * math.cos(setpoint.course_rad)
        east = setpoint.speed_m_s * math.sin(setpoint.course_rad)
        down = -_altitude_rate(altitude_m, state, self.limits)
        yaw = math.degrees(wrap_pi(setpoint.course_rad))
        _finite({"north": north, "east": east, "down": down, "yaw": yaw}, "velocity setpoint")
        return VelocityNedYaw(north_m_s=north, east_m_s=east, down_m_s=down, yaw_deg=yaw)

    async def start(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        await self.send(setpoint, altitude_m, state)
        await _offboard_call("offboard start", self.vehicle_id, self.offboard.start())

    async def send(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        value = self.setpoint(setpoint, altitude_m, state)
        await _offboard_call(
            "velocity setpoint", self.vehicle_id, self.offboard.set_velocity_ned(value)
        )

    async def stop(self) -> None:
        await _offboard_call("offboard stop (hold)", self.vehicle_id, self.offboard.stop())


COM_OBL_RC_ACT: Final = "COM_OBL_RC_ACT"
COM_OBL_RC_ACT_HOLD: Final = 5


async def read_param_number(params: ParamPort, *names: str) -> tuple[str, float] | None:
    """The first of ``names`` the vehicle has and its value, stored as an integer or a float
    (MAVSDK reads each only by its own type); None when it has none of them."""
    for name in names:
        try:
            return name, float(await params.get_param_int(name))
        except ParamError as exc:
            if exc.result != ParamResult.WRONG_TYPE:
                continue
        try:
            return name, await params.get_param_float(name)
        except ParamError:
            continue
    return None


async def check_speed_range(
    params: ParamPort,
    vehicle_id: int,
    limits: SetpointLimits,
    min_names: tuple[str, ...],
    max_names: tuple[str, ...],
    what: str,
) -> None:
    """Refuse (``LinkError``) a vehicle whose speed range, read from the first of ``min_names``
    / ``max_names`` it has, does not hold the mission's ``limits``; only warn when the range
    cannot be read. ``what`` says what the range is in the message ("this PX4 flies airspeeds")."""
    low = await read_param_number(params, *min_names)
    # (a vehicle without the first has no use for the second, whose reads would time out)
    high = None if low is None else await read_param_number(params, *max_names)
    if low is None or high is None:
        log.warning(
            "vehicle %d: its speed range (%s, %s) cannot be read: a mission speed outside it "
            "will not be flown",
            vehicle_id,
            min_names[0],
            max_names[0],
        )
        return
    log.info("vehicle %d: %s = %g, %s = %g", vehicle_id, low[0], low[1], high[0], high[1])
    if limits.min_speed_m_s < low[1] or limits.max_speed_m_s > high[1]:
        raise LinkError(
            f"vehicle {vehicle_id}: the mission commands {limits.min_speed_m_s:g}-"
            f"{limits.max_speed_m_s:g} m/s, but {what} of {low[1]:g}-{high[1]:g} m/s only "
            f"({low[0]}, {high[0]}): widen those or narrow the mission's speed limits"
        )


@dataclass(slots=True)
class Px4FixedWingAdapter:
    """PX4 fixed-wing: a point ``lookahead`` ahead on the course plus the course as velocity.

    PX4 flies a position + velocity setpoint as a line through the point along the velocity,
    at its own airspeed; the commanded speed goes out as MAV_CMD_DO_CHANGE_SPEED (airspeed)
    whenever it moves by more than ``speed_deadband_m_s``. ``offboard_loss_action`` is the
    COM_OBL_RC_ACT wanted (what PX4 does ~1 s after setpoints stop: 5 = hold, the default here;
    PX4's own default 0 flies straight on). It is read and, if different, set before take-off;
    ``None`` leaves the parameters alone (for a PX4-like vehicle without parameters). Before
    that a vehicle whose FW_AIRSPD_MIN..FW_AIRSPD_MAX does not hold the mission's speed limits
    is refused: PX4 would hold the commanded airspeeds within it.
    """

    vehicle_id: int
    offboard: OffboardPort
    commands: CommandPort
    params: ParamPort
    limits: SetpointLimits
    target_component: int = 1
    lookahead_s: float = 4.0
    min_lookahead_m: float = 40.0
    speed_deadband_m_s: float = 0.1
    offboard_loss_action: int | None = COM_OBL_RC_ACT_HOLD
    name: AutopilotName = "px4-fixed-wing"
    _speed_sent: float | None = field(default=None, init=False)

    def mode_name(self, custom_mode: int) -> str:
        return px4_mode_name(custom_mode)

    @property
    def control_mode(self) -> str:
        return "OFFBOARD"

    async def prepare(self) -> None:
        if self.offboard_loss_action is None:
            log.warning(
                "vehicle %d: %s left unchecked: the offboard-loss failsafe is the vehicle's own",
                self.vehicle_id,
                COM_OBL_RC_ACT,
            )
            return
        await check_speed_range(
            self.params,
            self.vehicle_id,
            self.limits,
            (FW_AIRSPD_MIN,),
            (FW_AIRSPD_MAX,),
            "this PX4 flies airspeeds (and holds a setpoint within them)",
        )
        try:
            current = await self.params.get_param_int(COM_OBL_RC_ACT)
            log.info("vehicle %d: %s = %d", self.vehicle_id, COM_OBL_RC_ACT, current)
            wanted = self.offboard_loss_action
            if current != wanted:
                await self.params.set_param_int(COM_OBL_RC_ACT, wanted)
                log.warning(
                    "vehicle %d: set %s from %d to %d",
                    self.vehicle_id,
                    COM_OBL_RC_ACT,
                    current,
                    wanted,
                )
        except ParamError as exc:
            raise LinkError(
                f"vehicle {self.vehicle_id}: cannot check/set {COM_OBL_RC_ACT}: {exc.result.name}"
            ) from exc

    def setpoint(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> tuple[PositionNedYaw, VelocityNedYaw]:
        if state.local_ned_m is None:
            raise LinkError(
                f"vehicle {self.vehicle_id}: PX4 fixed-wing adapter needs LOCAL_POSITION_NED, "
                "and the vehicle sends none"
            )
        north0, east0, down0 = state.local_ned_m
        lookahead = max(self.min_lookahead_m, self.lookahead_s * setpoint.speed_m_s)
        cos_c, sin_c = math.cos(setpoint.course_rad), math.sin(setpoint.course_rad)
        north = north0 + lookahead * cos_c
        east = east0 + lookahead * sin_c
        down = down0 - (altitude_m - state.relative_altitude_m)
        yaw = math.degrees(wrap_pi(setpoint.course_rad))
        v_north, v_east = setpoint.speed_m_s * cos_c, setpoint.speed_m_s * sin_c
        _finite(
            {"north": north, "east": east, "down": down, "v_north": v_north, "v_east": v_east},
            "position+velocity setpoint",
        )
        return (
            PositionNedYaw(north_m=north, east_m=east, down_m=down, yaw_deg=yaw),
            VelocityNedYaw(north_m_s=v_north, east_m_s=v_east, down_m_s=0.0, yaw_deg=yaw),
        )

    def speed_command(self, speed_m_s: float) -> MavlinkMessage:
        """MAV_CMD_DO_CHANGE_SPEED: param1 airspeed (0), param2 speed, param3 -1 (throttle kept)."""
        return command_long(
            self.vehicle_id,
            self.target_component,
            MAV_CMD_DO_CHANGE_SPEED,
            (SPEED_TYPE_AIRSPEED, speed_m_s, -1.0),
        )

    async def _airspeed(self, speed_m_s: float) -> None:
        sent = self._speed_sent
        if sent is not None and abs(speed_m_s - sent) <= self.speed_deadband_m_s:
            return
        await send_checked_command(
            self.commands, self.speed_command(speed_m_s), self.vehicle_id, "DO_CHANGE_SPEED"
        )
        self._speed_sent = speed_m_s

    async def start(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        await self.send(setpoint, altitude_m, state)
        await _offboard_call("offboard start", self.vehicle_id, self.offboard.start())

    async def send(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        position, velocity = self.setpoint(setpoint, altitude_m, state)
        await _offboard_call(
            "position+velocity setpoint",
            self.vehicle_id,
            self.offboard.set_position_velocity_ned(position, velocity),
        )
        await self._airspeed(setpoint.speed_m_s)

    async def stop(self) -> None:
        await _offboard_call("offboard stop (hold)", self.vehicle_id, self.offboard.stop())


SYSID_MYGCS: Final = "SYSID_MYGCS"
#: ArduPilot 4.7's name for SYSID_MYGCS, and the top of the range of GCS ids it may name
MAV_GCS_SYSID: Final = "MAV_GCS_SYSID"
MAV_GCS_SYSID_HI: Final = "MAV_GCS_SYSID_HI"
#: PX4 fixed-wing's airspeed range (m/s): airspeed setpoints are held within it
FW_AIRSPD_MIN: Final = "FW_AIRSPD_MIN"
FW_AIRSPD_MAX: Final = "FW_AIRSPD_MAX"
#: the airspeed range GUIDED_CHANGE_SPEED accepts (m/s), and their names before ArduPilot 4.5
AIRSPEED_MIN: Final = "AIRSPEED_MIN"
AIRSPEED_MAX: Final = "AIRSPEED_MAX"
ARSPD_FBW_MIN: Final = "ARSPD_FBW_MIN"
ARSPD_FBW_MAX: Final = "ARSPD_FBW_MAX"
FS_GCS_ENABL: Final = "FS_GCS_ENABL"
FS_LONG_ACTN: Final = "FS_LONG_ACTN"
#: MAVSDK's ground station identifies as system 245 (Configuration for GROUND_STATION)
MAVSDK_GCS_SYSTEM_ID: Final = 245
#: FS_GCS_ENABL 1: the GCS failsafe on heartbeat loss, in every mode
FS_GCS_ENABL_HEARTBEAT: Final = 1
#: FS_GCS_ENABL values that leave GUIDED unprotected: 0 (off, ArduPlane's default) and 3
#: (heartbeat loss counted in AUTO only; ``check_long_failsafe``)
FS_GCS_ENABL_NOT_IN_GUIDED: Final = (0, 3)
#: FS_LONG_ACTN 0 (continue, ArduPlane's default) keeps GUIDED flying its last course through
#: the failsafe (``failsafe_long_on_event``); 1 returns (RTL)
FS_LONG_ACTN_CONTINUE: Final = 0
FS_LONG_ACTN_RTL: Final = 1


@dataclass(slots=True)
class ArduPlaneAdapter:
    """ArduPlane GUIDED: course over ground, airspeed and altitude by the guided slew commands.

    Each goes out when it changes by more than its deadband; ArduPlane keeps the last one until
    the mode changes. The heading command's param3 is the allowed centripetal acceleration,
    speed * max course rate (m/s^2); ArduPlane banks at most atan(param3 / g), so its course
    rate stays under param3 / speed. Take-off is TAKEOFF mode: ArduPlane refuses
    MAV_CMD_NAV_TAKEOFF (which MAVSDK's ``Action.takeoff`` sends) unless it is a QuadPlane.

    GUIDED has no setpoint stream and so no offboard-loss failsafe: if the app dies the aircraft
    flies its last course for ever unless ArduPlane's GCS failsafe catches it. Stock ArduPlane
    has it off (FS_GCS_ENABL 0), counts only heartbeats from SYSID_MYGCS (255, not MAVSDK's
    245) and, in GUIDED, continues through it (FS_LONG_ACTN 0). So before take-off ``prepare``
    reads the three and sets SYSID_MYGCS to ``gcs_system_id``, FS_GCS_ENABL 0 or 3 to 1
    (heartbeat) and FS_LONG_ACTN 0 to 1 (RTL), logging each change; other values are the
    operator's and are kept. A read or write that fails is a ``LinkError`` naming the parameter:
    a vehicle that cannot be made to return is refused. ``gcs_system_id`` None leaves all three
    alone (a warning is logged). ArduPilot 4.7 renamed SYSID_MYGCS to MAV_GCS_SYSID (with
    MAV_GCS_SYSID_HI, the top of a range of GCS ids when not below it): when SYSID_MYGCS cannot
    be read, that one is checked and set instead (a range that holds ``gcs_system_id`` is kept).
    With ``check_airspeed_range`` ``prepare`` first refuses a vehicle whose airspeed range
    (AIRSPEED_MIN..AIRSPEED_MAX, ARSPD_FBW_* before ArduPilot 4.5) does not hold the mission's
    speed limits: it would refuse those GUIDED_CHANGE_SPEEDs in flight.
    """

    vehicle_id: int
    commands: CommandPort
    params: ParamPort
    limits: SetpointLimits
    gcs_system_id: int | None = MAVSDK_GCS_SYSTEM_ID
    check_airspeed_range: bool = True
    target_component: int = 1
    course_deadband_rad: float = math.radians(0.5)
    speed_deadband_m_s: float = 0.1
    altitude_deadband_m: float = 0.5
    name: AutopilotName = "arduplane"
    _course_sent: float | None = field(default=None, init=False)
    _speed_sent: float | None = field(default=None, init=False)
    _altitude_sent: float | None = field(default=None, init=False)

    def mode_name(self, custom_mode: int) -> str:
        return arduplane_mode_name(custom_mode)

    @property
    def control_mode(self) -> str:
        return "GUIDED"

    async def prepare(self) -> None:
        if self.check_airspeed_range:
            await check_speed_range(
                self.params,
                self.vehicle_id,
                self.limits,
                (AIRSPEED_MIN, ARSPD_FBW_MIN),
                (AIRSPEED_MAX, ARSPD_FBW_MAX),
                "this ArduPlane takes airspeeds",
            )
        gcs = self.gcs_system_id
        if gcs is None:
            log.warning(
                "vehicle %d: %s, %s and %s left unchecked: if this ground station goes silent "
                "the aircraft does what its own GCS failsafe settings say (stock: fly on)",
                self.vehicle_id,
                SYSID_MYGCS,
                FS_GCS_ENABL,
                FS_LONG_ACTN,
            )
            return
        name, current, high = await self._gcs_id_params()
        await self._ensure_param(
            name,
            lambda value: value == gcs or value <= gcs <= high,
            gcs,
            f"so that the GCS failsafe counts this ground station's heartbeats (system {gcs})",
            current,
        )
        await self._ensure_param(
            FS_GCS_ENABL,
            lambda value: value not in FS_GCS_ENABL_NOT_IN_GUIDED,
            FS_GCS_ENABL_HEARTBEAT,
            "so that losing this ground station's heartbeats raises the GCS failsafe in GUIDED",
        )
        await self._ensure_param(
            FS_LONG_ACTN,
            lambda value: value != FS_LONG_ACTN_CONTINUE,
            FS_LONG_ACTN_RTL,
            "so that the GCS failsafe returns (RTL) instead of flying the last GUIDED course on",
        )

    async def _gcs_id_params(self) -> tuple[str, int, int]:
        """The parameter naming the vehicle's GCS, its value, and the top of the range of GCS
        ids (below the value: none): SYSID_MYGCS, else ArduPilot 4.7's MAV_GCS_SYSID with
        MAV_GCS_SYSID_HI (0, its default, when that cannot be read)."""
        try:
            return SYSID_MYGCS, await self.params.get_param_int(SYSID_MYGCS), -1
        except ParamError as old:
            try:
                current = await self.params.get_param_int(MAV_GCS_SYSID)
            except ParamError as exc:
                raise LinkError(
                    f"vehicle {self.vehicle_id}: cannot read {SYSID_MYGCS} ({old.result.name}) "
                    f"or {MAV_GCS_SYSID} ({exc.result.name}); refusing a vehicle whose GCS "
                    "failsafe cannot be checked"
                ) from exc
        try:
            high = await self.params.get_param_int(MAV_GCS_SYSID_HI)
        except ParamError:
            high = 0
        log.info(
            "vehicle %d: %s (ArduPilot 4.7 or later) = %d, %s = %d",
            self.vehicle_id,
            MAV_GCS_SYSID,
            current,
            MAV_GCS_SYSID_HI,
            high,
        )
        return MAV_GCS_SYSID, current, high

    async def _ensure_param(
        self,
        name: str,
        acceptable: Callable[[int], bool],
        wanted: int,
        why: str,
        current: int | None = None,
    ) -> None:
        """Read ``name`` (unless its ``current`` value is given); when it is not acceptable set
        it to ``wanted`` and say why."""
        if current is None:
            try:
                current = await self.params.get_param_int(name)
            except ParamError as exc:
                raise LinkError(
                    f"vehicle {self.vehicle_id}: cannot read {name}: {exc.result.name}; refusing "
                    "a vehicle whose GCS failsafe cannot be checked"
                ) from exc
        log.info("vehicle %d: %s = %d", self.vehicle_id, name, current)
        if acceptable(current):
            return
        try:
            await self.params.set_param_int(name, wanted)
        except ParamError as exc:
            raise LinkError(
                f"vehicle {self.vehicle_id}: cannot set {name} from {current} to {wanted}: "
                f"{exc.result.name}; refusing a vehicle whose GCS failsafe cannot be made to "
                "return it"
            ) from exc
        log.warning(
            "vehicle %d: set %s from %d to %d %s", self.vehicle_id, name, current, wanted, why
        )

    def mode_command(self, custom_mode: int) -> MavlinkMessage:
        return command_long(
            self.vehicle_id,
            self.target_component,
            MAV_CMD_DO_SET_MODE,
            (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode),
        )

    def heading_command(self, course_rad: float, speed_m_s: float) -> MavlinkMessage:
        rate = self.limits.max_course_rate_rad_s
        max_lateral_accel = speed_m_s * rate if rate is not None else UNLIMITED_LATERAL_ACCEL_M_S2
        return command_int(
            self.vehicle_id,
            self.target_component,
            MAV_CMD_GUIDED_CHANGE_HEADING,
            (HEADING_TYPE_COURSE_OVER_GROUND, course_deg_0_360(course_rad), max_lateral_accel, 0.0),
        )

    def speed_command(self, speed_m_s: float) -> MavlinkMessage:
        return command_int(
            self.vehicle_id,
            self.target_component,
            MAV_CMD_GUIDED_CHANGE_SPEED,
            (SPEED_TYPE_AIRSPEED, speed_m_s, self.limits.max_accel_m_s2, 0.0),
        )

    def altitude_command(self, altitude_m: float) -> MavlinkMessage:
        return command_int(
            self.vehicle_id,
            self.target_component,
            MAV_CMD_GUIDED_CHANGE_ALTITUDE,
            (0.0, 0.0, self.limits.max_climb_rate_m_s, 0.0),
            frame=MAV_FRAME_GLOBAL_RELATIVE_ALT,
            z=altitude_m,
        )

    async def _send(self, message: MavlinkMessage, what: str) -> None:
        await send_checked_command(self.commands, message, self.vehicle_id, what)

    async def take_off(self) -> None:
        """Switch to TAKEOFF mode: an armed ArduPlane climbs out and loiters ahead."""
        await self._send(self.mode_command(ARDUPLANE_TAKEOFF), "take-off (mode change to TAKEOFF)")

    async def start(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        await self._send(self.mode_command(ARDUPLANE_GUIDED), "mode change to GUIDED")
        self._course_sent = self._speed_sent = self._altitude_sent = None
        await self.send(setpoint, altitude_m, state)

    async def send(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        course = self._course_sent
        if course is None or abs(wrap_pi(setpoint.course_rad - course)) > self.course_deadband_rad:
            await self._send(
                self.heading_command(setpoint.course_rad, setpoint.speed_m_s),
                "GUIDED_CHANGE_HEADING",
            )
            self._course_sent = setpoint.course_rad
        speed = self._speed_sent
        if speed is None or abs(setpoint.speed_m_s - speed) > self.speed_deadband_m_s:
            await self._send(self.speed_command(setpoint.speed_m_s), "GUIDED_CHANGE_SPEED")
            self._speed_sent = setpoint.speed_m_s
        alt = self._altitude_sent
        if alt is None or abs(altitude_m - alt) > self.altitude_deadband_m:
            await self._send(self.altitude_command(altitude_m), "GUIDED_CHANGE_ALTITUDE")
            self._altitude_sent = altitude_m

    async def stop(self) -> None:
        await self._send(self.mode_command(ARDUPLANE_LOITER), "mode change to LOITER")


def choose_autopilot(
    autopilot: Autopilot, vehicle: Vehicle, configured: AutopilotName | None, vehicle_id: int
) -> AutopilotName:
    """The command form for a vehicle: the configured one, else from what the vehicle reports.

    Raises ``UnsupportedVehicleError`` for a vehicle that takes none of the forms.
    """
    if configured is not None:
        if configured not in AUTOPILOT_NAMES:
            raise UnsupportedVehicleError(
                f"vehicle {vehicle_id}: unknown autopilot adapter {configured!r}; "
                f"choose one of {', '.join(AUTOPILOT_NAMES)}"
            )
        return configured
    if autopilot == Autopilot.PX4 and vehicle == Vehicle.FIXED_WING:
        return "px4-fixed-wing"
    if autopilot == Autopilot.PX4 and vehicle == Vehicle.MULTICOPTER:
        return "velocity"
    if autopilot == Autopilot.ARDUPILOT and vehicle == Vehicle.FIXED_WING:
        return "arduplane"
    if autopilot == Autopilot.GENERIC and vehicle in (Vehicle.FIXED_WING, Vehicle.GENERIC):
        return "velocity"
    raise UnsupportedVehicleError(
        f"vehicle {vehicle_id} reports autopilot {autopilot.name} and vehicle type "
        f"{vehicle.name}: none of the supported command forms fits it (PX4 fixed-wing or "
        "multicopter, ArduPlane, a generic fixed-wing taking velocity setpoints such as the "
        "built-in simulator); refusing it before take-off. Set the vehicle's autopilot adapter "
        f"in the config ({', '.join(AUTOPILOT_NAMES)}) to force one."
    )
