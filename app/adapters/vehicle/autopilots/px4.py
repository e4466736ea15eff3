"""The PX4 fixed-wing adapter: a point ahead on the course with the course as velocity and the
wanted path curvature as acceleration; and PX4's flight mode names."""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Final

from mavsdk.plugins.mavlink_direct import MavlinkMessage
from mavsdk.plugins.offboard import AccelerationNed, PositionNedYaw, VelocityNedYaw
from mavsdk.plugins.param import ParamError
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from app.adapters.vehicle.autopilots.base import (
    AccelerationOffboardPort,
    AutopilotName,
    CommandPort,
    OffboardControl,
    ParamJournal,
    ParamPort,
    VehicleState,
    check_finite,
    check_message_rates,
    check_speed_range,
    command_long,
    offboard_call,
    request_message_rates,
    restore_message_rates,
    send_checked_command,
)
from app.adapters.vehicle.autopilots.limits import SetpointLimits
from app.core.frames import wrap_pi
from app.errors import LinkError
from app.runtime.ports.vehicle import CourseSpeedCommand

log = logging.getLogger(__name__)

# PX4's custom_mode: main mode in byte 2, sub mode (of AUTO) in byte 3 (px4_custom_mode.h);
# the names are MAVSDK's flight modes. pymavlink has no number for the last three.
PX4_MAIN_MODES: Final = {
    mavutil.PX4_CUSTOM_MAIN_MODE_MANUAL: "MANUAL",
    mavutil.PX4_CUSTOM_MAIN_MODE_ALTCTL: "ALTCTL",
    mavutil.PX4_CUSTOM_MAIN_MODE_POSCTL: "POSCTL",
    mavutil.PX4_CUSTOM_MAIN_MODE_ACRO: "ACRO",
    mavutil.PX4_CUSTOM_MAIN_MODE_OFFBOARD: "OFFBOARD",
    mavutil.PX4_CUSTOM_MAIN_MODE_STABILIZED: "STABILIZED",
    mavutil.PX4_CUSTOM_MAIN_MODE_RATTITUDE: "RATTITUDE",
    9: "TERMINATION",
}
PX4_AUTO_SUB_MODES: Final = {
    mavutil.PX4_CUSTOM_SUB_MODE_AUTO_READY: "READY",
    mavutil.PX4_CUSTOM_SUB_MODE_AUTO_TAKEOFF: "TAKEOFF",
    mavutil.PX4_CUSTOM_SUB_MODE_AUTO_LOITER: "HOLD",
    mavutil.PX4_CUSTOM_SUB_MODE_AUTO_MISSION: "MISSION",
    mavutil.PX4_CUSTOM_SUB_MODE_AUTO_RTL: "RETURN_TO_LAUNCH",
    mavutil.PX4_CUSTOM_SUB_MODE_AUTO_LAND: "LAND",
    mavutil.PX4_CUSTOM_SUB_MODE_AUTO_RTGS: "RETURN_TO_GROUND_STATION",
    mavutil.PX4_CUSTOM_SUB_MODE_AUTO_FOLLOW_TARGET: "FOLLOW_ME",
    9: "PRECISION_LAND",
    10: "VTOL_TAKEOFF",
}


def px4_mode_name(custom_mode: int) -> str:
    """PX4's flight mode name from HEARTBEAT.custom_mode (main mode in byte 2, sub in byte 3)."""
    main = (custom_mode >> 16) & 0xFF
    sub = (custom_mode >> 24) & 0xFF
    if main == mavutil.PX4_CUSTOM_MAIN_MODE_AUTO:
        return PX4_AUTO_SUB_MODES.get(sub, f"AUTO_{sub}")
    return PX4_MAIN_MODES.get(main, f"UNKNOWN_{custom_mode}")


#: PX4 fixed-wing's airspeed range (m/s): airspeed setpoints are held within it
FW_AIRSPD_MIN: Final = "FW_AIRSPD_MIN"
FW_AIRSPD_MAX: Final = "FW_AIRSPD_MAX"
#: the airspeed PX4 flies in OFFBOARD (m/s, a float parameter)
FW_AIRSPD_TRIM: Final = "FW_AIRSPD_TRIM"
COM_OBL_RC_ACT: Final = "COM_OBL_RC_ACT"
COM_OBL_RC_ACT_HOLD: Final = 5


def normal_acceleration_ned(
    course_rad: float, speed_m_s: float, course_rate_rad_s: float, max_course_rate_rad_s: float
) -> tuple[float, float]:
    """The horizontal acceleration (north, east; m/s^2) of flying ``course_rad`` at ``speed_m_s``
    while the course turns at ``course_rate_rad_s`` (positive clockwise seen from above).

    a_n = v * course_rate, normal to the velocity, to its right for a clockwise turn; the path's
    curvature is then a_n / v^2 = course_rate / v. The rate is first held within
    +-``max_course_rate_rad_s`` (the envelope: the vehicle cannot turn faster), so
    |a_n| <= v * max_course_rate_rad_s. Zero speed or zero rate gives zero.
    """
    rate = max(-max_course_rate_rad_s, min(max_course_rate_rad_s, course_rate_rad_s))
    a_n = speed_m_s * rate
    # the unit normal to the right of a course chi (clockwise from north) is (-sin chi, cos chi)
    return -a_n * math.sin(course_rad), a_n * math.cos(course_rad)


@dataclass(slots=True)
class Px4FixedWingAdapter(OffboardControl):
    """PX4 fixed-wing: a point ``lookahead`` ahead on the course, the course as velocity, and the
    course's rate as the acceleration normal to it (``set_position_velocity_acceleration_ned``).

    PX4 v1.16 flies a position + velocity setpoint in its position controller's AUTO_PATH mode:
    a line through the point along the velocity, with the acceleration's component normal to
    the velocity turned into a path curvature |v|^2 / |a_n| that NPFG feeds forward
    (FixedwingPositionControl.cpp: ``Run``, the offboard ``trajectory_setpoint`` branch, and
    ``control_auto_path``). The adapter sends a_n = v * course_rate (``normal_acceleration_ned``),
    so a vehicle on a turning course is not left to catch the turn by feedback alone;
    ``curvature_feed_forward`` False sends position + velocity only.

    **The line's course.** With the curvature fed forward, the line is laid along the wanted
    ground course itself (``CourseSpeedCommand.path_course_rad``), not along the course
    command, which leads it by rate / k for a first-order course loop: NPFG turns onto a line
    and feeds its curvature forward, so a line led into the turn makes it turn tighter than the
    circle, and the team settled 2-4 m inside the 90 m circle on real v1.16 SIH (and on the
    simulator's PX4). Without the feed-forward the led command is the line.

    **The sign in v1.16.** That branch computes the curvature's direction as
    ``-v_hat.cross(a_n_hat)``: an acceleration to the right of the velocity (a clockwise turn)
    comes out as a negative radius, which NPFG flies as counter-clockwise (its positive curvature
    is clockwise: ``navigateLoiter``). PX4 fixed that sign after v1.16 (PX4-Autopilot PR #27582,
    in fw_mode_manager). ``mirror_normal_accel`` True (the default, for v1.16 and earlier) sends
    the acceleration mirrored about the velocity so that v1.16 feeds forward the right turn;
    set it False for a PX4 with the fix.

    **Speed.** PX4 v1.16 does not fly a commanded speed in OFFBOARD (``honours_speed`` False):
    ``Run`` sets the setpoint's cruising speed to NaN on every offboard trajectory setpoint, so
    ``adapt_airspeed_setpoint`` flies FW_AIRSPD_TRIM, and ``vehicle_command_poll`` applies
    MAV_CMD_DO_CHANGE_SPEED only when the controller is in FW_POSCTRL_MODE_AUTO (a
    position+velocity setpoint puts it in AUTO_PATH), yet ACKs it as accepted. So the adapter
    sends DO_CHANGE_SPEED once per ``start`` (the first setpoint's speed, for a PX4-like vehicle
    that does apply it, such as an AUTO mode before the switch) and never again. With
    ``airspeed_via_trim_param`` (off by default) the speed is flown instead by writing
    FW_AIRSPD_TRIM, which v1.16 reads within a control cycle (``honours_speed`` True then); see
    ``_trim_airspeed`` for what each write costs.

    ``offboard_loss_action`` is the COM_OBL_RC_ACT wanted (what PX4 does ~1 s after setpoints
    stop: 5 = hold, the default here; PX4's own default 0 flies straight on). It is read and, if
    different, set before take-off; ``None`` leaves the parameters alone (for a PX4-like vehicle
    without parameters). Before that a vehicle whose FW_AIRSPD_MIN..FW_AIRSPD_MAX does not hold
    the mission's speed limits is refused: PX4 would hold the commanded airspeeds within it.
    Every parameter changed is written back by ``restore_params``.

    ``telemetry_rates_hz`` (None: nothing asked): messages to request by
    MAV_CMD_SET_MESSAGE_INTERVAL in ``prepare``, put back at PX4's own rates (interval 0) by
    ``restore_params``. PX4 SITL's offboard port (UDP 14540, an ``onboard`` mode link) streams
    GLOBAL_POSITION_INT at 50 Hz, LOCAL_POSITION_NED at 30 Hz and ATTITUDE at 100 Hz
    (mavlink_main.cpp ``configure_streams_to_default``), far faster than a mission steers:
    ``px4_mission_rates`` slows them and the fast streams the link never reads. A ``normal``
    mode link, such as a telemetry radio, streams position at 5 and 1 Hz:
    ``PX4_TELEMETRY_RATES_HZ`` or ``px4_mission_rates`` raises it.
    """

    vehicle_id: int
    offboard: AccelerationOffboardPort
    commands: CommandPort
    params: ParamPort
    limits: SetpointLimits
    target_component: int = 1
    lookahead_s: float = 4.0
    min_lookahead_m: float = 40.0
    offboard_loss_action: int | None = COM_OBL_RC_ACT_HOLD
    curvature_feed_forward: bool = True
    mirror_normal_accel: bool = True
    telemetry_rates_hz: Mapping[str, float] | None = None
    airspeed_via_trim_param: bool = False
    trim_min_interval_s: float = 5.0
    trim_deadband_m_s: float = 0.5
    name: AutopilotName = "px4-fixed-wing"
    _speed_pending: bool = field(default=True, init=False)
    _trim_sent: float | None = field(default=None, init=False)
    _trim_sent_t_s: float | None = field(default=None, init=False)
    _trim_original: float | None = field(default=None, init=False)
    _journal: ParamJournal = field(init=False)
    _rates_set: tuple[str, ...] = field(default=(), init=False)

    def __post_init__(self) -> None:
        if self.telemetry_rates_hz is not None:
            check_message_rates(self.telemetry_rates_hz)
        for what in ("trim_min_interval_s", "trim_deadband_m_s"):
            value = getattr(self, what)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{what} must be finite and >= 0, got {value!r}")
        self._journal = ParamJournal(self.vehicle_id)

    @property
    def honours_speed(self) -> bool:
        return self.airspeed_via_trim_param

    def mode_name(self, custom_mode: int) -> str:
        return px4_mode_name(custom_mode)

    @property
    def control_mode(self) -> str:
        return "OFFBOARD"

    async def prepare(self) -> None:
        if self.telemetry_rates_hz:
            accepted = await request_message_rates(
                self.commands, self.vehicle_id, self.target_component, self.telemetry_rates_hz
            )
            self._rates_set = tuple(name for name, ok in accepted.items() if ok)
        if self.airspeed_via_trim_param:
            try:
                self._trim_original = await self.params.get_param_float(FW_AIRSPD_TRIM)
            except ParamError as exc:
                raise LinkError(
                    f"vehicle {self.vehicle_id}: cannot read {FW_AIRSPD_TRIM} (asked to fly the "
                    f"speed through it): {exc.result.name}"
                ) from exc
            log.info("vehicle %d: %s = %g", self.vehicle_id, FW_AIRSPD_TRIM, self._trim_original)
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
                self._journal.record(COM_OBL_RC_ACT, current)
                log.warning(
                    "vehicle %d: set %s from %d to %d (restored at the end)",
                    self.vehicle_id,
                    COM_OBL_RC_ACT,
                    current,
                    wanted,
                )
        except ParamError as exc:
            raise LinkError(
                f"vehicle {self.vehicle_id}: cannot check/set {COM_OBL_RC_ACT}: {exc.result.name}"
            ) from exc

    async def restore_params(self) -> None:
        """Write back the parameters ``prepare`` (and the trim path) changed, and put every
        stream it set back at PX4's own rate."""
        await self._journal.restore(self.params)
        if self._rates_set:
            await restore_message_rates(
                self.commands, self.vehicle_id, self.target_component, self._rates_set
            )
            self._rates_set = ()

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
        course = self.line_course(setpoint)
        cos_c, sin_c = math.cos(course), math.sin(course)
        north = north0 + lookahead * cos_c
        east = east0 + lookahead * sin_c
        down = down0 - (altitude_m - state.relative_altitude_m)
        yaw = math.degrees(wrap_pi(course))
        v_north, v_east = setpoint.speed_m_s * cos_c, setpoint.speed_m_s * sin_c
        check_finite(
            {"north": north, "east": east, "down": down, "v_north": v_north, "v_east": v_east},
            "position+velocity setpoint",
        )
        return (
            PositionNedYaw(north_m=north, east_m=east, down_m=down, yaw_deg=yaw),
            VelocityNedYaw(north_m_s=v_north, east_m_s=v_east, down_m_s=0.0, yaw_deg=yaw),
        )

    def line_course(self, setpoint: CourseSpeedCommand) -> float:
        """The course the line is laid along: the wanted ground course where the curvature is
        fed forward and the command carries it, else the (led) course command."""
        if self.curvature_feed_forward and setpoint.path_course_rad is not None:
            return setpoint.path_course_rad
        return setpoint.course_rad

    def acceleration(self, setpoint: CourseSpeedCommand) -> AccelerationNed:
        """The acceleration that makes PX4 feed forward the course's rate as the path's
        curvature (mirrored for v1.16's sign, ``mirror_normal_accel``); vertical 0 (PX4's
        fixed-wing controller ignores it)."""
        north, east = normal_acceleration_ned(
            self.line_course(setpoint),
            setpoint.speed_m_s,
            setpoint.course_rate_rad_s,
            self.limits.envelope.max_course_rate_rad_s,
        )
        if self.mirror_normal_accel:
            north, east = -north, -east
        check_finite({"a_north": north, "a_east": east}, "acceleration setpoint")
        return AccelerationNed(north_m_s2=north, east_m_s2=east, down_m_s2=0.0)

    def take_off_command(
        self, lat_deg: float, lon_deg: float, altitude_amsl_m: float
    ) -> MavlinkMessage:
        """MAV_CMD_NAV_TAKEOFF to ``altitude_amsl_m`` (param7, AMSL) from here (param5/6).
        PX4 v1.16's navigator (navigator_main.cpp, VEHICLE_CMD_NAV_TAKEOFF) takes param7 as the
        take-off altitude in place of MIS_TAKEOFF_ALT, finite param5/6 as the take-off point,
        and ignores param4 (the yaw is left to the flight task)."""
        return command_long(
            self.vehicle_id,
            self.target_component,
            mavlink.MAV_CMD_NAV_TAKEOFF,
            (0.0, 0.0, 0.0, 0.0, lat_deg, lon_deg, altitude_amsl_m),
        )

    async def take_off(self, lat_deg: float, lon_deg: float, altitude_amsl_m: float) -> None:
        await send_checked_command(
            self.commands,
            self.take_off_command(lat_deg, lon_deg, altitude_amsl_m),
            self.vehicle_id,
            "NAV_TAKEOFF",
        )

    def speed_command(self, speed_m_s: float) -> MavlinkMessage:
        """MAV_CMD_DO_CHANGE_SPEED: param1 airspeed (0), param2 speed, param3 -1 (throttle kept)."""
        return command_long(
            self.vehicle_id,
            self.target_component,
            mavlink.MAV_CMD_DO_CHANGE_SPEED,
            (mavlink.SPEED_TYPE_AIRSPEED, speed_m_s, -1.0),
        )

    async def start(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        self._speed_pending = True
        await OffboardControl.start(self, setpoint, altitude_m, state)

    async def _change_speed_once(self, speed_m_s: float) -> None:
        if not self._speed_pending:
            return
        await send_checked_command(
            self.commands, self.speed_command(speed_m_s), self.vehicle_id, "DO_CHANGE_SPEED"
        )
        self._speed_pending = False

    async def _trim_airspeed(self, speed_m_s: float, t_s: float) -> None:
        """Fly ``speed_m_s`` by writing FW_AIRSPD_TRIM, at most once per ``trim_min_interval_s``
        of vehicle time and only when it moved by more than ``trim_deadband_m_s``.

        The cost, which is why it is off by default: every change is a PARAM_SET answered by a
        PARAM_VALUE that PX4 broadcasts to every ground station (QGroundControl's parameter list
        changes under the operator), stores in its parameter file (flash or SD card wear on
        hardware) and logs; and the trim airspeed is more than a cruise setpoint: PX4 also
        scales its attitude controllers' gains and TECS's throttle trim with it. The original
        is written back by ``restore_params``; an app that dies first leaves the last value.
        """
        sent, sent_t = self._trim_sent, self._trim_sent_t_s
        if sent is not None and abs(speed_m_s - sent) <= self.trim_deadband_m_s:
            return
        if sent_t is not None and 0.0 <= t_s - sent_t < self.trim_min_interval_s:
            return
        try:
            await self.params.set_param_float(FW_AIRSPD_TRIM, speed_m_s)
        except ParamError as exc:
            raise LinkError(
                f"vehicle {self.vehicle_id}: cannot set {FW_AIRSPD_TRIM} to {speed_m_s:g}: "
                f"{exc.result.name}"
            ) from exc
        if self._trim_original is not None:
            self._journal.record(FW_AIRSPD_TRIM, self._trim_original)
        self._trim_sent, self._trim_sent_t_s = speed_m_s, t_s

    async def send(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        position, velocity = self.setpoint(setpoint, altitude_m, state)
        if self.curvature_feed_forward:
            acceleration = self.acceleration(setpoint)
            await offboard_call(
                "position+velocity+acceleration setpoint",
                self.vehicle_id,
                self.offboard.set_position_velocity_acceleration_ned(
                    position, velocity, acceleration
                ),
            )
        else:
            await offboard_call(
                "position+velocity setpoint",
                self.vehicle_id,
                self.offboard.set_position_velocity_ned(position, velocity),
            )
        await self._change_speed_once(setpoint.speed_m_s)
        if self.airspeed_via_trim_param:
            await self._trim_airspeed(setpoint.speed_m_s, state.t_s)


#: what to ask of a PX4 whose link streams position slowly (a ``normal`` mode link)
PX4_TELEMETRY_RATES_HZ: Final[Mapping[str, float]] = {
    "GLOBAL_POSITION_INT": 10.0,
    "LOCAL_POSITION_NED": 10.0,
}
#: what the link reads of PX4 and PX4's ``onboard`` link streams fast (mavlink_main.cpp
#: ``configure_streams_to_default``, v1.16: ATTITUDE 100 Hz, GLOBAL_POSITION_INT, HIGHRES_IMU
#: and ATTITUDE_QUATERNION 50, LOCAL_POSITION_NED and ODOMETRY 30, RC_CHANNELS 20); ATTITUDE,
#: which the PX4 link does not read, at the mission's rate for the horizon of a ground station
#: the relays serve
PX4_READ_STREAMS: Final = ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "ATTITUDE")
#: the fast ``onboard`` streams the link never reads
PX4_UNREAD_FAST_STREAMS: Final = ("HIGHRES_IMU", "ATTITUDE_QUATERNION", "ODOMETRY", "RC_CHANNELS")
#: the rate the unread fast streams are slowed to (Hz)
PX4_UNREAD_STREAM_RATE_HZ: Final = 1.0


def px4_mission_rates(rate_hz: float) -> dict[str, float]:
    """The streams to ask of PX4 for a mission steered at ``rate_hz``: what the link reads at
    that rate, PX4's fast streams it never reads at 1 Hz (about 410 messages a second of an
    ``onboard`` link down to about 100 at 10 Hz)."""
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        raise ValueError(f"the telemetry rate must be finite and > 0 Hz, got {rate_hz!r}")
    rates = dict.fromkeys(PX4_READ_STREAMS, rate_hz)
    rates.update(dict.fromkeys(PX4_UNREAD_FAST_STREAMS, PX4_UNREAD_STREAM_RATE_HZ))
    return rates
