"""What every autopilot adapter shares: the adapter protocol, the MAVSDK plugin ports it uses,
MAVLink command encoders, parameter checks, and the choice of an adapter for a vehicle."""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final, Literal, Protocol

from mavsdk.autopilot import Autopilot
from mavsdk.plugins.mavlink_direct import MavlinkDirectError, MavlinkMessage
from mavsdk.plugins.offboard import AccelerationNed, OffboardError, PositionNedYaw, VelocityNedYaw
from mavsdk.plugins.param import ParamError, ParamResult
from mavsdk.vehicle import Vehicle
from pymavlink.dialects.v20 import common as mavlink

from app.adapters.vehicle.autopilots.limits import SetpointLimits
from app.errors import LinkError
from app.runtime.ports.vehicle import CourseSpeedCommand, UnsupportedVehicleError

log = logging.getLogger(__name__)

AutopilotName = Literal["velocity", "px4-fixed-wing", "arduplane"]
AUTOPILOT_NAMES: Final[tuple[AutopilotName, ...]] = ("velocity", "px4-fixed-wing", "arduplane")
#: MAVSDK's ground station identifies as system 245 (Configuration for GROUND_STATION)
MAVSDK_GCS_SYSTEM_ID: Final = 245

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


class AccelerationOffboardPort(OffboardPort, Protocol):
    """An offboard port that also takes position + velocity + acceleration (MAVSDK 4's
    ``set_position_velocity_acceleration_ned``: SET_POSITION_TARGET_LOCAL_NED with only the
    yaw rate ignored, resent at 20 Hz)."""

    async def set_position_velocity_acceleration_ned(
        self,
        position_ned_yaw: PositionNedYaw,
        velocity_ned_yaw: VelocityNedYaw,
        acceleration_ned: AccelerationNed,
    ) -> Any: ...


class CommandPort(Protocol):
    """MavlinkDirect's send_command: a COMMAND_LONG/COMMAND_INT in, its final ack out."""

    async def send_command(self, command: MavlinkMessage) -> MavlinkMessage: ...


class ParamPort(Protocol):
    async def get_param_int(self, name: str) -> int: ...

    async def get_param_float(self, name: str) -> float: ...

    async def set_param_int(self, name: str, value: int) -> Any: ...

    async def set_param_float(self, name: str, value: float) -> Any: ...


#: how an adapter waits (``asyncio.sleep``; tests pass one that takes no time)
Sleep = Callable[[float], Awaitable[None]]


@dataclass(slots=True)
class ParamJournal:
    """The original value of every parameter an adapter changed, to write back at the end.

    ``record`` keeps the first original of a name (a second change of the same parameter does
    not overwrite what the vehicle had before the app); ``restore`` writes them back in the
    reverse of the order they were first changed, so the last safety setting made is the first
    undone. A write that fails is logged and the next one is tried: restoring never raises
    (``asyncio.CancelledError`` still goes through).
    """

    vehicle_id: int
    originals: dict[str, int | float] = field(default_factory=dict)

    def record(self, name: str, original: int | float) -> None:
        self.originals.setdefault(name, original)

    async def restore(self, params: ParamPort) -> None:
        for name, value in reversed(list(self.originals.items())):
            try:
                if isinstance(value, int):
                    await params.set_param_int(name, value)
                else:
                    await params.set_param_float(name, value)
            except Exception as exc:  # cleanup: every failure is logged, none is raised
                log.error(
                    "vehicle %d: could not restore %s to %s: %s", self.vehicle_id, name, value, exc
                )
                continue
            del self.originals[name]
            log.info("vehicle %d: restored %s to %s", self.vehicle_id, name, value)


@dataclass(frozen=True, slots=True)
class VehicleState:
    """What an adapter needs of the vehicle's state to place a setpoint.

    ``local_ned_m`` is the vehicle's own local position (LOCAL_POSITION_NED), which only the
    PX4 adapter needs; ``None`` when the vehicle sends none. ``flying_speed_m_s`` is the speed
    the airframe flies now (the autopilot's airspeed where it reports one, else its ground
    speed; ``None`` unknown), which the ArduPlane adapter sizes its turn limit on.
    ``roll_rad`` is the newest bank the autopilot reports (ATTITUDE, > 0 right; ``None`` when
    none has come lately), from which the ArduPlane adapter learns how much of the coordinated
    turn the airframe flies (``turn_efficiency``).
    """

    t_s: float
    course_rad: float
    relative_altitude_m: float
    local_ned_m: tuple[float, float, float] | None = None
    flying_speed_m_s: float | None = None
    roll_rad: float | None = None


def check_finite(values: Mapping[str, float], what: str) -> None:
    bad = {k: v for k, v in values.items() if not math.isfinite(v)}
    if bad:
        raise LinkError(f"refusing to send a non-finite {what}: {bad}")


def course_deg_0_360(course_rad: float) -> float:
    """A course in degrees in [0, 360), as MAVLink headings are sent."""
    deg = math.degrees(course_rad) % 360.0
    return 0.0 if deg >= 360.0 else deg


def altitude_rate(target_altitude_m: float, state: VehicleState, limits: SetpointLimits) -> float:
    """Climb rate (m/s, up positive) towards the target altitude, saturated."""
    error = target_altitude_m - state.relative_altitude_m
    rate = limits.altitude_gain_per_s * error
    return max(-limits.max_climb_rate_m_s, min(limits.max_climb_rate_m_s, rate))


class AutopilotAdapter(Protocol):
    """Turns checked (course, speed, altitude) setpoints into one autopilot's commands."""

    name: AutopilotName

    @property
    def honours_speed(self) -> bool:
        """Whether the vehicle flies the commanded speed in the control mode (the phase keeping
        may use speed); False for an autopilot that holds its own airspeed there."""
        ...

    def mode_name(self, custom_mode: int) -> str:
        """The flight mode name from HEARTBEAT.custom_mode."""
        ...

    @property
    def control_mode(self) -> str:
        """The mode name in which the vehicle follows this adapter's commands."""
        ...

    async def prepare(self) -> None:
        """Checks and settings before take-off; raises ``LinkError`` on a refusal. Every
        parameter it changes is recorded with its original value for ``restore_params``."""
        ...

    async def restore_params(self) -> None:
        """Write back the original of every parameter ``prepare`` changed, in an order that
        cannot trip a failsafe on the way; failures are logged, never raised."""
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


class OffboardControl:
    """Start and stop of the adapters that fly MAVSDK offboard (velocity, PX4 fixed-wing): the
    first setpoint, then offboard start; offboard stop leaves the vehicle in hold."""

    __slots__ = ()
    vehicle_id: int
    offboard: OffboardPort

    async def send(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        raise NotImplementedError

    async def start(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        await self.send(setpoint, altitude_m, state)
        await offboard_call("offboard start", self.vehicle_id, self.offboard.start())

    async def stop(self) -> None:
        await offboard_call("offboard stop (hold)", self.vehicle_id, self.offboard.stop())


async def offboard_call(what: str, vehicle_id: int, call: Any) -> None:
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
    if result != mavlink.MAV_RESULT_ACCEPTED:
        entry = mavlink.enums["MAV_RESULT"].get(result)
        name = f"MAV_RESULT_{result}" if entry is None else entry.name
        raise LinkError(f"vehicle {vehicle_id}: {what} refused: {name}")


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
    check_finite({k: float(v) for k, v in fields.items()}, "COMMAND_LONG")
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
    frame: int = mavlink.MAV_FRAME_GLOBAL,
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
    check_finite({k: float(v) for k, v in fields.items()}, "COMMAND_INT")
    return MavlinkMessage(
        message_name="COMMAND_INT",
        target_system_id=target_system,
        target_component_id=target_component,
        fields_json=json.dumps(fields),
    )


def message_interval_command(
    target_system: int, target_component: int, message_id: int, rate_hz: float
) -> MavlinkMessage:
    """MAV_CMD_SET_MESSAGE_INTERVAL: param1 the message id, param2 the interval (us), param3 0
    (to the link the command came on: ArduPilot denies any other, GCS_Common.cpp
    ``handle_command_set_message_interval``)."""
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        raise ValueError(f"a telemetry rate must be finite and > 0 Hz, got {rate_hz!r}")
    return command_long(
        target_system,
        target_component,
        mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
        (float(message_id), round(1e6 / rate_hz), 0.0),
    )


def default_interval_command(
    target_system: int, target_component: int, message_id: int
) -> MavlinkMessage:
    """MAV_CMD_SET_MESSAGE_INTERVAL with interval 0: the message back at the autopilot's own
    rate (PX4 mavlink_receiver.cpp ``set_message_interval``, ArduPilot GCS_Common.cpp)."""
    return command_long(
        target_system,
        target_component,
        mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
        (float(message_id), 0.0, 0.0),
    )


async def restore_message_rates(
    port: CommandPort, vehicle_id: int, target_component: int, names: Iterable[str]
) -> None:
    """Put every message of ``names`` back at the autopilot's own rate; a refusal or a lost
    answer is logged, not raised (the mission is over, the vehicle flies on)."""
    for name in names:
        message_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
        command = default_interval_command(vehicle_id, target_component, message_id)
        try:
            await send_checked_command(port, command, vehicle_id, f"{name} at its own rate")
        except LinkError as exc:
            log.warning(
                "vehicle %d: %s not put back at the autopilot's own rate: %s", vehicle_id, name, exc
            )


def check_message_rates(rates_hz: Mapping[str, float]) -> None:
    """Refuse (``ValueError``) a message that is not MAVLink's or a rate that is not > 0."""
    for name, rate_hz in rates_hz.items():
        if not hasattr(mavlink, f"MAVLINK_MSG_ID_{name}"):
            raise ValueError(f"unknown MAVLink message {name!r} in the telemetry rates")
        if not (math.isfinite(rate_hz) and rate_hz > 0.0):
            raise ValueError(f"the rate of {name} must be finite and > 0 Hz, got {rate_hz!r}")


async def request_message_rates(
    port: CommandPort,
    vehicle_id: int,
    target_component: int,
    rates_hz: Mapping[str, float],
) -> dict[str, bool]:
    """Ask for each message (by MAVLink name) at its rate on this link; the answer per name
    (True: accepted). A refusal or a lost answer is logged, not raised: the vehicle still sends
    the message at its own rate, and the mission flies on it, worse."""
    accepted: dict[str, bool] = {}
    for name, rate_hz in rates_hz.items():
        message_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
        command = message_interval_command(vehicle_id, target_component, message_id, rate_hz)
        try:
            await send_checked_command(port, command, vehicle_id, f"{name} at {rate_hz:g} Hz")
        except LinkError as exc:
            log.warning(
                "vehicle %d: SET_MESSAGE_INTERVAL not accepted (%s): %s stays at the vehicle's "
                "own rate",
                vehicle_id,
                exc,
                name,
            )
            accepted[name] = False
            continue
        log.info("vehicle %d: %s requested at %g Hz (accepted)", vehicle_id, name, rate_hz)
        accepted[name] = True
    return accepted


# ---------------------------------------------------------------------------------------------
# Adapters
# ---------------------------------------------------------------------------------------------


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
    envelope = limits.envelope
    if envelope.min_speed_m_s < low[1] or envelope.max_speed_m_s > high[1]:
        raise LinkError(
            f"vehicle {vehicle_id}: the mission commands {envelope.min_speed_m_s:g}-"
            f"{envelope.max_speed_m_s:g} m/s, but {what} of {low[1]:g}-{high[1]:g} m/s only "
            f"({low[0]}, {high[0]}): widen those or narrow the mission's speed limits"
        )


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
