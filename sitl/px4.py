"""The simulator's PX4 personality: its heartbeat and modes, offboard setpoints, the commands it
takes and the parameters it honours, and its offboard-loss failsafe.

Over one ``sitl.vehicle.SimVehicle`` airframe (select it with ``SimConfig(autopilot="px4")``,
the default). It flies offboard velocity, position and position+velocity setpoints, holds,
returns to its launch point, and falls back to hold (or return) when offboard setpoints stop.

Where it matters to the mission it does what PX4 v1.16.0 does (each a ``SimConfig`` option
whose default is the real behaviour):

- Airspeed in OFFBOARD (``px4_offboard_speed = "trim"``): a position or position+velocity
  setpoint is flown at FW_AIRSPD_TRIM whatever the velocity's magnitude:
  src/modules/fw_pos_control/FixedwingPositionControl.cpp ``Run`` sets the position setpoint's
  ``cruising_speed = NAN`` on every offboard trajectory setpoint and ``adapt_airspeed_setpoint``
  turns NaN into the trim airspeed. MAV_CMD_DO_CHANGE_SPEED is ACKed ACCEPTED
  (navigator/navigator_main.cpp ``run``) but applied only in AUTO modes
  (FixedwingPositionControl.cpp ``vehicle_command_poll``: FW_POSCTRL_MODE_AUTO; the next offboard
  setpoint clears it again); entering hold, take-off or return resets it to trim
  (navigator/loiter.cpp, takeoff.cpp, rtl_direct.cpp ``reset_cruising_speed``).
  FW_AIRSPD_TRIM is served and settable (``px4_trim_airspeed_m_s``; default: the vehicle's
  cruise speed; the stock value is 15 m/s). A velocity-only setpoint is flown at its own speed:
  that is this simulator's own extension (real PX4 keeps its attitude), for the velocity adapter.
- Acceleration in SET_POSITION_TARGET_LOCAL_NED (used when its type_mask does not ignore AX/AY,
  with a velocity): its component normal to the velocity is a path curvature fed forward,
  radius = direction * v^2 / |a_n| (FixedwingPositionControl.cpp ``Run``, the offboard branch;
  ``control_auto_path`` passes 1 / loiter_radius to NPFG). In v1.16.0 direction is
  -sign(v x a_n) (x north, y east), so a clockwise-turning acceleration feeds a counter-clockwise
  curvature forward (``px4_curvature_sign = "v1.16.0"``; PX4 fixed the sign after the release,
  PR #27582: ``"ned"``).
- Turn rate in OFFBOARD (``px4_roll_limit_deg``, FW_R_LIM, 50 deg: fw_path_navigation_params.c;
  airframe 10041 keeps it): NPFG follows a position setpoint's line banking up to FW_R_LIM, so
  it turns at up to g tan(FW_R_LIM) / V (0.78 rad/s at 15 m/s), whatever envelope the mission
  assumes. Real v1.16.0 SIH x3 flying `px4-sitl` turned at over 0.2 rad/s (the mission's
  envelope) 36 % of the track stage (0.5 s intervals), up to 0.39 rad/s at 27 deg of bank, and
  held the moving target's circle at 10-14 m RMS where this simulator, held to 0.2, gave
  14-35 m. Velocity-only setpoints (this simulator's own extension) and the other modes keep
  the envelope's rate. None: the envelope's rate everywhere.
- Take-off (``takeoff = "runway"``, airframe 10041 sets RWTO_TKOFF 1): arming leaves it on the
  ground; MAV_CMD_NAV_TAKEOFF (or the take-off mode) while armed starts the ground roll; the land
  detector reports "in air" during the roll (see ``sitl.vehicle``); take-off ends in hold once
  the climb has reached the vehicle's altitude. ``"launch"``: arming launches it at once.
"""

import logging
import math
import struct
from dataclasses import dataclass, replace
from typing import Final

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from app.core.frames import wrap_pi
from app.core.plant import heading_for_ground_course
from sitl import telemetry
from sitl.config import SimConfig
from sitl.guidance import (
    Command,
    LineCommand,
    LoiterCommand,
    VelocityCommand,
    guide,
)
from sitl.vehicle import (
    ARM_DISARM_FORCE,
    AUTOPILOT_COMPONENT,
    PX4_STREAMS,
    FlightMode,
    Outgoing,
    SilenceTimer,
    SimVehicle,
    StreamTable,
    as_int,
    param_id_text,
)

log = logging.getLogger(__name__)

#: standard gravity (m/s^2)
GRAVITY_M_S2: Final = 9.80665


@dataclass(frozen=True, slots=True)
class Px4Mode:
    """A PX4 flight mode: main mode in bits 16-23 of custom_mode, sub mode in bits 24-31."""

    name: str
    main: int
    sub: int = 0

    @property
    def custom_mode(self) -> int:
        return (self.main << 16) | (self.sub << 24)


OFFBOARD: Final = Px4Mode("offboard", mavutil.PX4_CUSTOM_MAIN_MODE_OFFBOARD)
HOLD: Final = Px4Mode(
    "hold", mavutil.PX4_CUSTOM_MAIN_MODE_AUTO, mavutil.PX4_CUSTOM_SUB_MODE_AUTO_LOITER
)
RETURN: Final = Px4Mode(
    "return", mavutil.PX4_CUSTOM_MAIN_MODE_AUTO, mavutil.PX4_CUSTOM_SUB_MODE_AUTO_RTL
)
TAKEOFF: Final = Px4Mode(
    "takeoff", mavutil.PX4_CUSTOM_MAIN_MODE_AUTO, mavutil.PX4_CUSTOM_SUB_MODE_AUTO_TAKEOFF
)
_MODES_BY_CUSTOM: Final = {(m.main, m.sub): m for m in (OFFBOARD, HOLD, RETURN, TAKEOFF)}

#: a launched take-off ("launch") holds after this long; a runway take-off once within
#: TAKEOFF_ALTITUDE_TOLERANCE_M of the vehicle's altitude
TAKEOFF_DURATION_S: Final = 5.0
TAKEOFF_ALTITUDE_TOLERANCE_M: Final = 1.0
MIN_VELOCITY_SETPOINT_M_S: Final = 0.5
#: an acceleration normal to the velocity below this (m/s^2) gives no curvature (PX4: a zero
#: normal has no direction, the radius is NaN and the curvature 0)
MIN_NORMAL_ACCEL_M_S2: Final = 1e-6
_ACCEL_IGNORE: Final = (
    mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE
)

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


class Px4Autopilot:
    """PX4 behind one simulated airframe: the mode it is in, its offboard setpoint and failsafe
    parameters (COM_OF_LOSS_T, COM_OBL_RC_ACT), settable over MAVLink."""

    def __init__(self, sim: SimConfig, trim_airspeed_m_s: float) -> None:
        self.offboard_setpoint: Command | None = None
        #: FW_AIRSPD_TRIM (m/s)
        self.trim_airspeed_m_s = trim_airspeed_m_s
        self._offboard_speed = sim.px4_offboard_speed
        self._curvature_sign = -1.0 if sim.px4_curvature_sign == "v1.16.0" else 1.0
        roll = sim.px4_roll_limit_deg
        self._max_lateral_accel_m_s2 = (
            None if roll is None else GRAVITY_M_S2 * math.tan(math.radians(roll))
        )
        self._runway = sim.takeoff == "runway"
        self.offboard_timeout_s = sim.offboard_timeout_s
        self.failsafe_action = sim.failsafe_action
        self._offboard_min_wall_s = sim.offboard_timeout_min_wall_s
        self._setpoints = SilenceTimer()
        self._mode_entered_t_s = 0.0
        self._reported_in_air = False

    @property
    def boot_mode(self) -> FlightMode:
        return HOLD

    @property
    def trim_throttle(self) -> float:
        """FW_THR_TRIM: the throttle that holds trim airspeed in level flight (PX4 default)."""
        return 0.6

    @property
    def turn_efficiency(self) -> float:
        """The coordinated turn: PX4 SIH's turns were not measured against it."""
        return 1.0

    @property
    def stream_defaults(self) -> StreamTable:
        return PX4_STREAMS

    @property
    def _trim_in_offboard(self) -> bool:
        return self._offboard_speed == "trim"

    # ---- modes -------------------------------------------------------------------------------

    def mode_events(self, v: SimVehicle, t_s: float, wall_s: float) -> list[Outgoing]:
        """Mode changes that happen on their own at ``t_s``: failsafe, end of take-off."""
        out: list[Outgoing] = []
        if v.mode is OFFBOARD and self._offboard_lost(t_s, wall_s):
            action = RETURN if self.failsafe_action == "return" else HOLD
            self._set_mode(v, action, t_s)
            text = f"Failsafe: offboard lost, switching to {action.name}"
            log.info("vehicle %d: %s at t=%.2f s", v.system_id, text, t_s)
            out.append(v.statustext(mavlink.MAV_SEVERITY_WARNING, text))
            out.append(v.heartbeat())
            v.next_heartbeat_at(t_s + v.stream_interval_s(mavlink.MAVLINK_MSG_ID_HEARTBEAT))
        in_air = v.landed_state_in_air
        if in_air != self._reported_in_air:
            # Commander on the land detector's change (already during the ground roll)
            self._reported_in_air = in_air
            text = "Takeoff detected" if in_air else "Landing detected"
            out.append(v.statustext(mavlink.MAV_SEVERITY_INFO, text))
        if v.mode is TAKEOFF and self._takeoff_done(v, t_s):
            self._set_mode(v, HOLD, t_s)
            out.append(v.statustext(mavlink.MAV_SEVERITY_INFO, "Takeoff complete, holding"))
        return out

    def _takeoff_done(self, v: SimVehicle, t_s: float) -> bool:
        if not v.in_air:
            return False
        if not self._runway:
            return t_s - self._mode_entered_t_s >= TAKEOFF_DURATION_S
        return v.air_altitude_m >= v.altitude_target_m - TAKEOFF_ALTITUDE_TOLERANCE_M

    def _offboard_lost(self, t_s: float, wall_s: float) -> bool:
        return self._setpoints.silent(
            t_s, wall_s, self.offboard_timeout_s, self._offboard_min_wall_s
        )

    def fly(self, v: SimVehicle, dt_s: float) -> None:
        """One physics step in the air, flying the current command. The path (line, loiter,
        velocity) is followed over the ground: NPFG flies the air-relative bearing that holds
        the path's ground course in the wind its EKF estimates (here: the wind that blows),
        so a cross wind costs a crab angle, not a cross-track offset."""
        if v.mode is OFFBOARD and self.offboard_setpoint is not None:
            v.command = self._offboard_command(self.offboard_setpoint)
        limits = v.config.limits
        course_cmd, speed_cmd = guide(v.state, v.command or v.hold_here(), limits.course_gain_per_s)
        accel = self._max_lateral_accel_m_s2
        if accel is not None and v.mode is OFFBOARD and isinstance(v.command, LineCommand):
            # NPFG banks up to FW_R_LIM on a position setpoint's line
            speed = max(v.state.speed_m_s, limits.min_speed_m_s)
            rate = max(limits.max_course_rate_rad_s, accel / speed)
            limits = replace(limits, max_course_rate_rad_s=rate)
        heading_cmd = heading_for_ground_course(
            course_cmd, v.state.speed_m_s, v.wind_east_m_s, v.wind_north_m_s
        )
        v.step(heading_cmd, speed_cmd, limits, dt_s)

    def _offboard_command(self, setpoint: Command) -> Command:
        """A position (+velocity) setpoint flown at FW_AIRSPD_TRIM (cruising_speed NaN)."""
        if self._trim_in_offboard and isinstance(setpoint, LineCommand | LoiterCommand):
            return replace(setpoint, speed_m_s=self.trim_airspeed_m_s)
        return setpoint

    def _set_mode(self, v: SimVehicle, mode: FlightMode, t_s: float) -> None:
        if mode is not v.mode and mode in (HOLD, TAKEOFF, RETURN) and self._trim_in_offboard:
            v.cruise_speed_m_s = self.trim_airspeed_m_s  # navigator: reset_cruising_speed()
        v.mode = mode
        self._mode_entered_t_s = t_s
        if mode is TAKEOFF and self._runway:
            s = v.state  # straight on along the runway until the climb is done
            v.command = LineCommand(s.east_m, s.north_m, s.course_rad, v.cruise_speed_m_s)
        elif mode is HOLD or mode is TAKEOFF:
            v.command = v.hold_here()
        elif mode is RETURN:
            v.command = v.loiter_at(v.home_east_m, v.home_north_m)
        elif mode is OFFBOARD:
            setpoint = self.offboard_setpoint
            v.command = None if setpoint is None else self._offboard_command(setpoint)

    def launched(self, v: SimVehicle, t_s: float) -> None:
        """The airframe has just been launched (or has rotated): fly the current mode."""
        entered = self._mode_entered_t_s
        self._set_mode(v, v.mode, t_s)
        self._mode_entered_t_s = entered

    def arm(self, v: SimVehicle, t_s: float) -> None:
        """Arm (no-op when armed): on the runway it stays on the ground unless in take-off;
        with ``takeoff = "launch"`` arming launches it."""
        if v.armed:
            return
        v.armed = True
        if not self._runway or v.mode is TAKEOFF:
            v.take_off(t_s)

    # ---- incoming ----------------------------------------------------------------------------

    def handle(
        self, v: SimVehicle, msg: mavlink.MAVLink_message, t_s: float, wall_s: float
    ) -> list[Outgoing]:
        """Offboard setpoints and the parameter protocol."""
        msg_id = msg.get_msgId()
        if msg_id == mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED:
            self._on_setpoint(v, msg, t_s, wall_s)
            return []
        if msg_id == mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_READ:
            if msg.target_component not in (0, AUTOPILOT_COMPONENT):
                return []
            names = list(_PARAM_TYPES)
            index = msg.param_index
            name = names[index] if 0 <= index < len(names) else param_id_text(msg.param_id)
            return [self._param_value(v, name)] if name in _PARAM_TYPES else []
        if msg_id == mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_LIST:
            if msg.target_component not in (0, AUTOPILOT_COMPONENT):
                return []
            return [self._param_value(v, name) for name in _PARAM_TYPES]
        if msg_id == mavlink.MAVLINK_MSG_ID_PARAM_SET:
            name = param_id_text(msg.param_id)
            if name not in _PARAM_TYPES or msg.target_component not in (0, AUTOPILOT_COMPONENT):
                return []
            self._set_param(v, name, msg.param_value)
            return [self._param_value(v, name)]  # the value now in force (unchanged if refused)
        return []

    def _on_setpoint(
        self, v: SimVehicle, msg: mavlink.MAVLink_message, t_s: float, wall_s: float
    ) -> None:
        values = (msg.x, msg.y, msg.vx, msg.vy, msg.yaw)
        if msg.coordinate_frame != mavlink.MAV_FRAME_LOCAL_NED:
            log.debug(
                "vehicle %d: setpoint frame %d not supported", v.system_id, msg.coordinate_frame
            )
            return
        mask = msg.type_mask
        use_position = not (
            mask
            & (
                mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE
                | mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE
            )
        )
        use_velocity = not (
            mask
            & (
                mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE
                | mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE
            )
        )
        use_yaw = not (mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE)
        if not all(math.isfinite(x) for x in values if x is not None):
            used = (use_position, use_position, use_velocity, use_velocity, use_yaw)
            if any(u and not math.isfinite(x) for u, x in zip(used, values, strict=True)):
                log.debug("vehicle %d: non-finite setpoint dropped", v.system_id)
                return
        speed = math.hypot(msg.vx, msg.vy) if use_velocity else 0.0
        setpoint: Command
        if use_position and use_velocity and speed >= MIN_VELOCITY_SETPOINT_M_S:
            curvature = 0.0
            if not mask & _ACCEL_IGNORE:
                if not (math.isfinite(msg.afx) and math.isfinite(msg.afy)):
                    log.debug("vehicle %d: non-finite acceleration dropped", v.system_id)
                    return
                curvature = self.curvature_per_m(msg.vx, msg.vy, msg.afx, msg.afy)
            course = math.atan2(msg.vy, msg.vx)
            setpoint = LineCommand(msg.y, msg.x, course, speed, curvature)
        elif use_position:
            setpoint = v.loiter_at(msg.y, msg.x)
        elif use_velocity and speed >= MIN_VELOCITY_SETPOINT_M_S:
            setpoint = VelocityCommand(math.atan2(msg.vy, msg.vx), speed)
        elif use_yaw:
            setpoint = VelocityCommand(wrap_pi(msg.yaw), max(speed, v.cruise_speed_m_s))
        elif use_velocity:
            setpoint = VelocityCommand(v.state.course_rad, speed)
        else:
            log.debug("vehicle %d: setpoint with nothing to fly dropped", v.system_id)
            return
        self.offboard_setpoint = setpoint
        self._setpoints.heard(t_s, wall_s)
        if v.mode is OFFBOARD:
            v.command = self._offboard_command(setpoint)

    def curvature_per_m(
        self, v_north_m_s: float, v_east_m_s: float, a_north_m_s2: float, a_east_m_s2: float
    ) -> float:
        """The path curvature (1/m, > 0 clockwise) PX4 feeds forward for an offboard velocity and
        acceleration: 1 / loiter_radius with loiter_radius = direction * v^2 / |a_normal|."""
        speed = math.hypot(v_north_m_s, v_east_m_s)
        un, ue = v_north_m_s / speed, v_east_m_s / speed
        along = a_north_m_s2 * un + a_east_m_s2 * ue
        an, ae = a_north_m_s2 - along * un, a_east_m_s2 - along * ue
        normal = math.hypot(an, ae)
        if normal < MIN_NORMAL_ACCEL_M_S2:
            return 0.0
        cross = un * ae - ue * an  # v x a_n in (north, east): > 0 turning clockwise
        direction = self._curvature_sign * math.copysign(1.0, cross)
        return direction * normal / (speed * speed)

    def run_command(
        self,
        v: SimVehicle,
        command: int,
        p: tuple[float, ...],
        t_s: float,
        wall_s: float,
        frame: int | None,
    ) -> tuple[int, list[Outgoing]]:
        """One of PX4's commands (``frame`` None for COMMAND_LONG): the result and any replies."""
        denied = mavlink.MAV_RESULT_DENIED
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            was_armed = v.armed
            result = self._arm_disarm(v, p[0] >= 0.5, as_int(p[1]) == ARM_DISARM_FORCE, t_s)
            if v.armed == was_armed:
                return result, []
            # Commander::arm / disarm: "Armed by %s" with the reason, here a MAVLink command
            text = "Armed by external command" if v.armed else "Disarmed by external command"
            return result, [v.statustext(mavlink.MAV_SEVERITY_INFO, text), v.heartbeat()]
        if command == mavlink.MAV_CMD_DO_SET_MODE:
            return self._do_set_mode(v, as_int(p[0]), as_int(p[1]), as_int(p[2]), t_s, wall_s)
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            if not v.armed:
                return denied, []
            return self._enter(v, TAKEOFF, t_s)
        if command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self._enter(v, RETURN, t_s)
        if command == mavlink.MAV_CMD_NAV_LOITER_UNLIM:
            return self._enter(v, HOLD, t_s)
        if command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            return self._change_speed(v, p[1]), []
        if command == mavlink.MAV_CMD_DO_REPOSITION:
            return self._reposition(v, p, t_s)
        return mavlink.MAV_RESULT_UNSUPPORTED, []

    def _enter(self, v: SimVehicle, mode: FlightMode, t_s: float) -> tuple[int, list[Outgoing]]:
        changed = mode is not v.mode
        self._set_mode(v, mode, t_s)
        if mode is TAKEOFF and v.armed and not v.in_air:
            v.take_off(t_s)
        out = [v.heartbeat()] if changed else []
        return mavlink.MAV_RESULT_ACCEPTED, out

    def _arm_disarm(self, v: SimVehicle, arm: bool, force: bool, t_s: float) -> int:
        if arm:
            self.arm(v, t_s)
            return int(mavlink.MAV_RESULT_ACCEPTED)
        if v.in_air and not force:
            return int(mavlink.MAV_RESULT_DENIED)
        v.disarm()
        return int(mavlink.MAV_RESULT_ACCEPTED)

    def _do_set_mode(
        self, v: SimVehicle, base_mode: int, main: int, sub: int, t_s: float, wall_s: float
    ) -> tuple[int, list[Outgoing]]:
        if not base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return mavlink.MAV_RESULT_DENIED, []
        mode = _MODES_BY_CUSTOM.get((main, sub))
        if main == mavutil.PX4_CUSTOM_MAIN_MODE_OFFBOARD:
            mode = OFFBOARD
        if mode is None:
            return mavlink.MAV_RESULT_DENIED, []
        if mode is OFFBOARD and (
            self.offboard_setpoint is None or self._offboard_lost(t_s, wall_s)
        ):
            return mavlink.MAV_RESULT_DENIED, [
                v.statustext(mavlink.MAV_SEVERITY_CRITICAL, "Offboard denied: no setpoints")
            ]
        if mode is TAKEOFF and not v.armed:
            return mavlink.MAV_RESULT_DENIED, []
        return self._enter(v, mode, t_s)

    def _reposition(
        self, v: SimVehicle, p: tuple[float, ...], t_s: float
    ) -> tuple[int, list[Outgoing]]:
        """Hold (loiter) at a latitude/longitude, as PX4 does for MAV_CMD_DO_REPOSITION."""
        lat, lon = p[4], p[5]
        if not (v.in_air and math.isfinite(lat) and math.isfinite(lon)):
            return mavlink.MAV_RESULT_DENIED, []
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            return mavlink.MAV_RESULT_DENIED, []
        east, north = v.local_of(lat, lon)
        changed = v.mode is not HOLD
        if changed and self._trim_in_offboard:
            v.cruise_speed_m_s = self.trim_airspeed_m_s  # Loiter::on_activation
        if math.isfinite(p[0]) and p[0] > 0.0:
            self._apply_speed(v, p[0])
        v.mode = HOLD
        self._mode_entered_t_s = t_s
        v.command = v.loiter_at(east, north)
        return mavlink.MAV_RESULT_ACCEPTED, [v.heartbeat()] if changed else []

    def _change_speed(self, v: SimVehicle, speed_m_s: float) -> int:
        """MAV_CMD_DO_CHANGE_SPEED: ACCEPTED; in OFFBOARD (real PX4) it changes nothing."""
        if not (self._trim_in_offboard and v.mode is OFFBOARD):
            self._apply_speed(v, speed_m_s)
        return int(mavlink.MAV_RESULT_ACCEPTED)

    def _apply_speed(self, v: SimVehicle, speed_m_s: float) -> None:
        """The AUTO modes' cruising speed (<= 0 or NaN: back to trim)."""
        limits = v.config.limits
        if not (math.isfinite(speed_m_s) and speed_m_s > 0.0):
            v.cruise_speed_m_s = self.trim_airspeed_m_s
        else:
            v.cruise_speed_m_s = limits.clamp_speed(speed_m_s)
        cmd = v.command
        if isinstance(cmd, LoiterCommand) and v.mode is not OFFBOARD:
            v.command = LoiterCommand(
                cmd.center_east_m,
                cmd.center_north_m,
                cmd.radius_m,
                cmd.clockwise,
                v.cruise_speed_m_s,
            )

    # ---- parameters --------------------------------------------------------------------------

    def _param(self, v: SimVehicle, name: str) -> float:
        if name == PARAM_OFFBOARD_LOSS_TIMEOUT:
            return self.offboard_timeout_s
        if name == PARAM_OFFBOARD_LOSS_ACTION:
            return _PX4_RETURN_ACTION if self.failsafe_action == "return" else _PX4_HOLD_ACTION
        if name == PARAM_CRUISE_SPEED:
            return self.trim_airspeed_m_s
        if name == PARAM_AIRSPEED_MIN:
            return v.config.limits.min_speed_m_s
        if name == PARAM_AIRSPEED_MAX:
            return v.config.limits.max_speed_m_s
        return v.loiter_radius_m

    def _set_param(self, v: SimVehicle, name: str, wire_value: float) -> None:
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
            self.set_trim_airspeed(v, wire_value)
        elif name == PARAM_LOITER_RADIUS and wire_value >= 1.05 * v.config.min_turn_radius_m:
            v.loiter_radius_m = wire_value

    def set_trim_airspeed(self, v: SimVehicle, speed_m_s: float) -> None:
        """FW_AIRSPD_TRIM, within the airspeed limits: flown in OFFBOARD from the next step, and
        in the AUTO modes where no cruising speed was commanded."""
        old = self.trim_airspeed_m_s
        self.trim_airspeed_m_s = v.config.limits.clamp_speed(speed_m_s)
        if not self._trim_in_offboard or v.cruise_speed_m_s == old:
            self._apply_speed(v, self.trim_airspeed_m_s)

    def _param_value(self, v: SimVehicle, name: str) -> Outgoing:
        names = list(_PARAM_TYPES)
        kind = _PARAM_TYPES[name]
        value = self._param(v, name)
        if kind == mavlink.MAV_PARAM_TYPE_INT32:
            value = struct.unpack("<f", struct.pack("<i", int(value)))[0]
        return AUTOPILOT_COMPONENT, mavlink.MAVLink_param_value_message(
            name.encode("ascii"), value, kind, len(names), names.index(name)
        )

    # ---- outgoing ----------------------------------------------------------------------------

    def heartbeat(self, v: SimVehicle) -> mavlink.MAVLink_message:
        return telemetry.heartbeat(v.mode.custom_mode, v.armed)

    def timesync_answer(self, tc1: int, ts1: int) -> mavlink.MAVLink_message:
        return Px4TimesyncAnswer(tc1, ts1)

    def autopilot_version(self, v: SimVehicle) -> mavlink.MAVLink_message:
        return telemetry.autopilot_version(v.system_id)


#: the target bytes real PX4 v1.16 SITL's answers carried (uninitialised stack; seen in every
#: answer of a real run's tlog: 88, 28)
PX4_TIMESYNC_TARGET: Final = (88, 28)


class Px4TimesyncAnswer(mavlink.MAVLink_timesync_message):  # type: ignore[misc]
    """PX4 v1.16's answer to a TIMESYNC request: mavlink_timesync.cpp ``handle_message`` fills
    only tc1 and ts1 of a ``mavlink_timesync_t`` on the stack, so the MAVLink 2 extension
    fields target_system / target_component go out as whatever was there (88, 28 in a real
    run), and a MAVLink library that knows them (MAVSDK's) takes the answer for another
    system's and drops it. pymavlink's dialect here has no such fields, so they are appended
    to the payload by hand."""

    def pack(self, mav: mavlink.MAVLink, force_mavlink1: bool = False) -> bytes:
        payload = self.unpacker.pack(self.tc1, self.ts1) + bytes(PX4_TIMESYNC_TARGET)
        return bytes(self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1))
