"""The PX4 fixed-wing adapter: a point ahead on the course with the course as velocity, the
airspeed by MAV_CMD_DO_CHANGE_SPEED; and PX4's flight mode names."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Final

from mavsdk.plugins.mavlink_direct import MavlinkMessage
from mavsdk.plugins.offboard import PositionNedYaw, VelocityNedYaw
from mavsdk.plugins.param import ParamError
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from app.adapters.vehicle.autopilots.base import (
    AutopilotName,
    CommandPort,
    OffboardControl,
    OffboardPort,
    ParamPort,
    VehicleState,
    check_finite,
    check_speed_range,
    command_long,
    offboard_call,
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
COM_OBL_RC_ACT: Final = "COM_OBL_RC_ACT"
COM_OBL_RC_ACT_HOLD: Final = 5


@dataclass(slots=True)
class Px4FixedWingAdapter(OffboardControl):
    """PX4 fixed-wing: a point ``lookahead`` ahead on the course plus the course as velocity.

    PX4 flies a position + velocity setpoint as a line through the point along the velocity,
    at its own airspeed; the commanded speed goes out as mavlink.MAV_CMD_DO_CHANGE_SPEED (airspeed)
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
        check_finite(
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
            mavlink.MAV_CMD_DO_CHANGE_SPEED,
            (mavlink.SPEED_TYPE_AIRSPEED, speed_m_s, -1.0),
        )

    async def _airspeed(self, speed_m_s: float) -> None:
        sent = self._speed_sent
        if sent is not None and abs(speed_m_s - sent) <= self.speed_deadband_m_s:
            return
        await send_checked_command(
            self.commands, self.speed_command(speed_m_s), self.vehicle_id, "DO_CHANGE_SPEED"
        )
        self._speed_sent = speed_m_s

    async def send(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        position, velocity = self.setpoint(setpoint, altitude_m, state)
        await offboard_call(
            "position+velocity setpoint",
            self.vehicle_id,
            self.offboard.set_position_velocity_ned(position, velocity),
        )
        await self._airspeed(setpoint.speed_m_s)
