"""One simulated PX4-like fixed-wing as a MAVLink state machine: modes, arming, offboard, failsafe.

No sockets and no clock here: ``handle`` takes a decoded message and the current simulated (and
wall) time and returns the replies; ``advance`` steps the flight by one physics step; ``telemetry``
returns the streams that are due. The server (``sitl.server``) does the I/O.
"""

import logging
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Protocol

from pymavlink.dialects.v20 import common as mavlink

from sitl import telemetry
from sitl.camera import Observation, TrackingCamera
from sitl.config import SimConfig, VehicleConfig
from sitl.fixedwing import FixedWingState, step, wrap_pi
from sitl.geodesy import Geodesy
from sitl.guidance import Command, LineCommand, LoiterCommand, VelocityCommand, guide

log = logging.getLogger(__name__)

AUTOPILOT_COMPONENT: Final = 1
CAMERA_COMPONENT: Final = 100

# PX4 custom modes: main mode in bits 16-23 of custom_mode, sub mode in bits 24-31
PX4_MAIN_AUTO: Final = 4
PX4_MAIN_OFFBOARD: Final = 6
PX4_SUB_AUTO_TAKEOFF: Final = 2
PX4_SUB_AUTO_LOITER: Final = 3
PX4_SUB_AUTO_RTL: Final = 5


class FlightMode(Protocol):
    """A flight mode as the heartbeat reports it: a name for the truth, the custom_mode."""

    @property
    def name(self) -> str: ...

    @property
    def custom_mode(self) -> int: ...


@dataclass(frozen=True, slots=True)
class Px4Mode:
    name: str
    main: int
    sub: int = 0

    @property
    def custom_mode(self) -> int:
        return (self.main << 16) | (self.sub << 24)


OFFBOARD: Final = Px4Mode("offboard", PX4_MAIN_OFFBOARD)
HOLD: Final = Px4Mode("hold", PX4_MAIN_AUTO, PX4_SUB_AUTO_LOITER)
RETURN: Final = Px4Mode("return", PX4_MAIN_AUTO, PX4_SUB_AUTO_RTL)
TAKEOFF: Final = Px4Mode("takeoff", PX4_MAIN_AUTO, PX4_SUB_AUTO_TAKEOFF)
_MODES_BY_CUSTOM: Final = {(m.main, m.sub): m for m in (OFFBOARD, HOLD, RETURN, TAKEOFF)}

TAKEOFF_DURATION_S: Final = 5.0
MIN_VELOCITY_SETPOINT_M_S: Final = 0.5

# SET_POSITION_TARGET type_mask bits (POSITION_TARGET_TYPEMASK)
_IGNORE_X: Final = 1
_IGNORE_Y: Final = 2
_IGNORE_VX: Final = 8
_IGNORE_VY: Final = 16
_IGNORE_YAW: Final = 1024

# The PX4 parameters the simulator honours, in PARAM_REQUEST_LIST order
PARAM_OFFBOARD_LOSS_TIMEOUT: Final = "COM_OF_LOSS_T"  # s, simulated
PARAM_OFFBOARD_LOSS_ACTION: Final = "COM_OBL_RC_ACT"  # 3: return; anything else: hold
PARAM_CRUISE_SPEED: Final = "FW_AIRSPD_TRIM"  # m/s
PARAM_LOITER_RADIUS: Final = "NAV_LOITER_RAD"  # m
# the airspeed range DO_CHANGE_SPEED setpoints are held within (m/s): the vehicle's speed limits,
# read-only here
PARAM_AIRSPEED_MIN: Final = "FW_AIRSPD_MIN"
PARAM_AIRSPEED_MAX: Final = "FW_AIRSPD_MAX"
_PARAM_TYPES: Final = {
    PARAM_OFFBOARD_LOSS_TIMEOUT: mavlink.MAV_PARAM_TYPE_REAL32,
    PARAM_OFFBOARD_LOSS_ACTION: mavlink.MAV_PARAM_TYPE_INT32,
    PARAM_CRUISE_SPEED: mavlink.MAV_PARAM_TYPE_REAL32,
    PARAM_LOITER_RADIUS: mavlink.MAV_PARAM_TYPE_REAL32,
    PARAM_AIRSPEED_MIN: mavlink.MAV_PARAM_TYPE_REAL32,
    PARAM_AIRSPEED_MAX: mavlink.MAV_PARAM_TYPE_REAL32,
}
_PX4_RETURN_ACTION: Final = 3
_PX4_HOLD_ACTION: Final = 5

# message id -> default interval in simulated seconds (None: telemetry_rate_hz); -1: off
_HEARTBEAT_ID: Final = mavlink.MAVLINK_MSG_ID_HEARTBEAT
_DEFAULT_STREAMS: Final[dict[int, float | None]] = {
    mavlink.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: 0.2,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: None,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: None,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: None,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: None,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: 5.0,
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: -1.0,  # on request (MAVSDK attitude_quaternion)
}

Outgoing = tuple[int, mavlink.MAVLink_message]  # (source component id, message)
GeoLookup = Callable[[], tuple[float, float, float]]  # () -> (lat_deg, lon_deg, alt_amsl_m)


def param_id_text(param_id: str | bytes) -> str:
    """A PARAM_* message's param_id as text (NUL-padded to 16 bytes on the wire)."""
    if isinstance(param_id, bytes):
        param_id = param_id.decode("ascii", "replace")
    return param_id.split("\x00", 1)[0]


def _as_int(value: float, default: int = 0) -> int:
    """A command parameter as an integer; NaN or infinity ("unused") gives ``default``."""
    return round(value) if math.isfinite(value) else default


@dataclass(frozen=True, slots=True)
class VehicleTruth:
    """What the vehicle really does, for scoring (never sent over MAVLink)."""

    index: int
    system_id: int
    state: FixedWingState
    altitude_m: float
    armed: bool
    in_air: bool
    mode: str
    command: Command | None
    link_up: bool
    camera_enabled: bool


class SimVehicle:
    """A PX4-like fixed-wing behind one MAVLink system id.

    Before arming it stands at its launch point on the ground; arming launches it (as a
    catapult would) into its configured start state, in the air, in the current mode (hold at
    boot). It flies offboard velocity, position and position+velocity setpoints, holds, returns
    to its launch point, and falls back to hold (or return) when offboard setpoints stop.
    """

    def __init__(
        self,
        index: int,
        config: VehicleConfig,
        sim: SimConfig,
        camera: TrackingCamera,
        geodesy: Geodesy,
    ) -> None:
        self.index = index
        self.system_id = index + 1
        self.config = config
        self._sim = sim
        self._geodesy = geodesy
        self.camera = camera
        self.state = FixedWingState(
            east_m=config.start.east_m,
            north_m=config.start.north_m,
            course_rad=config.start.course_rad,
            speed_m_s=0.0,
        )
        self.home_east_m = config.start.east_m
        self.home_north_m = config.start.north_m
        self._home_lla = geodesy.to_geodetic(self.home_east_m, self.home_north_m, 0.0)
        self.armed = False
        self.in_air = False
        self.mode: FlightMode = HOLD
        self.command: Command | None = None
        self.cruise_speed_m_s = config.cruise_speed_m_s
        self.offboard_setpoint: Command | None = None
        self._last_setpoint_t_s = -math.inf
        self._last_setpoint_wall_s = -math.inf
        self._mode_entered_t_s = 0.0
        self._streams: dict[int, float] = {}
        self._next_due: dict[int, float] = {}
        for msg_id, interval in _DEFAULT_STREAMS.items():
            self._set_stream(msg_id, interval, 0.0)
        self._camera_period_s = 1.0 / camera.config.rate_hz
        self._next_camera_t_s = 0.0
        self._battery_fraction = 1.0
        self.observations_sent = 0
        self.last_observation: Observation | None = None
        self.wind_east_m_s = 0.0
        self.wind_north_m_s = 0.0
        # settable through PX4 parameters
        self.offboard_timeout_s = sim.offboard_timeout_s
        self.failsafe_action = sim.failsafe_action
        self._loiter_radius_m = config.effective_loiter_radius_m

    # ---- truth -------------------------------------------------------------------------------

    def truth(self, link_up: bool) -> VehicleTruth:
        return VehicleTruth(
            index=self.index,
            system_id=self.system_id,
            state=self.state,
            altitude_m=self.altitude_m,
            armed=self.armed,
            in_air=self.in_air,
            mode=self.mode.name,
            command=self.command if self.in_air else None,
            link_up=link_up,
            camera_enabled=self.camera.enabled,
        )

    @property
    def altitude_m(self) -> float:
        return self.config.altitude_m if self.in_air else 0.0

    @property
    def loiter_radius_m(self) -> float:
        return self._loiter_radius_m

    # ---- flight ------------------------------------------------------------------------------

    def advance(
        self, dt_s: float, t_s: float, wall_s: float, wind_east_m_s: float, wind_north_m_s: float
    ) -> list[Outgoing]:
        """Check the failsafe at time ``t_s``, then fly one physics step of ``dt_s`` in the wind."""
        self.wind_east_m_s, self.wind_north_m_s = wind_east_m_s, wind_north_m_s
        out = self._mode_events(t_s, wall_s)
        if not self.in_air:
            return out
        self._fly(dt_s)
        self._battery_fraction = max(0.0, self._battery_fraction - dt_s / 3600.0)
        return out

    def _mode_events(self, t_s: float, wall_s: float) -> list[Outgoing]:
        """Mode changes that happen on their own at ``t_s``: failsafe, end of take-off."""
        out: list[Outgoing] = []
        if self.mode is OFFBOARD and self._offboard_lost(t_s, wall_s):
            action = RETURN if self.failsafe_action == "return" else HOLD
            self._set_mode(action, t_s)
            text = f"Failsafe: offboard lost, switching to {action.name}"
            log.info("vehicle %d: %s at t=%.2f s", self.system_id, text, t_s)
            out.append(self._statustext(mavlink.MAV_SEVERITY_WARNING, text))
            out.append(self._heartbeat())
            self._next_due[_HEARTBEAT_ID] = t_s + self._streams[_HEARTBEAT_ID]
        if self.mode is TAKEOFF and t_s - self._mode_entered_t_s >= TAKEOFF_DURATION_S:
            self._set_mode(HOLD, t_s)
            out.append(self._statustext(mavlink.MAV_SEVERITY_INFO, "Takeoff complete, holding"))
        return out

    def _fly(self, dt_s: float) -> None:
        """One physics step in the air, flying the current command (in the current wind)."""
        if self.mode is OFFBOARD and self.offboard_setpoint is not None:
            self.command = self.offboard_setpoint
        course_cmd, speed_cmd = guide(
            self.state, self.command or self._hold_here(), self.config.limits.course_gain_per_s
        )
        self.state = step(
            self.state,
            course_cmd,
            speed_cmd,
            self.config.limits,
            dt_s,
            self.wind_east_m_s,
            self.wind_north_m_s,
        )

    def _offboard_lost(self, t_s: float, wall_s: float) -> bool:
        return (
            t_s - self._last_setpoint_t_s > self.offboard_timeout_s
            and wall_s - self._last_setpoint_wall_s > self._sim.offboard_timeout_min_wall_s
        )

    def _hold_here(self) -> LoiterCommand:
        """A loiter circle through the current position, tangent to the current course."""
        radius = self.loiter_radius_m
        clockwise = self.config.loiter_clockwise
        side = self.state.course_rad + (0.5 * math.pi if clockwise else -0.5 * math.pi)
        return LoiterCommand(
            center_east_m=self.state.east_m + radius * math.sin(side),
            center_north_m=self.state.north_m + radius * math.cos(side),
            radius_m=radius,
            clockwise=clockwise,
            speed_m_s=self.cruise_speed_m_s,
        )

    def _set_mode(self, mode: FlightMode, t_s: float) -> None:
        self.mode = mode
        self._mode_entered_t_s = t_s
        if mode is HOLD or mode is TAKEOFF:
            self.command = self._hold_here()
        elif mode is RETURN:
            self.command = LoiterCommand(
                self.home_east_m,
                self.home_north_m,
                self.loiter_radius_m,
                self.config.loiter_clockwise,
                self.cruise_speed_m_s,
            )
        elif mode is OFFBOARD:
            self.command = self.offboard_setpoint

    def _launch(self, t_s: float) -> None:
        start = self.config.start
        self.state = FixedWingState(
            east_m=self.state.east_m,
            north_m=self.state.north_m,
            course_rad=start.course_rad,
            speed_m_s=start.speed_m_s,
        )
        self.in_air = True
        self._set_mode(self.mode, t_s)

    # ---- incoming ----------------------------------------------------------------------------

    def handle(self, msg: mavlink.MAVLink_message, t_s: float, wall_s: float) -> list[Outgoing]:
        """React to one decoded message addressed to this system (or broadcast)."""
        msg_id = msg.get_msgId()
        if msg_id == mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED:
            self._on_setpoint(msg, t_s, wall_s)
            return []
        if msg_id == mavlink.MAVLINK_MSG_ID_COMMAND_LONG:
            params = (
                msg.param1,
                msg.param2,
                msg.param3,
                msg.param4,
                msg.param5,
                msg.param6,
                msg.param7,
            )
            return self._on_command(
                msg, msg.command, params, msg.target_component, t_s, wall_s, None
            )
        if msg_id == mavlink.MAVLINK_MSG_ID_COMMAND_INT:
            params = (
                msg.param1,
                msg.param2,
                msg.param3,
                msg.param4,
                msg.x / 1e7,
                msg.y / 1e7,
                msg.z,
            )
            return self._on_command(
                msg, msg.command, params, msg.target_component, t_s, wall_s, msg.frame
            )
        if msg_id == mavlink.MAVLINK_MSG_ID_PING and msg.target_system == 0:
            reply = mavlink.MAVLink_ping_message(
                msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent()
            )
            return [(AUTOPILOT_COMPONENT, reply)]
        if msg_id == mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_READ:
            if msg.target_component not in (0, AUTOPILOT_COMPONENT):
                return []
            names = list(_PARAM_TYPES)
            index = msg.param_index
            name = names[index] if 0 <= index < len(names) else param_id_text(msg.param_id)
            return [self._param_value(name)] if name in _PARAM_TYPES else []
        if msg_id == mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_LIST:
            if msg.target_component not in (0, AUTOPILOT_COMPONENT):
                return []
            return [self._param_value(name) for name in _PARAM_TYPES]
        if msg_id == mavlink.MAVLINK_MSG_ID_PARAM_SET:
            name = param_id_text(msg.param_id)
            if name not in _PARAM_TYPES or msg.target_component not in (0, AUTOPILOT_COMPONENT):
                return []
            self._set_param(name, msg.param_value)
            return [self._param_value(name)]  # the value now in force (unchanged if refused)
        if msg_id == mavlink.MAVLINK_MSG_ID_TIMESYNC and msg.tc1 == 0:
            return [
                (AUTOPILOT_COMPONENT, mavlink.MAVLink_timesync_message(round(t_s * 1e9), msg.ts1))
            ]
        return []

    def _on_setpoint(self, msg: mavlink.MAVLink_message, t_s: float, wall_s: float) -> None:
        values = (msg.x, msg.y, msg.vx, msg.vy, msg.yaw)
        if msg.coordinate_frame != mavlink.MAV_FRAME_LOCAL_NED:
            log.debug(
                "vehicle %d: setpoint frame %d not supported", self.system_id, msg.coordinate_frame
            )
            return
        mask = msg.type_mask
        use_position = not (mask & (_IGNORE_X | _IGNORE_Y))
        use_velocity = not (mask & (_IGNORE_VX | _IGNORE_VY))
        use_yaw = not (mask & _IGNORE_YAW)
        if not all(math.isfinite(v) for v in values if v is not None):
            used = (use_position, use_position, use_velocity, use_velocity, use_yaw)
            if any(u and not math.isfinite(v) for u, v in zip(used, values, strict=True)):
                log.debug("vehicle %d: non-finite setpoint dropped", self.system_id)
                return
        speed = math.hypot(msg.vx, msg.vy) if use_velocity else 0.0
        setpoint: Command
        if use_position and use_velocity and speed >= MIN_VELOCITY_SETPOINT_M_S:
            setpoint = LineCommand(msg.y, msg.x, math.atan2(msg.vy, msg.vx), speed)
        elif use_position:
            setpoint = LoiterCommand(
                msg.y,
                msg.x,
                self.loiter_radius_m,
                self.config.loiter_clockwise,
                self.cruise_speed_m_s,
            )
        elif use_velocity and speed >= MIN_VELOCITY_SETPOINT_M_S:
            setpoint = VelocityCommand(math.atan2(msg.vy, msg.vx), speed)
        elif use_yaw:
            setpoint = VelocityCommand(wrap_pi(msg.yaw), max(speed, self.cruise_speed_m_s))
        elif use_velocity:
            setpoint = VelocityCommand(self.state.course_rad, speed)
        else:
            log.debug("vehicle %d: setpoint with nothing to fly dropped", self.system_id)
            return
        self.offboard_setpoint = setpoint
        self._last_setpoint_t_s = t_s
        self._last_setpoint_wall_s = wall_s
        if self.mode is OFFBOARD:
            self.command = setpoint

    def _on_command(
        self,
        msg: mavlink.MAVLink_message,
        command: int,
        p: tuple[float, ...],
        target_component: int,
        t_s: float,
        wall_s: float,
        frame: int | None,
    ) -> list[Outgoing]:
        """A COMMAND_LONG (``frame`` None) or COMMAND_INT, answered with COMMAND_ACK."""
        requester = (msg.get_srcSystem(), msg.get_srcComponent())
        if target_component == CAMERA_COMPONENT:
            return [self._ack(command, mavlink.MAV_RESULT_UNSUPPORTED, requester, CAMERA_COMPONENT)]
        if target_component not in (0, AUTOPILOT_COMPONENT):
            return []
        result, extra = self._run_command(command, p, t_s, wall_s, frame)
        return [self._ack(command, result, requester), *extra]

    def _run_command(
        self, command: int, p: tuple[float, ...], t_s: float, wall_s: float, frame: int | None
    ) -> tuple[int, list[Outgoing]]:
        accepted, denied = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_DENIED
        if command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            reply = self._message_by_id(_as_int(p[0], -1), t_s)
            if reply is None:
                return mavlink.MAV_RESULT_UNSUPPORTED, []
            return accepted, [reply]
        if command == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return accepted, [self._autopilot_version()]
        if command == mavlink.MAV_CMD_GET_HOME_POSITION:
            return accepted, [self._home_position(t_s)]
        if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            msg_id, interval_us = _as_int(p[0], -1), p[1]
            if math.isnan(interval_us):
                interval_us = 0.0
            if msg_id not in _DEFAULT_STREAMS:
                return mavlink.MAV_RESULT_UNSUPPORTED, []
            if interval_us == 0:
                self._set_stream(msg_id, _DEFAULT_STREAMS[msg_id], t_s)
            elif interval_us < 0:
                self._set_stream(msg_id, -1.0, t_s)
            else:
                self._set_stream(msg_id, interval_us * 1e-6, t_s)
            return accepted, []
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            was_armed = self.armed
            result = self._arm_disarm(p[0] >= 0.5, _as_int(p[1]) == 21196, t_s)
            return result, ([self._heartbeat()] if self.armed != was_armed else [])
        if command == mavlink.MAV_CMD_DO_SET_MODE:
            return self._do_set_mode(_as_int(p[0]), _as_int(p[1]), _as_int(p[2]), t_s, wall_s)
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            if not self.armed:
                return denied, []
            return self._enter(TAKEOFF, t_s)
        if command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self._enter(RETURN, t_s)
        if command == mavlink.MAV_CMD_NAV_LOITER_UNLIM:
            return self._enter(HOLD, t_s)
        if command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            return self._change_speed(p[1]), []
        if command == mavlink.MAV_CMD_DO_REPOSITION:
            return self._reposition(p, t_s)
        return mavlink.MAV_RESULT_UNSUPPORTED, []

    def _enter(self, mode: FlightMode, t_s: float) -> tuple[int, list[Outgoing]]:
        changed = mode is not self.mode
        self._set_mode(mode, t_s)
        if mode is TAKEOFF and self.armed and not self.in_air:
            self._launch(t_s)
        out = [self._heartbeat()] if changed else []
        return mavlink.MAV_RESULT_ACCEPTED, out

    def arm(self, t_s: float) -> None:
        """Arm and launch, as MAV_CMD_COMPONENT_ARM_DISARM does (no-op when armed)."""
        if not self.armed:
            self.armed = True
            self._launch(t_s)

    def _arm_disarm(self, arm: bool, force: bool, t_s: float) -> int:
        if arm:
            self.arm(t_s)
            return int(mavlink.MAV_RESULT_ACCEPTED)
        if self.in_air and not force:
            return int(mavlink.MAV_RESULT_DENIED)
        self.armed = False
        self.in_air = False
        self.state = FixedWingState(
            self.state.east_m, self.state.north_m, self.state.course_rad, 0.0
        )
        return int(mavlink.MAV_RESULT_ACCEPTED)

    def _do_set_mode(
        self, base_mode: int, main: int, sub: int, t_s: float, wall_s: float
    ) -> tuple[int, list[Outgoing]]:
        if not base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return mavlink.MAV_RESULT_DENIED, []
        mode = _MODES_BY_CUSTOM.get((main, sub))
        if main == PX4_MAIN_OFFBOARD:
            mode = OFFBOARD
        if mode is None:
            return mavlink.MAV_RESULT_DENIED, []
        if mode is OFFBOARD and (
            self.offboard_setpoint is None or self._offboard_lost(t_s, wall_s)
        ):
            return mavlink.MAV_RESULT_DENIED, [
                self._statustext(mavlink.MAV_SEVERITY_CRITICAL, "Offboard denied: no setpoints")
            ]
        if mode is TAKEOFF and not self.armed:
            return mavlink.MAV_RESULT_DENIED, []
        return self._enter(mode, t_s)

    def _reposition(self, p: tuple[float, ...], t_s: float) -> tuple[int, list[Outgoing]]:
        """Hold (loiter) at a latitude/longitude, as PX4 does for MAV_CMD_DO_REPOSITION."""
        lat, lon = p[4], p[5]
        if not (self.in_air and math.isfinite(lat) and math.isfinite(lon)):
            return mavlink.MAV_RESULT_DENIED, []
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            return mavlink.MAV_RESULT_DENIED, []
        if math.isfinite(p[0]) and p[0] > 0.0:
            self._change_speed(p[0])
        east, north, _ = self._geodesy.to_local(lat, lon, self._sim.origin_alt_m)
        changed = self.mode is not HOLD
        self.mode = HOLD
        self._mode_entered_t_s = t_s
        self.command = LoiterCommand(
            east, north, self.loiter_radius_m, self.config.loiter_clockwise, self.cruise_speed_m_s
        )
        return mavlink.MAV_RESULT_ACCEPTED, [self._heartbeat()] if changed else []

    def _param(self, name: str) -> float:
        if name == PARAM_OFFBOARD_LOSS_TIMEOUT:
            return self.offboard_timeout_s
        if name == PARAM_OFFBOARD_LOSS_ACTION:
            return _PX4_RETURN_ACTION if self.failsafe_action == "return" else _PX4_HOLD_ACTION
        if name == PARAM_CRUISE_SPEED:
            return self.cruise_speed_m_s
        if name == PARAM_AIRSPEED_MIN:
            return self.config.limits.min_speed_m_s
        if name == PARAM_AIRSPEED_MAX:
            return self.config.limits.max_speed_m_s
        return self._loiter_radius_m

    def _set_param(self, name: str, wire_value: float) -> None:
        """Apply a PARAM_SET; a value out of range is refused (the old value stays)."""
        if _PARAM_TYPES[name] == mavlink.MAV_PARAM_TYPE_INT32:
            action = struct.unpack("<i", struct.pack("<f", wire_value))[0]  # bytewise encoding
            self.failsafe_action = "return" if action == _PX4_RETURN_ACTION else "hold"
            return
        if not math.isfinite(wire_value):
            return
        if name == PARAM_OFFBOARD_LOSS_TIMEOUT and wire_value > 0.0:
            self.offboard_timeout_s = wire_value
        elif name == PARAM_CRUISE_SPEED and wire_value > 0.0:
            self._change_speed(wire_value)
        elif name == PARAM_LOITER_RADIUS and wire_value >= 1.05 * self.config.min_turn_radius_m:
            self._loiter_radius_m = wire_value

    def _param_value(self, name: str) -> Outgoing:
        names = list(_PARAM_TYPES)
        kind = _PARAM_TYPES[name]
        value = self._param(name)
        if kind == mavlink.MAV_PARAM_TYPE_INT32:
            value = struct.unpack("<f", struct.pack("<i", int(value)))[0]
        return AUTOPILOT_COMPONENT, mavlink.MAVLink_param_value_message(
            name.encode("ascii"), value, kind, len(names), names.index(name)
        )

    def _change_speed(self, speed_m_s: float) -> int:
        limits = self.config.limits
        if speed_m_s < 0.0 or not math.isfinite(speed_m_s):
            self.cruise_speed_m_s = self.config.cruise_speed_m_s
        else:
            self.cruise_speed_m_s = limits.clamp_speed(speed_m_s)
        cmd = self.command
        if isinstance(cmd, LoiterCommand) and self.mode is not OFFBOARD:
            self.command = LoiterCommand(
                cmd.center_east_m,
                cmd.center_north_m,
                cmd.radius_m,
                cmd.clockwise,
                self.cruise_speed_m_s,
            )
        return int(mavlink.MAV_RESULT_ACCEPTED)

    def _set_stream(self, msg_id: int, interval_s: float | None, t_s: float) -> None:
        interval = 1.0 / self._sim.telemetry_rate_hz if interval_s is None else interval_s
        self._streams[msg_id] = interval
        self._next_due[msg_id] = t_s

    # ---- outgoing ----------------------------------------------------------------------------

    def telemetry(self, t_s: float, geo: GeoLookup) -> list[Outgoing]:
        """The streams due at ``t_s`` (each at most once per call)."""
        out: list[Outgoing] = []
        for msg_id, interval in self._streams.items():
            if interval < 0.0:
                continue
            due = self._next_due[msg_id]
            if t_s + 1e-9 < due:
                continue
            # keep the stream on its grid, but never owe more than one message
            self._next_due[msg_id] = max(due + interval, t_s + 0.5 * interval)
            msg = self._message_by_id(msg_id, t_s, geo)
            if msg is not None:
                out.append(msg)
        return out

    def camera_due(self, t_s: float) -> bool:
        if t_s + 1e-9 < self._next_camera_t_s:
            return False
        self._next_camera_t_s = max(
            self._next_camera_t_s + self._camera_period_s, t_s + 0.5 * self._camera_period_s
        )
        return True

    def tracking_message(self, obs: Observation, lat: float, lon: float, alt: float) -> Outgoing:
        """CAMERA_TRACKING_GEO_STATUS for an observation geolocated at (lat, lon, alt)."""
        self.observations_sent += 1
        self.last_observation = obs
        return CAMERA_COMPONENT, telemetry.camera_tracking_geo_status(obs, lat, lon, alt)

    def _message_by_id(
        self, msg_id: int, t_s: float, geo: GeoLookup | None = None
    ) -> Outgoing | None:
        """Message ``msg_id`` now, or None if this vehicle does not send it."""
        msg = self._build(msg_id, t_s, geo or self._own_geo)
        return None if msg is None else (AUTOPILOT_COMPONENT, msg)

    def _own_geo(self) -> tuple[float, float, float]:
        return self._geodesy.to_geodetic(self.state.east_m, self.state.north_m, self.altitude_m)

    def _build(self, msg_id: int, t_s: float, geo: GeoLookup) -> mavlink.MAVLink_message | None:
        s = self.state
        if msg_id == _HEARTBEAT_ID:
            return self._heartbeat_message()
        if msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return self._autopilot_version()[1]
        if msg_id == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
            return telemetry.home_position(
                *self._home_lla, self.home_east_m, self.home_north_m, t_s
            )
        if msg_id == mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            return telemetry.extended_sys_state(self.in_air)
        if msg_id == mavlink.MAVLINK_MSG_ID_SYS_STATUS:
            return telemetry.sys_status(self._battery_fraction)
        if msg_id == mavlink.MAVLINK_MSG_ID_BATTERY_STATUS:
            return telemetry.battery_status(self._battery_fraction)
        if msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE:
            return telemetry.attitude(s, t_s)
        if msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION:
            return telemetry.attitude_quaternion(s, t_s)
        v_north, v_east = self._ground_velocity()
        if msg_id == mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            return telemetry.local_position_ned(s, self.altitude_m, v_north, v_east, t_s)
        if msg_id == mavlink.MAVLINK_MSG_ID_VFR_HUD:
            ground_speed = math.hypot(v_north, v_east)
            alt_amsl = self._sim.origin_alt_m + self.altitude_m
            return telemetry.vfr_hud(s, ground_speed, self.in_air, alt_amsl)
        if msg_id == mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            return telemetry.global_position_int(geo(), self.altitude_m, v_north, v_east, s, t_s)
        if msg_id == mavlink.MAVLINK_MSG_ID_GPS_RAW_INT:
            return telemetry.gps_raw_int(geo(), v_north, v_east, t_s)
        return None

    def _ground_velocity(self) -> tuple[float, float]:
        """(north, east) ground velocity: airspeed along the heading plus the wind drift."""
        s = self.state
        return s.v_north_m_s + self.wind_north_m_s, s.v_east_m_s + self.wind_east_m_s

    def _heartbeat_message(self) -> mavlink.MAVLink_message:
        return telemetry.heartbeat(self.mode.custom_mode, self.armed)

    def _heartbeat(self) -> Outgoing:
        return AUTOPILOT_COMPONENT, self._heartbeat_message()

    def _autopilot_version(self) -> Outgoing:
        return AUTOPILOT_COMPONENT, telemetry.autopilot_version(self.system_id)

    def _home_position(self, t_s: float) -> Outgoing:
        return AUTOPILOT_COMPONENT, telemetry.home_position(
            *self._home_lla, self.home_east_m, self.home_north_m, t_s
        )

    def _statustext(self, severity: int, text: str) -> Outgoing:
        return AUTOPILOT_COMPONENT, telemetry.statustext(severity, text)

    def _ack(
        self,
        command: int,
        result: int,
        requester: tuple[int, int],
        component: int = AUTOPILOT_COMPONENT,
    ) -> Outgoing:
        return component, telemetry.command_ack(command, result, requester)
