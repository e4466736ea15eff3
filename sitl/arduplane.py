"""One simulated ArduPlane: its heartbeat, flight modes, GUIDED slew commands and GCS failsafe.

The ArduPlane personality over one ``sitl.vehicle.SimVehicle`` airframe (select it with
``SimConfig(autopilot="arduplane")``). What it answers was read off ArduPilot's source
(docs/simulator.md lists the files): mode numbers of ArduPlane/mode.h; HEARTBEAT of
GCS_MAVLink_Plane.cpp (``base_mode``, ``custom_mode`` = the mode number); DO_SET_MODE of
GCS_Common.cpp ``_set_mode_common`` (a mode it cannot enter is MAV_RESULT_FAILED); the
MAV_CMD_GUIDED_CHANGE_HEADING / _SPEED / _ALTITUDE checks of
``handle_command_int_guided_slew_commands``; NAV_TAKEOFF refused unless a QuadPlane; the GCS
failsafe of ``check_long_failsafe`` / ``failsafe_long_on_event``, driven by the parameters that
configure it (SYSID_MYGCS, FS_GCS_ENABL, FS_LONG_ACTN, FS_LONG_TIMEOUT), which are read and set
over MAVLink as ArduPilot's GCS_Param.cpp serves them.

Where it matters to the mission it does what ArduPlane 4.6.2 does (each a ``SimConfig`` option
whose default is the real behaviour):

- Telemetry rates (``arduplane_stream_rate_hz``): with no request every stream group runs at its
  SRn_* rate, 1 Hz as shipped (ArduPlane/GCS_Mavlink.cpp ``GCS_MAVLINK_Parameters::var_info``,
  the groups of ``all_stream_entries``): SYS_STATUS and GPS_RAW_INT (EXT_STAT),
  GLOBAL_POSITION_INT and LOCAL_POSITION_NED (POSITION), ATTITUDE (EXTRA1), VFR_HUD (EXTRA2),
  BATTERY_STATUS (EXTRA3); EXTENDED_SYS_STATE, HOME_POSITION and ATTITUDE_QUATERNION only on
  request. MAV_CMD_SET_MESSAGE_INTERVAL sets one message's interval (GCS_Common.cpp
  ``set_message_interval``: 0 back to its group's rate, -1 off); REQUEST_DATA_STREAM sets a
  group's rate (GCS_Param.cpp ``handle_request_data_stream``, start_stop 0 stops it).
- GUIDED's heading loop (``arduplane_guided_heading = "pid"``, mode_guided.cpp
  ``ModeGuided::update``): after MAV_CMD_GUIDED_CHANGE_HEADING the bank is GUIDED_P (centidegrees
  of bank per radian of course-over-ground error; Parameters.h ``guidedHeading``, 5000) times the
  error, limited to atan(param3 / g) (param3 the lateral acceleration limit, at least 0.05 m/s^2)
  and to ROLL_LIMIT_DEG (45; LIM_ROLL_CD before 4.5); the turn is the coordinated one,
  course rate = g tan(bank) / V. At 14 m/s the small-error gain is about 0.6 /s, not 1 /s.
- The turn at a bank (``arduplane_turn_efficiency``, 0.70): real ArduPlane 4.6.2 SITL (its plane
  model, stock plane.parm, GUIDED) turned at 0.70 of g tan(bank) / V (median over three
  aircraft, 0.65-0.73 in every 3 m/s airspeed band from 9 to 22 m/s, against ATTITUDE's roll and
  VFR_HUD's airspeed), so every mode's turn here is eta g tan(bank) / V and ATTITUDE reports
  the bank that turn takes, atan(V rate / (eta g)).
  The bank reaches the demanded one through the roll controller, whose angle loop is first
  order with RLL2SRV_TCONST (0.5 s; libraries/APM_Control/AP_RollController.cpp: desired
  roll rate = angle error / tau), so the loop lags the course command by about half a second.
- The airspeed in GUIDED (``arduplane_speed_time_constant_s``, 4 s): real ArduPlane 4.6.2 SITL's
  VFR_HUD airspeed followed GUIDED_CHANGE_SPEED about 3 s late (the RMS difference from the
  command was least, 1.1-1.2 m/s against 1.6 at no lag, with the command 3 s earlier; a
  first-order fit gave 5-6 s with the 2 m/s^2 slew in it): TECS trades speed and height
  slowly. Here the speed flown follows the slewed target through a first-order lag of that
  time constant.
- GCS failsafe (``arduplane_gcs_seen_at_boot``): the last heartbeat from SYSID_MYGCS starts at
  the autopilot's boot (ArduPlane/system.cpp ``init_ardupilot``: "reset last heartbeat time"),
  so FS_GCS_ENABL set more than FS_LONG_TIMEOUT after boot, before a heartbeat from the GCS has
  been counted, trips it at once (system.cpp ``check_long_failsafe``). It says "GCS Failsafe On:
  <mode>" and "GCS Failsafe Off" (events.cpp ``failsafe_long_on_event`` / ``_off_event``).
- GUIDED entered (``arduplane_guided_rebase``): the guided waypoint is the current location,
  altitude included (mode_guided.cpp ``ModeGuided::_enter``: ``set_guided_WP(current_loc)``), so
  GUIDED entered on the take-off climb holds that low altitude.
- Take-off (``takeoff = "runway"``): TAKEOFF while armed starts a ground roll and a climb to the
  vehicle's altitude (see ``sitl.vehicle``), loitering 200 m ahead.
"""

import logging
import math
from dataclasses import dataclass, replace
from typing import Final

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from app.core.frames import wrap_pi
from app.core.plant import heading_for_ground_course
from sitl.config import SimConfig, VehicleConfig
from sitl.guidance import (
    Command,
    CourseCommand,
    LoiterCommand,
    VelocityCommand,
    guide,
)
from sitl.telemetry import GRAVITY_M_S2
from sitl.vehicle import (
    ARM_DISARM_FORCE,
    AUTOPILOT_COMPONENT,
    FlightMode,
    Outgoing,
    SilenceTimer,
    SimVehicle,
    StreamTable,
    as_int,
    param_id_text,
)

log = logging.getLogger(__name__)

#: GUIDED_CHANGE_HEADING's param3 below this is taken as this (m/s^2): ``MAX(param3, 0.05f)``
MIN_LATERAL_ACCEL_M_S2: Final = 0.05
#: TECS_CLMB_MAX and TECS_SINK_MIN/MAX defaults are about 5 m/s: the airframe's climb limit
MAX_CLIMB_RATE_M_S: Final = 5.0
#: GUIDED_CHANGE_ALTITUDE's param3 0 is taken as this vertical rate (m/s; "pick a large value")
UNLIMITED_ALT_RATE_M_S: Final = 1000.0
#: ModeGuided::update_target_altitude runs at 10 Hz (the adjust_altitude_target task)
ALT_TARGET_PERIOD_S: Final = 0.1
#: TECS_TIME_CONST default (s): TECS closes a height error with about this time constant
TECS_TIME_CONSTANT_S: Final = 5.0
#: TKOFF_DIST default: TAKEOFF mode loiters this far ahead of the launch point (m)
TAKEOFF_LOITER_DISTANCE_M: Final = 200.0
#: GCS heartbeats come at a wall-clock rate (MAVSDK: 1 Hz), so the failsafe also waits this
#: much wall time of silence (the offboard failsafe's reason, see SimConfig)
GCS_FAILSAFE_MIN_WALL_S: Final = 2.5
FAILSAFE_GCS: Final = 3  # failsafe_state in ArduPlane/defines.h
MODE_REASON_GCS_FAILSAFE: Final = 5  # ModeReason::GCS_FAILSAFE (AP_Vehicle/ModeReason.h)

# The ArduPlane parameters the personality honours (ArduPlane/Parameters.cpp and Parameters.h),
# in PARAM_REQUEST_LIST order, with the MAV_PARAM_TYPE of the AP_Param each is stored as.
# ArduPilot sends that type in PARAM_VALUE with the value C-cast to the float field
# (GCS_MAVLINK::mav_param_type, cast_to_float) and takes PARAM_SET values the same way,
# whatever param_type the sender gives (AP_Param::set_float).
PARAM_SYSID_MYGCS: Final = "SYSID_MYGCS"  # AP_Int16, default 255: whose heartbeats count
PARAM_FS_GCS_ENABL: Final = "FS_GCS_ENABL"  # AP_Int8: 0 off, 1 heartbeat, 2 + REMRSSI, 3 AUTO only
PARAM_FS_LONG_ACTN: Final = "FS_LONG_ACTN"  # AP_Int8: 0 continue, 1 RTL, 2 glide, 3 parachute, ...
PARAM_FS_LONG_TIMEOUT: Final = "FS_LONG_TIMEOUT"  # AP_Float, s
# the airspeed range GUIDED_CHANGE_SPEED accepts (aparm.airspeed_min / _max, AP_Int16, m/s;
# named ARSPD_FBW_MIN / _MAX before ArduPilot 4.5): the vehicle's speed limits
PARAM_AIRSPEED_MIN: Final = "AIRSPEED_MIN"
PARAM_AIRSPEED_MAX: Final = "AIRSPEED_MAX"
# GUIDED's heading PID's P (AP_Float, centidegrees of bank per radian; Parameters.h
# ``guidedHeading{5000.0, ...}``) and the bank limit (aparm.roll_limit, AP_Float, degrees)
PARAM_GUIDED_P: Final = "GUIDED_P"
#: the roll controller's time constant (s; AP_RollController ``gains.tau``, "RLL2SRV_TCONST")
ROLL_TIME_CONSTANT_S: Final = 0.5
PARAM_ROLL_LIMIT_DEG: Final = "ROLL_LIMIT_DEG"
GUIDED_P_DEFAULT: Final = 5000.0
ROLL_LIMIT_DEG_DEFAULT: Final = 45.0
PARAM_TYPES: Final = {
    PARAM_SYSID_MYGCS: mavlink.MAV_PARAM_TYPE_INT16,
    PARAM_FS_GCS_ENABL: mavlink.MAV_PARAM_TYPE_INT8,
    PARAM_FS_LONG_ACTN: mavlink.MAV_PARAM_TYPE_INT8,
    PARAM_FS_LONG_TIMEOUT: mavlink.MAV_PARAM_TYPE_REAL32,
    PARAM_AIRSPEED_MIN: mavlink.MAV_PARAM_TYPE_INT16,
    PARAM_AIRSPEED_MAX: mavlink.MAV_PARAM_TYPE_INT16,
    PARAM_GUIDED_P: mavlink.MAV_PARAM_TYPE_REAL32,
    PARAM_ROLL_LIMIT_DEG: mavlink.MAV_PARAM_TYPE_REAL32,
}
# ArduPilot 4.7 renamed SYSID_MYGCS to MAV_GCS_SYSID (libraries/GCS_MAVLink/GCS.cpp, default
# 255) and added MAV_GCS_SYSID_HI (default 0): when HI >= MAV_GCS_SYSID every system id from
# MAV_GCS_SYSID to HI is a GCS, else only MAV_GCS_SYSID (GCS::sysid_is_gcs)
PARAM_MAV_GCS_SYSID: Final = "MAV_GCS_SYSID"
PARAM_MAV_GCS_SYSID_HI: Final = "MAV_GCS_SYSID_HI"
PARAM_TYPES_4_7: Final = {
    PARAM_MAV_GCS_SYSID: mavlink.MAV_PARAM_TYPE_INT16,
    PARAM_MAV_GCS_SYSID_HI: mavlink.MAV_PARAM_TYPE_INT16,
    **{name: kind for name, kind in PARAM_TYPES.items() if name != PARAM_SYSID_MYGCS},
}
_INT_RANGES: Final = {
    mavlink.MAV_PARAM_TYPE_INT8: (-128, 127),
    mavlink.MAV_PARAM_TYPE_INT16: (-32768, 32767),
}
#: PARAM_VALUE.param_index -1 (65535 on the wire): the answer to a read by name and the
#: confirmation of a PARAM_SET (GCS::send_parameter_value)
PARAM_INDEX_NONE: Final = 65535
# FS_GCS_ENABL values (GCS_FAILSAFE_* in ArduPlane/defines.h)
GCS_FAILSAFE_HEARTBEAT: Final = 1
GCS_FAILSAFE_HB_RSSI: Final = 2
GCS_FAILSAFE_HB_AUTO: Final = 3
# FS_LONG_ACTN values (FS_ACTION_LONG_* in ArduPlane/defines.h)
FS_ACTION_LONG_CONTINUE: Final = 0
FS_ACTION_LONG_RTL: Final = 1
FS_ACTION_LONG_GLIDE: Final = 2
FS_ACTION_LONG_PARACHUTE: Final = 3
FS_ACTION_LONG_AUTO: Final = 4


@dataclass(frozen=True, slots=True)
class ArduPlaneMode:
    """An ArduPlane flight mode: HEARTBEAT.custom_mode is its number (ArduPlane/mode.h)."""

    name: str
    number: int

    @property
    def custom_mode(self) -> int:
        return self.number


def _plane_mode(number: int) -> ArduPlaneMode:
    """The mode with this number, named as pymavlink's ArduPlane mode mapping names it."""
    return ArduPlaneMode(mavutil.mode_mapping_apm[number].lower(), number)


MANUAL: Final = _plane_mode(mavlink.PLANE_MODE_MANUAL)
CIRCLE: Final = _plane_mode(mavlink.PLANE_MODE_CIRCLE)
AUTO: Final = _plane_mode(mavlink.PLANE_MODE_AUTO)
RTL: Final = _plane_mode(mavlink.PLANE_MODE_RTL)
LOITER: Final = _plane_mode(mavlink.PLANE_MODE_LOITER)
TAKEOFF: Final = _plane_mode(mavlink.PLANE_MODE_TAKEOFF)
GUIDED: Final = _plane_mode(mavlink.PLANE_MODE_GUIDED)
_NAMED: Final = {m.number: m for m in (MANUAL, CIRCLE, AUTO, RTL, LOITER, TAKEOFF, GUIDED)}
#: fixed-wing modes of ArduPlane/mode.h that are not named above (entered, flown straight on)
_OTHER_MODES: Final = frozenset(
    {
        mavlink.PLANE_MODE_STABILIZE,
        mavlink.PLANE_MODE_TRAINING,
        mavlink.PLANE_MODE_ACRO,
        mavlink.PLANE_MODE_FLY_BY_WIRE_A,
        mavlink.PLANE_MODE_FLY_BY_WIRE_B,
        mavlink.PLANE_MODE_CRUISE,
        mavlink.PLANE_MODE_AUTOTUNE,
        mavlink.PLANE_MODE_AVOID_ADSB,
        mavlink.PLANE_MODE_THERMAL,
    }
)
#: QuadPlane modes (refused: this is not a QuadPlane) and numbers ArduPlane has not
#: (9, 16 = INITIALISING, > 25) are refused with MAV_RESULT_FAILED
_LOITERING: Final = (CIRCLE, AUTO, LOITER)
#: Mode::is_guided_mode(): GUIDED, AVOID_ADSB
_GUIDED_LIKE: Final = {GUIDED.number, mavlink.PLANE_MODE_AVOID_ADSB}
#: modes in which failsafe_long_on_event does what FS_LONG_ACTN says only if it is not 0
#: (continue): AUTO, AVOID_ADSB, GUIDED; every other fixed-wing mode but RTL returns on 0 too
_FAILSAFE_AUTO_MODES: Final = {AUTO.number, mavlink.PLANE_MODE_AVOID_ADSB, GUIDED.number}
#: modes whose HEARTBEAT base_mode is "stabilize" (GCS_MAVLINK_Plane::base_mode)
_STABILIZE_MODES: Final = (
    mavlink.PLANE_MODE_STABILIZE,
    mavlink.PLANE_MODE_FLY_BY_WIRE_A,
    mavlink.PLANE_MODE_FLY_BY_WIRE_B,
    mavlink.PLANE_MODE_CRUISE,
    mavlink.PLANE_MODE_AUTOTUNE,
)

_ALT_FRAMES_RELATIVE: Final = {
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT,  # flat terrain at the origin: terrain = relative
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
}
_ALT_FRAMES_ABSOLUTE: Final = {mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT}

# HEARTBEAT.base_mode bits (GCS_MAVLINK_Plane::base_mode)
_CUSTOM: Final = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
_GUIDED_FLAG: Final = mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
_STABILIZE: Final = mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
_MANUAL_INPUT: Final = mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED  # STICK_MIXING default
_ARMED: Final = mavlink.MAV_MODE_FLAG_SAFETY_ARMED

ARDUPILOT_CAPABILITIES: Final = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
)
ARDUPLANE_VERSION: Final = (4 << 24) | (5 << 16) | (7 << 8) | 255  # reports ArduPlane 4.5.7

# The stream groups (ArduPlane/GCS_Mavlink.cpp STREAM_*_msgs) of the messages the airframe sends,
# by MAV_DATA_STREAM id; messages in no group are sent only on request
_M = mavlink
STREAM_GROUPS: Final[dict[int, tuple[int, ...]]] = {
    _M.MAV_DATA_STREAM_EXTENDED_STATUS: (
        _M.MAVLINK_MSG_ID_SYS_STATUS,
        _M.MAVLINK_MSG_ID_GPS_RAW_INT,
    ),
    _M.MAV_DATA_STREAM_POSITION: (
        _M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
        _M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
    ),
    _M.MAV_DATA_STREAM_EXTRA1: (_M.MAVLINK_MSG_ID_ATTITUDE,),
    _M.MAV_DATA_STREAM_EXTRA2: (_M.MAVLINK_MSG_ID_VFR_HUD,),
    # (Plane's EXTRA3 also carries WIND: its AHRS wind estimate)
    _M.MAV_DATA_STREAM_EXTRA3: (_M.MAVLINK_MSG_ID_BATTERY_STATUS, _M.MAVLINK_MSG_ID_WIND),
}
_ON_REQUEST_ONLY: Final = (
    _M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
    _M.MAVLINK_MSG_ID_HOME_POSITION,
    _M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
)


def arduplane_streams(rate_hz: float) -> StreamTable:
    """What ArduPlane streams unasked with every SRn_* rate at ``rate_hz`` (0: nothing but the
    heartbeat, which ArduPilot always sends at 1 Hz)."""
    interval = 1.0 / rate_hz if rate_hz > 0.0 else -1.0
    table: StreamTable = {_M.MAVLINK_MSG_ID_HEARTBEAT: 1.0}
    for ids in STREAM_GROUPS.values():
        table.update(dict.fromkeys(ids, interval))
    table.update(dict.fromkeys(_ON_REQUEST_ONLY, -1.0))
    return table


def long_failsafe_mode(mode_number: int, action: int) -> int | None:
    """The mode ArduPlane's ``failsafe_long_on_event`` switches to from ``mode_number`` when
    FS_LONG_ACTN is ``action``; None when it stays (parachute and AUTOLAND are not imitated:
    the parachute leaves the mode alone, AUTOLAND is taken as its RTL fallback)."""
    if action == FS_ACTION_LONG_PARACHUTE:
        return None
    if mode_number == RTL.number:
        return AUTO.number if action == FS_ACTION_LONG_AUTO else None
    if action == FS_ACTION_LONG_GLIDE:
        return int(mavlink.PLANE_MODE_FLY_BY_WIRE_A)
    if action == FS_ACTION_LONG_AUTO:
        return AUTO.number
    if mode_number in _FAILSAFE_AUTO_MODES and action == FS_ACTION_LONG_CONTINUE:
        return None
    return RTL.number


def param_value_from_wire(kind: int, wire_value: float) -> float:
    """A PARAM_SET value as AP_Param::set_float stores it: integer types get 0.01 added away
    from zero, are clamped to their range and truncated."""
    limits = _INT_RANGES.get(kind)
    if limits is None:
        return wire_value
    nudged = wire_value + (0.01 if wire_value >= 0.0 else -0.01)
    return float(int(max(limits[0], min(limits[1], nudged))))


def mode_by_number(number: int) -> ArduPlaneMode | None:
    """The fixed-wing ArduPlane mode with this number, None for QuadPlane or unknown ones."""
    if number in _NAMED:
        return _NAMED[number]
    return _plane_mode(number) if number in _OTHER_MODES else None


class ArduPlaneAutopilot:
    """ArduPlane (plain fixed wing, no QuadPlane) behind one simulated airframe.

    It boots in MANUAL on the ground. Arming does not launch it (a real one needs throttle);
    entering TAKEOFF while armed (or arming in TAKEOFF) launches it, as a catapult would, and it
    loiters 200 m ahead at its altitude, staying in TAKEOFF. GUIDED flies, from the moment it
    is entered, a loiter where it is until MAV_CMD_GUIDED_CHANGE_HEADING gives it a course over
    ground; the guided targets last until the mode changes. It takes no offboard setpoints.
    ``params`` holds the failsafe parameters and the airspeed range (``PARAM_TYPES``), read
    live by the failsafe and GUIDED_CHANGE_SPEED.
    """

    def __init__(self, config: VehicleConfig, sim: SimConfig, boot_offset_s: float = 0.0) -> None:
        self._origin_alt_m = sim.origin_alt_m
        self._streams = arduplane_streams(sim.arduplane_stream_rate_hz)
        self._heading_pid = sim.arduplane_guided_heading == "pid"
        self._turn_efficiency = sim.arduplane_turn_efficiency
        self._speed_tau_s = sim.arduplane_speed_time_constant_s
        #: the airspeed TECS is bringing the airframe to (m/s), lagging GUIDED's target
        self._tecs_speed_m_s: float | None = None
        #: the bank the airframe flies (rad, > 0 right), lagging GUIDED's demand
        self._bank_rad = 0.0
        self._rebase = sim.arduplane_guided_rebase
        self._reset_guided()
        failsafe = sim.gcs_failsafe
        new_names = sim.gcs_sysid_param == PARAM_MAV_GCS_SYSID
        #: the parameters served and their MAV_PARAM_TYPE (ArduPilot 4.7 names or the older ones)
        self.param_types: dict[str, int] = dict(PARAM_TYPES_4_7 if new_names else PARAM_TYPES)
        gcs_ids: dict[str, float] = (
            {PARAM_MAV_GCS_SYSID: float(sim.gcs_system_id), PARAM_MAV_GCS_SYSID_HI: 0.0}
            if new_names
            else {PARAM_SYSID_MYGCS: float(sim.gcs_system_id)}
        )
        self.params: dict[str, float] = {
            **gcs_ids,
            PARAM_FS_GCS_ENABL: 0.0 if failsafe == "off" else float(GCS_FAILSAFE_HEARTBEAT),
            PARAM_FS_LONG_ACTN: float(
                FS_ACTION_LONG_RTL if failsafe == "return" else FS_ACTION_LONG_CONTINUE
            ),
            PARAM_FS_LONG_TIMEOUT: sim.gcs_failsafe_timeout_s,
            # whole m/s (AP_Int16) within the vehicle's own speed range
            PARAM_AIRSPEED_MIN: float(math.ceil(config.limits.min_speed_m_s)),
            PARAM_AIRSPEED_MAX: float(math.floor(config.limits.max_speed_m_s)),
            PARAM_GUIDED_P: GUIDED_P_DEFAULT,
            PARAM_ROLL_LIMIT_DEG: ROLL_LIMIT_DEG_DEFAULT,
        }
        #: parameters whose PARAM_SET is refused as ArduPilot refuses one it may not take over
        #: MAVLink (``allow_set_via_mavlink`` false): "Param write denied" and the old value
        self.param_write_denied: frozenset[str] = frozenset()
        self.gcs_failsafe_active = False
        self._gcs_heard = SilenceTimer()
        if sim.arduplane_gcs_seen_at_boot:  # init_ardupilot: sysid_myggcs_seen(millis())
            self._gcs_heard.heard(-boot_offset_s, -math.inf)
        #: modes the GCS may not enter (FLTMODE_GCSBLOCK); a test sets it to refuse a mode
        self.gcs_blocked_modes: frozenset[int] = frozenset()

    def _reset_guided(self) -> None:
        """Mode::enter resets the guided slew targets on every mode change."""
        self._guided_course_rad: float | None = None
        self._guided_lateral_accel_m_s2 = MIN_LATERAL_ACCEL_M_S2
        self._guided_speed_m_s: float | None = None
        self._guided_accel_m_s2 = math.inf
        self._guided_altitude_m: float | None = None
        #: the vertical rate of the last GUIDED_CHANGE_ALTITUDE (m/s); None: no slew commanded
        self._guided_alt_rate_m_s: float | None = None

    # ---- state -------------------------------------------------------------------------------

    @property
    def boot_mode(self) -> FlightMode:
        return MANUAL

    @property
    def trim_throttle(self) -> float:
        """TRIM_THROTTLE: the cruise throttle (ArduPlane default 45 %)."""
        return 0.45

    @property
    def turn_efficiency(self) -> float:
        return self._turn_efficiency

    @property
    def stream_defaults(self) -> StreamTable:
        return self._streams

    @property
    def guided_targets(self) -> tuple[float | None, float | None, float | None]:
        """(course over ground rad, airspeed m/s, altitude m) set by the guided slew commands."""
        return self._guided_course_rad, self._guided_speed_m_s, self._guided_altitude_m

    # ---- modes -------------------------------------------------------------------------------

    def _set_mode(self, v: SimVehicle, mode: FlightMode, t_s: float) -> None:
        assert isinstance(mode, ArduPlaneMode), mode
        if mode != v.mode:
            self._reset_guided()
            if mode == GUIDED and self._rebase and v.in_air:
                # set_guided_WP(current_loc): the altitude it was entered at
                self._guided_altitude_m = v.air_altitude_m
                v.altitude_target_m = v.air_altitude_m
                v.climb_rate_m_s = MAX_CLIMB_RATE_M_S
        v.mode = mode
        v.command = self._mode_command(v, mode)

    def _mode_command(
        self, v: SimVehicle, mode: ArduPlaneMode
    ) -> LoiterCommand | VelocityCommand | None:
        if not v.in_air:
            return None
        if mode in _LOITERING or mode == GUIDED:
            return v.hold_here()  # GUIDED: set_guided_WP(current location)
        if mode == RTL:
            return v.loiter_at(v.home_east_m, v.home_north_m)
        if mode == TAKEOFF:
            course = v.state.course_rad
            return v.loiter_at(
                v.home_east_m + TAKEOFF_LOITER_DISTANCE_M * math.sin(course),
                v.home_north_m + TAKEOFF_LOITER_DISTANCE_M * math.cos(course),
            )
        return VelocityCommand(v.state.course_rad, v.cruise_speed_m_s)  # straight on

    def _change_mode(self, v: SimVehicle, number: int, t_s: float) -> tuple[int, list[Outgoing]]:
        """Plane::set_mode for a GCS request: MAV_RESULT_FAILED when it cannot be entered."""
        mode = mode_by_number(number)
        if mode is None:
            return mavlink.MAV_RESULT_FAILED, []
        if number in self.gcs_blocked_modes and mode != v.mode:
            text = (
                f"Mode change to {mode.name.upper()} denied, GCS entry disabled (FLTMODE_GCSBLOCK)"
            )
            return mavlink.MAV_RESULT_FAILED, [v.statustext(mavlink.MAV_SEVERITY_NOTICE, text)]
        changed = mode != v.mode
        if changed:
            self._set_mode(v, mode, t_s)
        if mode == TAKEOFF and v.armed and not v.in_air:
            v.take_off(t_s)
        return mavlink.MAV_RESULT_ACCEPTED, [v.heartbeat()] if changed else []

    def arm(self, v: SimVehicle, t_s: float) -> None:
        """Arm; only TAKEOFF mode launches (in MANUAL the throttle is the pilot's)."""
        if v.armed:
            return
        v.armed = True
        if v.mode == TAKEOFF:
            v.take_off(t_s)

    def launched(self, v: SimVehicle, t_s: float) -> None:
        """Launched (in TAKEOFF): fly the current mode from there."""
        assert isinstance(v.mode, ArduPlaneMode), v.mode
        v.command = self._mode_command(v, v.mode)

    # ---- incoming ----------------------------------------------------------------------------

    def handle(
        self, v: SimVehicle, msg: mavlink.MAVLink_message, t_s: float, wall_s: float
    ) -> list[Outgoing]:
        """The GCS's heartbeats and the parameter protocol; offboard setpoints are ignored."""
        msg_id = msg.get_msgId()
        if msg_id == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            return self._on_gcs_heartbeat(v, msg, t_s, wall_s)
        if msg_id == mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED:
            return []  # no offboard setpoints (only LOCAL_OFFSET_NED altitude in GUIDED)
        if msg_id == mavlink.MAVLINK_MSG_ID_REQUEST_DATA_STREAM:
            self._on_request_data_stream(v, msg, t_s)
            return []
        if msg_id in (
            mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_READ,
            mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_LIST,
            mavlink.MAVLINK_MSG_ID_PARAM_SET,
        ):
            if msg.target_component not in (0, AUTOPILOT_COMPONENT):
                return []
            return self._on_param_message(v, msg)
        return []

    def _on_request_data_stream(
        self, v: SimVehicle, msg: mavlink.MAVLink_message, t_s: float
    ) -> None:
        """GCS_Param.cpp handle_request_data_stream: a group's rate (start_stop 0: stop it;
        MAV_DATA_STREAM_ALL: every group)."""
        if msg.target_component not in (0, AUTOPILOT_COMPONENT) or msg.start_stop not in (0, 1):
            return
        rate_hz = float(msg.req_message_rate) if msg.start_stop == 1 else 0.0
        stream = msg.req_stream_id
        if stream == mavlink.MAV_DATA_STREAM_ALL:
            groups = list(STREAM_GROUPS.values())
        elif stream in STREAM_GROUPS:
            groups = [STREAM_GROUPS[stream]]
        else:
            return
        interval = 1.0 / rate_hz if rate_hz > 0.0 else -1.0
        for ids in groups:
            for msg_id in ids:
                v.set_stream(msg_id, interval, t_s)

    # ---- parameters (GCS_Param.cpp) ----------------------------------------------------------

    def _on_param_message(self, v: SimVehicle, msg: mavlink.MAVLink_message) -> list[Outgoing]:
        """PARAM_REQUEST_LIST: every parameter; PARAM_REQUEST_READ: by index, or by name when the
        index is -1 (answered with index -1); PARAM_SET: the value stored as its type, confirmed
        with PARAM_VALUE. Unknown names, bad indices and non-finite values get no answer."""
        msg_id = msg.get_msgId()
        types = self.param_types
        names = list(types)
        if msg_id == mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_LIST:
            return [self._param_value_message(v, name, names.index(name)) for name in names]
        if msg_id == mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_READ:
            index = msg.param_index
            if index != -1:
                known = 0 <= index < len(names)
                return [self._param_value_message(v, names[index], index)] if known else []
            name = param_id_text(msg.param_id)
            known = name in types
            return [self._param_value_message(v, name, PARAM_INDEX_NONE)] if known else []
        name = param_id_text(msg.param_id)
        value = float(msg.param_value)
        if name not in types or not math.isfinite(value):
            return []
        if name in self.param_write_denied:
            text = f"Param write denied ({name})"
            return [
                v.statustext(mavlink.MAV_SEVERITY_WARNING, text),
                self._param_value_message(v, name, PARAM_INDEX_NONE),  # the value in force
            ]
        self.params[name] = param_value_from_wire(types[name], value)
        log.info("vehicle %d: %s set to %g", v.system_id, name, self.params[name])
        return [self._param_value_message(v, name, PARAM_INDEX_NONE)]

    def _param_value_message(self, v: SimVehicle, name: str, index: int) -> Outgoing:
        return AUTOPILOT_COMPONENT, mavlink.MAVLink_param_value_message(
            name.encode("ascii"),
            self.params[name],
            self.param_types[name],
            len(self.param_types),
            index,
        )

    def _param_int(self, name: str) -> int:
        return int(self.params[name])

    def is_gcs(self, system_id: int) -> bool:
        """Whether heartbeats from ``system_id`` are the GCS's: SYSID_MYGCS, or from ArduPilot
        4.7 MAV_GCS_SYSID, or the range up to MAV_GCS_SYSID_HI when that is not below it
        (GCS::sysid_is_gcs)."""
        if PARAM_SYSID_MYGCS in self.params:
            return system_id == self._param_int(PARAM_SYSID_MYGCS)
        low, high = self._param_int(PARAM_MAV_GCS_SYSID), self._param_int(PARAM_MAV_GCS_SYSID_HI)
        if high <= low:
            return system_id == low
        return low <= system_id <= high

    def _on_gcs_heartbeat(
        self, v: SimVehicle, msg: mavlink.MAVLink_message, t_s: float, wall_s: float
    ) -> list[Outgoing]:
        """Only the GCS of SYSID_MYGCS counts (GCS_MAVLINK::handle_heartbeat)."""
        if not self.is_gcs(msg.get_srcSystem()):
            return []
        self._gcs_heard.heard(t_s, wall_s)
        if not self.gcs_failsafe_active:
            return []
        self.gcs_failsafe_active = False  # the mode is not changed back (failsafe_long_off_event)
        text = "GCS Failsafe Off"
        log.info("vehicle %d: %s at t=%.2f s", v.system_id, text, t_s)
        return [v.statustext(mavlink.MAV_SEVERITY_WARNING, text)]

    def run_command(
        self,
        v: SimVehicle,
        command: int,
        p: tuple[float, ...],
        t_s: float,
        wall_s: float,
        frame: int | None,
    ) -> tuple[int, list[Outgoing]]:
        failed, accepted = mavlink.MAV_RESULT_FAILED, mavlink.MAV_RESULT_ACCEPTED
        if command in (
            mavlink.MAV_CMD_GUIDED_CHANGE_HEADING,
            mavlink.MAV_CMD_GUIDED_CHANGE_SPEED,
            mavlink.MAV_CMD_GUIDED_CHANGE_ALTITUDE,
        ):
            if frame is None:  # handled in handle_command_int_packet only (see docs)
                return mavlink.MAV_RESULT_UNSUPPORTED, []
            return self._guided_slew(v, command, p, frame), []
        if command == mavlink.MAV_CMD_DO_SET_MODE:
            if not as_int(p[0]) & _CUSTOM:
                return mavlink.MAV_RESULT_DENIED, []
            return self._change_mode(v, as_int(p[1], -1), t_s)
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            # AP_Arming_Plane::arm / disarm: "Throttle armed" / "Throttle disarmed"
            info = mavlink.MAV_SEVERITY_INFO
            if p[0] >= 0.5:
                was = v.armed
                self.arm(v, t_s)
                return accepted, [] if was else [
                    v.statustext(info, "Throttle armed"),
                    v.heartbeat(),
                ]
            if v.in_air and as_int(p[1]) != ARM_DISARM_FORCE:
                return failed, []  # disarming in flight needs the force value
            was = v.armed
            v.disarm()
            return accepted, [v.statustext(info, "Throttle disarmed"), v.heartbeat()] if was else []
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            return failed, []  # handle_command_MAV_CMD_NAV_TAKEOFF: only a QuadPlane takes off so
        if command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self._change_mode(v, RTL.number, t_s)
        if command == mavlink.MAV_CMD_NAV_LOITER_UNLIM:
            return self._change_mode(v, LOITER.number, t_s)
        if command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            if v.mode.custom_mode not in _GUIDED_LIKE | {AUTO.number}:
                return failed, []
            if not (math.isfinite(p[1]) and p[1] > 0.0):
                return failed, []
            self._guided_speed_m_s = v.config.limits.clamp_speed(p[1])
            return accepted, []
        if command == mavlink.MAV_CMD_DO_REPOSITION:
            return self._reposition_guided(v, p, t_s)
        return mavlink.MAV_RESULT_UNSUPPORTED, []

    def _guided_slew(self, v: SimVehicle, command: int, p: tuple[float, ...], frame: int) -> int:
        """handle_command_int_guided_slew_commands: FAILED outside GUIDED, DENIED for bad values."""
        if v.mode != GUIDED:
            return int(mavlink.MAV_RESULT_FAILED)
        denied = int(mavlink.MAV_RESULT_DENIED)
        if command == mavlink.MAV_CMD_GUIDED_CHANGE_HEADING:
            kind, heading_deg, accel = as_int(p[0], -1), p[1], p[2]
            if not (math.isfinite(heading_deg) and 0.0 <= heading_deg < 360.0):
                return denied
            if kind == mavlink.HEADING_TYPE_DEFAULT:
                self._guided_course_rad = None
                return int(mavlink.MAV_RESULT_ACCEPTED)
            if kind != mavlink.HEADING_TYPE_COURSE_OVER_GROUND:
                return denied  # HEADING_TYPE_HEADING is ArduPlane's too, not imitated here
            self._guided_course_rad = wrap_pi(math.radians(heading_deg))
            accel = accel if math.isfinite(accel) else 0.0
            self._guided_lateral_accel_m_s2 = max(accel, MIN_LATERAL_ACCEL_M_S2)
            return int(mavlink.MAV_RESULT_ACCEPTED)
        if command == mavlink.MAV_CMD_GUIDED_CHANGE_SPEED:
            if as_int(p[0], -1) != mavlink.SPEED_TYPE_AIRSPEED:
                return denied
            speed, accel = p[1], p[2]
            low = self.params[PARAM_AIRSPEED_MIN]
            high = self.params[PARAM_AIRSPEED_MAX]
            if not (math.isfinite(speed) and low <= speed <= high):
                return int(mavlink.MAV_RESULT_FAILED)  # outside AIRSPEED_MIN..AIRSPEED_MAX
            self._guided_speed_m_s = speed
            accel = abs(accel) if math.isfinite(accel) else 0.0
            self._guided_accel_m_s2 = math.inf if accel == 0.0 else accel
            return int(mavlink.MAV_RESULT_ACCEPTED)
        altitude, rate = p[6], p[2]
        if not math.isfinite(altitude) or altitude in (0.0, -1.0):
            return denied  # "disallow default value of -1 and dangerous value of zero"
        if frame in _ALT_FRAMES_RELATIVE:
            self._guided_altitude_m = altitude
        elif frame in _ALT_FRAMES_ABSOLUTE:
            self._guided_altitude_m = altitude - self._origin_alt_m
        else:
            return denied
        rate = abs(rate) if math.isfinite(rate) else 0.0
        self._guided_alt_rate_m_s = UNLIMITED_ALT_RATE_M_S if rate == 0.0 else rate
        self._slew_altitude(v)
        return int(mavlink.MAV_RESULT_ACCEPTED)

    def _slew_altitude(self, v: SimVehicle) -> None:
        """ModeGuided::update_target_altitude (4.6): the height TECS is given is the *current*
        altitude moved toward the commanded one by rate x 0.1 s (the task's period), so with a
        rate of a few m/s TECS sees a few decimetres of error and hardly climbs (real 4.6.2 SITL:
        NAV_CONTROLLER_OUTPUT alt_error 0.3 m at rate 3 m/s, 0.05 m/s of climb, 70 m short of
        the command for a whole mission); param3 0 (1000 m/s) gives TECS the command itself.
        TECS closes the error it is given with its time constant, at most at its climb limit."""
        target, rate = self._guided_altitude_m, self._guided_alt_rate_m_s
        if target is None or rate is None:
            return
        step = rate * ALT_TARGET_PERIOD_S
        now = v.air_altitude_m
        interim = max(now - step, min(now + step, target))
        v.altitude_target_m = interim
        v.climb_rate_m_s = min(MAX_CLIMB_RATE_M_S, abs(interim - now) / TECS_TIME_CONSTANT_S)

    def _reposition_guided(
        self, v: SimVehicle, p: tuple[float, ...], t_s: float
    ) -> tuple[int, list[Outgoing]]:
        """DO_REPOSITION: GUIDED, loitering at the point (if asked to change mode, or in GUIDED)."""
        lat, lon = p[4], p[5]
        if not (math.isfinite(lat) and math.isfinite(lon) and -90 <= lat <= 90):
            return mavlink.MAV_RESULT_DENIED, []
        if not (as_int(p[1]) & mavlink.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE or v.mode == GUIDED):
            return mavlink.MAV_RESULT_FAILED, []
        result, out = self._change_mode(v, GUIDED.number, t_s)
        if result != mavlink.MAV_RESULT_ACCEPTED or not v.in_air:
            return result, out
        self._guided_course_rad = None
        east, north = v.local_of(lat, lon)
        v.command = v.loiter_at(east, north)
        return result, out

    # ---- flight ------------------------------------------------------------------------------

    def _gcs_failsafe_armed(self, v: SimVehicle) -> bool:
        """check_long_failsafe: FS_GCS_ENABL 1 or 2 in any mode, 3 only in AUTO (REMRSSI, the
        other half of 2, is not imitated: there is no radio)."""
        enabled = self._param_int(PARAM_FS_GCS_ENABL)
        if enabled in (GCS_FAILSAFE_HEARTBEAT, GCS_FAILSAFE_HB_RSSI):
            return True
        return enabled == GCS_FAILSAFE_HB_AUTO and v.mode == AUTO

    def mode_events(self, v: SimVehicle, t_s: float, wall_s: float) -> list[Outgoing]:
        """The GCS failsafe (check_long_failsafe / failsafe_long_on_event)."""
        heard = self._gcs_heard
        if (
            self.gcs_failsafe_active
            or not heard.ever  # "gcs_last_seen_ms != 0": never before a first heartbeat
            or not self._gcs_failsafe_armed(v)
            or not heard.silent(
                t_s, wall_s, self.params[PARAM_FS_LONG_TIMEOUT], GCS_FAILSAFE_MIN_WALL_S
            )
        ):
            return []
        self.gcs_failsafe_active = True
        target = long_failsafe_mode(v.mode.custom_mode, self._param_int(PARAM_FS_LONG_ACTN))
        mode = None if target is None else mode_by_number(target)
        if mode is not None and mode != v.mode:
            self._set_mode(v, mode, t_s)
        text = f"GCS Failsafe On: {v.mode.name.upper()}"  # the mode it is in now
        log.info("vehicle %d: %s at t=%.2f s", v.system_id, text, t_s)
        out = [v.statustext(mavlink.MAV_SEVERITY_WARNING, text)]
        out.append(v.heartbeat())  # system status CRITICAL, and the mode
        v.next_heartbeat_at(t_s + 1.0)
        return out

    def fly(self, v: SimVehicle, dt_s: float) -> None:
        """One physics step: GUIDED flies the guided targets (course over ground in the wind)."""
        limits = v.config.limits
        command = v.command or v.hold_here()
        if v.mode == GUIDED:
            command = self._guided_command(v, command)
            self._slew_altitude(v)
        course, speed = guide(v.state, command, limits.course_gain_per_s)
        speed_now = max(v.state.speed_m_s, limits.min_speed_m_s)
        if isinstance(command, CourseCommand) and self._heading_pid:
            demand = self.guided_bank_rad(v, command)
            self._bank_rad += (demand - self._bank_rad) * -math.expm1(-dt_s / ROLL_TIME_CONSTANT_S)
            rate = self._turn_efficiency * GRAVITY_M_S2 * math.tan(self._bank_rad) / speed_now
            rate = max(-limits.max_course_rate_rad_s, min(limits.max_course_rate_rad_s, rate))
            course = v.state.course_rad + rate / limits.course_gain_per_s
        elif isinstance(command, CourseCommand):
            course = heading_for_ground_course(
                course, v.state.speed_m_s, v.wind_east_m_s, v.wind_north_m_s
            )
            rate = min(limits.max_course_rate_rad_s, command.max_lateral_accel_m_s2 / speed_now)
            limits = replace(limits, max_course_rate_rad_s=rate)
        if v.mode == GUIDED and self._guided_speed_m_s is not None:
            limits = replace(
                limits, max_accel_m_s2=min(limits.max_accel_m_s2, self._guided_accel_m_s2)
            )
            speed = self._tecs_speed(v, speed, dt_s)
        else:
            self._tecs_speed_m_s = None
        v.step(course, speed, limits, dt_s)
        if not (isinstance(command, CourseCommand) and self._heading_pid):
            # the bank of the turn the other modes fly, where a GUIDED heading loop takes over
            self._bank_rad = math.atan(
                v.state.course_rate_rad_s * speed_now / (self._turn_efficiency * GRAVITY_M_S2)
            )

    def _tecs_speed(self, v: SimVehicle, target_m_s: float, dt_s: float) -> float:
        """The speed TECS flies toward now: the guided target through a first-order lag of
        ``arduplane_speed_time_constant_s`` (none when 0), from the speed flown."""
        if self._speed_tau_s <= 0.0:
            return target_m_s
        lagged = self._tecs_speed_m_s if self._tecs_speed_m_s is not None else v.state.speed_m_s
        lagged += (target_m_s - lagged) * -math.expm1(-dt_s / self._speed_tau_s)
        self._tecs_speed_m_s = lagged
        return lagged

    def guided_bank_rad(self, v: SimVehicle, command: CourseCommand) -> float:
        """ModeGuided::update: bank = GUIDED_P * (course over ground error), limited to
        atan(lateral accel limit / g) and ROLL_LIMIT_DEG (> 0: to the right)."""
        v_north = v.state.v_north_m_s + v.wind_north_m_s
        v_east = v.state.v_east_m_s + v.wind_east_m_s
        ground_course = math.atan2(v_east, v_north)
        error = wrap_pi(command.course_rad - ground_course)
        bank = math.radians(self.params[PARAM_GUIDED_P] * error / 100.0)
        limit = min(
            math.atan(command.max_lateral_accel_m_s2 / GRAVITY_M_S2),
            math.radians(max(self.params[PARAM_ROLL_LIMIT_DEG], 0.0)),
        )
        return max(-limit, min(limit, bank))

    def guided_course_rate_rad_s(self, v: SimVehicle, command: CourseCommand) -> float:
        """The turn at the GUIDED bank demanded: eta g tan(bank) / V (the airframe gets there
        through the roll controller's lag, ``ROLL_TIME_CONSTANT_S``)."""
        speed = max(v.state.speed_m_s, v.config.limits.min_speed_m_s)
        bank = self.guided_bank_rad(v, command)
        return self._turn_efficiency * GRAVITY_M_S2 * math.tan(bank) / speed

    def _guided_command(self, v: SimVehicle, command: Command) -> Command:
        """GUIDED: the commanded course, else the loiter it entered with, at the guided speed."""
        speed = self._guided_speed_m_s or v.cruise_speed_m_s
        if self._guided_course_rad is not None:
            return CourseCommand(self._guided_course_rad, speed, self._guided_lateral_accel_m_s2)
        if isinstance(command, LoiterCommand):
            return replace(command, speed_m_s=speed)
        return command

    # ---- outgoing ----------------------------------------------------------------------------

    def heartbeat(self, v: SimVehicle) -> mavlink.MAVLink_message:
        assert isinstance(v.mode, ArduPlaneMode), v.mode
        return heartbeat(v.mode, v.armed, v.in_air, self.gcs_failsafe_active)

    def timesync_answer(self, tc1: int, ts1: int) -> mavlink.MAVLink_message:
        # GCS_Common.cpp handle_timesync: the answer's target fields are 0 (a broadcast)
        return mavlink.MAVLink_timesync_message(tc1, ts1)

    def autopilot_version(self, v: SimVehicle) -> mavlink.MAVLink_message:
        return mavlink.MAVLink_autopilot_version_message(
            ARDUPILOT_CAPABILITIES, ARDUPLANE_VERSION, 0, 0, 0,
            [0] * 8, [0] * 8, [0] * 8, 0, 0, 0x4150_0000_0000_0000 + v.system_id,
        )  # fmt: skip


def heartbeat(
    mode: ArduPlaneMode, armed: bool, flying: bool, failsafe: bool
) -> mavlink.MAVLink_message:
    """ArduPlane's HEARTBEAT: fixed wing, ArduPilotMega, base_mode as GCS_MAVLINK_Plane builds
    it (with the default stick mixing), custom_mode = the mode number, CRITICAL in failsafe."""
    if mode == MANUAL:
        base = _MANUAL_INPUT
    elif mode.number in _STABILIZE_MODES:
        base = _STABILIZE
    elif mode.number in (mavlink.PLANE_MODE_TRAINING, mavlink.PLANE_MODE_ACRO):
        base = _MANUAL_INPUT
    else:  # AUTO, RTL, LOITER, THERMAL, AVOID_ADSB, GUIDED, CIRCLE, TAKEOFF
        base = _GUIDED_FLAG | _STABILIZE
    if mode != MANUAL:
        base |= _STABILIZE
    base |= _MANUAL_INPUT | _CUSTOM | (_ARMED if armed else 0)
    if failsafe:
        status = mavlink.MAV_STATE_CRITICAL
    else:
        status = mavlink.MAV_STATE_ACTIVE if flying else mavlink.MAV_STATE_STANDBY
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_FIXED_WING,
        mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
        base,
        mode.number,
        status,
        3,
    )
