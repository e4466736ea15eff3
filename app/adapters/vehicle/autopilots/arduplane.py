"""The ArduPlane adapter: GUIDED with the guided slew commands, and the GCS failsafe made to
return the aircraft; and ArduPlane's flight mode names."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final

from mavsdk.plugins.mavlink_direct import MavlinkMessage
from mavsdk.plugins.param import ParamError
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from app.adapters.vehicle.autopilots.base import (
    MAVSDK_GCS_SYSTEM_ID,
    AutopilotName,
    CommandPort,
    ParamPort,
    VehicleState,
    check_speed_range,
    command_int,
    command_long,
    course_deg_0_360,
    send_checked_command,
)
from app.adapters.vehicle.autopilots.limits import SetpointLimits
from app.core.frames import wrap_pi
from app.errors import LinkError
from app.runtime.ports.vehicle import CourseSpeedCommand

log = logging.getLogger(__name__)

#: ArduPlane's mode names by number (pymavlink's mapping of ArduPlane/mode.h)
ARDUPLANE_MODE_NAMES: Final[dict[int, str]] = dict(
    mavutil.mode_mapping_bynumber(mavlink.MAV_TYPE_FIXED_WING)
)
ARDUPLANE_GUIDED: Final = mavlink.PLANE_MODE_GUIDED
ARDUPLANE_LOITER: Final = mavlink.PLANE_MODE_LOITER
ARDUPLANE_TAKEOFF: Final = mavlink.PLANE_MODE_TAKEOFF
#: GUIDED_CHANGE_HEADING param3 when the course rate is unlimited: ArduPlane takes at least
#: 0.05 m/s^2 (``MAX(param3, 0.05f)``, so 0 would barely turn) and banks no more than its own
#: roll limit, so a value this large leaves the turn to the airframe
UNLIMITED_LATERAL_ACCEL_M_S2: Final = 1000.0


def arduplane_mode_name(custom_mode: int) -> str:
    """ArduPlane's flight mode name from HEARTBEAT.custom_mode."""
    return ARDUPLANE_MODE_NAMES.get(custom_mode, f"UNKNOWN_{custom_mode}")


SYSID_MYGCS: Final = "SYSID_MYGCS"
#: ArduPilot 4.7's name for SYSID_MYGCS, and the top of the range of GCS ids it may name
MAV_GCS_SYSID: Final = "MAV_GCS_SYSID"
MAV_GCS_SYSID_HI: Final = "MAV_GCS_SYSID_HI"
#: the airspeed range GUIDED_CHANGE_SPEED accepts (m/s), and their names before ArduPilot 4.5
AIRSPEED_MIN: Final = "AIRSPEED_MIN"
AIRSPEED_MAX: Final = "AIRSPEED_MAX"
ARSPD_FBW_MIN: Final = "ARSPD_FBW_MIN"
ARSPD_FBW_MAX: Final = "ARSPD_FBW_MAX"
FS_GCS_ENABL: Final = "FS_GCS_ENABL"
FS_LONG_ACTN: Final = "FS_LONG_ACTN"
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
            mavlink.MAV_CMD_DO_SET_MODE,
            (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode),
        )

    def heading_command(self, course_rad: float, speed_m_s: float) -> MavlinkMessage:
        rate = self.limits.max_course_change_rad_s
        max_lateral_accel = speed_m_s * rate if rate is not None else UNLIMITED_LATERAL_ACCEL_M_S2
        return command_int(
            self.vehicle_id,
            self.target_component,
            mavlink.MAV_CMD_GUIDED_CHANGE_HEADING,
            (
                mavlink.HEADING_TYPE_COURSE_OVER_GROUND,
                course_deg_0_360(course_rad),
                max_lateral_accel,
                0.0,
            ),
        )

    def speed_command(self, speed_m_s: float) -> MavlinkMessage:
        return command_int(
            self.vehicle_id,
            self.target_component,
            mavlink.MAV_CMD_GUIDED_CHANGE_SPEED,
            (mavlink.SPEED_TYPE_AIRSPEED, speed_m_s, self.limits.envelope.max_accel_m_s2, 0.0),
        )

    def altitude_command(self, altitude_m: float) -> MavlinkMessage:
        return command_int(
            self.vehicle_id,
            self.target_component,
            mavlink.MAV_CMD_GUIDED_CHANGE_ALTITUDE,
            (0.0, 0.0, self.limits.max_climb_rate_m_s, 0.0),
            frame=mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
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
