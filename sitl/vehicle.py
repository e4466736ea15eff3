"""One simulated fixed-wing airframe as a MAVLink peer, flown by an autopilot personality.

The airframe (``SimVehicle``) holds the physics, arming and launch, the telemetry streams and
the camera; an ``Autopilot`` (``sitl.px4``, ``sitl.arduplane``) holds the heartbeat and modes,
the commands and parameters, and the failsafes, and acts on the airframe it is given.

No sockets and no clock here: ``handle`` takes a decoded message and the current simulated (and
wall) time and returns the replies; ``advance`` steps the flight by one physics step; ``telemetry``
returns the streams that are due. The server (``sitl.server``) does the I/O.

What the airframe does as the real ones do:

- Boot clock: every time field (``time_boot_ms``, ``time_usec``, TIMESYNC) counts from the
  vehicle's own boot, ``SimConfig.boot_offset_s(i)`` before the simulation started, so vehicles
  started one after another report different clocks.
- Take-off (``SimConfig.takeoff = "runway"``): a ground roll from rest along the start course at
  ``ROLL_ACCEL_M_S2``, rotation at the minimum airspeed, then a climb at ``CLIMB_RATE_M_S`` to the
  vehicle's altitude. The landed state it reports (EXTENDED_SYS_STATE) follows PX4's fixed-wing
  land detector (src/modules/land_detector/FixedwingLandDetector.cpp ``_get_landed_state``):
  landed while the low-passed airspeed is under LNDFW_AIRSPD_MAX (6 m/s) and the low-passed
  ground speed under LNDFW_VEL_XY_MAX (5 m/s), filters 0.95/0.05 and 0.97/0.03 run every 50 ms,
  flying at once (FLYING_TRIGGER_TIME_US = 0): "in air" comes during the ground roll, at about
  9 m/s and no height, not at a safe height.
- Altitude: the airframe climbs or sinks toward ``altitude_target_m`` at ``climb_rate_m_s``;
  the personalities set the target (take-off, GUIDED entry, GUIDED_CHANGE_ALTITUDE).
"""

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Protocol

from pymavlink.dialects.v20 import common as mavlink

from app.core.plant import FixedWingState, VehicleEnvelope, step
from sitl import telemetry
from sitl.camera import Observation, TrackingCamera
from sitl.config import SimConfig, VehicleConfig
from sitl.geodesy import Geodesy
from sitl.guidance import Command, LoiterCommand

AUTOPILOT_COMPONENT: Final = mavlink.MAV_COMP_ID_AUTOPILOT1
CAMERA_COMPONENT: Final = mavlink.MAV_COMP_ID_CAMERA
#: MAV_CMD_COMPONENT_ARM_DISARM param2 that forces a disarm in flight
ARM_DISARM_FORCE: Final = 21196


class FlightMode(Protocol):
    """A flight mode as the heartbeat reports it: a name for the truth, the custom_mode."""

    @property
    def name(self) -> str: ...

    @property
    def custom_mode(self) -> int: ...


#: ground roll acceleration (m/s^2) and climb rate after rotation (m/s; FW_T_CLMB_MAX and
#: TECS_CLMB_MAX are 5 m/s by default)
ROLL_ACCEL_M_S2: Final = 3.0
CLIMB_RATE_M_S: Final = 5.0
#: PX4's fixed-wing land detector (FixedwingLandDetector.cpp, land_detector_params_fw.c): the
#: thresholds and the time constants of its two low-pass filters run every 50 ms
LNDFW_AIRSPD_MAX_M_S: Final = 6.0
LNDFW_VEL_XY_MAX_M_S: Final = 5.0
LAND_DETECTOR_PERIOD_S: Final = 0.05
AIRSPEED_FILTER_TAU_S: Final = LAND_DETECTOR_PERIOD_S / -math.log(0.95)
GROUND_SPEED_FILTER_TAU_S: Final = LAND_DETECTOR_PERIOD_S / -math.log(0.97)

# message id -> default interval in simulated seconds (None: telemetry_rate_hz); -1: off
_HEARTBEAT_ID: Final = mavlink.MAVLINK_MSG_ID_HEARTBEAT
StreamTable = dict[int, float | None]
#: the streams PX4 sends (at the simulator's telemetry rate) without being asked
PX4_STREAMS: Final[StreamTable] = {
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
    mavlink.MAVLINK_MSG_ID_WIND_COV: 1.0,  # mavlink_main.cpp: 0.5-1 Hz in the normal modes
    # streams real PX4 has (fast on an onboard link) and this simulator does not send: their
    # intervals are taken, as PX4 takes them, and nothing is sent
    mavlink.MAVLINK_MSG_ID_HIGHRES_IMU: -1.0,
    mavlink.MAVLINK_MSG_ID_ODOMETRY: -1.0,
    mavlink.MAVLINK_MSG_ID_RC_CHANNELS: -1.0,
}
#: ArduPilot's WIND (ardupilotmega, not in common)
MSG_ID_WIND: Final = 168

Outgoing = tuple[int, mavlink.MAVLink_message]  # (source component id, message)
GeoLookup = Callable[[], tuple[float, float, float]]  # () -> (lat_deg, lon_deg, alt_amsl_m)


def param_id_text(param_id: str | bytes) -> str:
    """A PARAM_* message's param_id as text (NUL-padded to 16 bytes on the wire)."""
    if isinstance(param_id, bytes):
        param_id = param_id.decode("ascii", "replace")
    return param_id.split("\x00", 1)[0]


def as_int(value: float, default: int = 0) -> int:
    """A command parameter as an integer; NaN or infinity ("unused") gives ``default``."""
    return round(value) if math.isfinite(value) else default


@dataclass(slots=True)
class SilenceTimer:
    """When a peer (setpoints, a ground station's heartbeats) was last heard, in simulated and
    wall time. A failsafe counts silence only once both have passed: clients send at a
    wall-clock rate, so at a high speed-up simulated time alone would trip it
    (``SimConfig.offboard_timeout_min_wall_s``)."""

    t_s: float = -math.inf
    wall_s: float = -math.inf

    @property
    def ever(self) -> bool:
        return self.t_s > -math.inf

    def heard(self, t_s: float, wall_s: float) -> None:
        self.t_s, self.wall_s = t_s, wall_s

    def silent(self, t_s: float, wall_s: float, timeout_s: float, min_wall_s: float) -> bool:
        """More than ``timeout_s`` of simulated and ``min_wall_s`` of wall time since heard."""
        return t_s - self.t_s > timeout_s and wall_s - self.wall_s > min_wall_s


class Autopilot(Protocol):
    """An autopilot personality over the airframe: the modes, commands and parameters of one
    autopilot (``sitl.px4.Px4Autopilot``, ``sitl.arduplane.ArduPlaneAutopilot``)."""

    @property
    def boot_mode(self) -> FlightMode:
        """The mode it boots in."""
        ...

    @property
    def trim_throttle(self) -> float:
        """The throttle (0..1) that holds cruise airspeed in level flight."""
        ...

    @property
    def turn_efficiency(self) -> float:
        """The course rate the airframe turns at a bank, as a fraction of the coordinated
        turn's g tan(bank) / V: the bank reported is atan(V rate / (eta g))."""
        ...

    @property
    def stream_defaults(self) -> StreamTable:
        """The streams it sends without being asked (message id -> interval s; None: the
        simulator's telemetry rate; negative: only on request), and the set a message interval
        of 0 returns a message to."""
        ...

    def mode_events(self, v: "SimVehicle", t_s: float, wall_s: float) -> list[Outgoing]:
        """Mode changes that happen on their own at ``t_s`` (failsafes, end of take-off)."""
        ...

    def fly(self, v: "SimVehicle", dt_s: float) -> None:
        """One physics step in the air (``v.step``), flying what the mode commands."""
        ...

    def launched(self, v: "SimVehicle", t_s: float) -> None:
        """The airframe has just been launched into the air."""
        ...

    def arm(self, v: "SimVehicle", t_s: float) -> None:
        """Arm (and launch, if this autopilot launches on arming)."""
        ...

    def handle(
        self, v: "SimVehicle", msg: mavlink.MAVLink_message, t_s: float, wall_s: float
    ) -> list[Outgoing]:
        """A message the airframe does not answer itself (setpoints, parameters, heartbeats)."""
        ...

    def run_command(
        self,
        v: "SimVehicle",
        command: int,
        p: tuple[float, ...],
        t_s: float,
        wall_s: float,
        frame: int | None,
    ) -> tuple[int, list[Outgoing]]:
        """A command to the autopilot (``frame`` None: COMMAND_LONG): result and replies."""
        ...

    def heartbeat(self, v: "SimVehicle") -> mavlink.MAVLink_message: ...

    def autopilot_version(self, v: "SimVehicle") -> mavlink.MAVLink_message: ...

    def timesync_answer(self, tc1: int, ts1: int) -> mavlink.MAVLink_message:
        """Its answer to a TIMESYNC request (tc1 its boot time, ns; ts1 the request's)."""
        ...


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
    #: the landed state it reports (EXTENDED_SYS_STATE): "in air" already during a ground roll
    landed_state_in_air: bool = False


class SimVehicle:
    """One simulated fixed-wing airframe behind one MAVLink system id, flown by ``autopilot``.

    The airframe holds what every autopilot shares: the physics state in the wind, arming and
    launch, the telemetry streams and the camera, and the MAVLink services (ping, time sync,
    message requests and intervals). Everything else (heartbeat and modes, the commands it
    accepts and how, parameters, failsafes) is the autopilot personality's.
    """

    def __init__(
        self,
        index: int,
        config: VehicleConfig,
        sim: SimConfig,
        camera: TrackingCamera,
        geodesy: Geodesy,
        autopilot: Autopilot,
    ) -> None:
        self.index = index
        self.system_id = index + 1
        #: how long before simulated time 0 its autopilot booted (s)
        self.boot_offset_s = sim.boot_offset_s(index)
        self.config = config
        self.autopilot = autopilot
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
        #: on the runway, rolling for take-off (``in_air`` turns true at rotation)
        self.rolling = False
        self._filtered_airspeed_m_s = 0.0
        self._filtered_ground_speed_m_s = 0.0
        #: the altitude (m above home) the airframe climbs or sinks to, and how fast (m/s)
        self.altitude_target_m = config.altitude_m
        self.climb_rate_m_s = CLIMB_RATE_M_S
        self.mode: FlightMode = autopilot.boot_mode
        self.command: Command | None = None
        self.cruise_speed_m_s = config.cruise_speed_m_s
        self.loiter_radius_m = config.effective_loiter_radius_m
        #: the height flown in the air (m above home)
        self.air_altitude_m = config.altitude_m
        self._streams: dict[int, float] = {}
        self._next_due: dict[int, float] = {}
        for msg_id, interval in autopilot.stream_defaults.items():
            self.set_stream(msg_id, interval, 0.0)
        self._camera_period_s = 1.0 / camera.config.rate_hz
        self._next_camera_t_s = 0.0
        self._battery_fraction = 1.0
        self.observations_sent = 0
        self.last_observation: Observation | None = None
        self.wind_east_m_s = 0.0
        self.wind_north_m_s = 0.0
        #: the rate of climb of the last physics step (m/s, up > 0)
        self.climb_m_s = 0.0
        #: the component id its tracking camera sends from (CAMERA_TRACKING_GEO_STATUS)
        self.camera_component_id = sim.camera_component_id

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
            landed_state_in_air=self.landed_state_in_air,
        )

    @property
    def altitude_m(self) -> float:
        return self.air_altitude_m if self.in_air else 0.0

    @property
    def landed_state_in_air(self) -> bool:
        """PX4's fixed-wing land detector: flying once either low-passed speed is over its
        threshold (while armed), so already during the ground roll."""
        if self.in_air:
            return True
        return self.armed and (
            self._filtered_airspeed_m_s > LNDFW_AIRSPD_MAX_M_S
            or self._filtered_ground_speed_m_s > LNDFW_VEL_XY_MAX_M_S
        )

    def boot_time_s(self, t_s: float) -> float:
        """Simulated time ``t_s`` on the vehicle's own boot clock (s since its boot)."""
        return t_s + self.boot_offset_s

    # ---- flight ------------------------------------------------------------------------------

    def advance(
        self, dt_s: float, t_s: float, wall_s: float, wind_east_m_s: float, wind_north_m_s: float
    ) -> list[Outgoing]:
        """Check the failsafe at time ``t_s``, then fly one physics step of ``dt_s`` in the wind."""
        self.wind_east_m_s, self.wind_north_m_s = wind_east_m_s, wind_north_m_s
        out = self.autopilot.mode_events(self, t_s, wall_s)
        self.climb_m_s = 0.0
        if self.rolling:
            self._roll(dt_s, t_s)
        elif self.in_air:
            self.autopilot.fly(self, dt_s)
            self._climb(dt_s)
        self._detect(dt_s)
        if self.in_air or self.rolling:
            self._battery_fraction = max(0.0, self._battery_fraction - dt_s / 3600.0)
        return out

    def _roll(self, dt_s: float, t_s: float) -> None:
        """One step of the ground roll: straight on along the runway, accelerating; rotate (into
        the air, height 0, climbing to the vehicle's altitude) at the minimum airspeed."""
        s = self.state
        rotate_m_s = self.config.limits.min_speed_m_s
        speed = min(s.speed_m_s + ROLL_ACCEL_M_S2 * dt_s, rotate_m_s)
        mean = 0.5 * (s.speed_m_s + speed)
        self.state = FixedWingState(
            s.east_m + mean * dt_s * math.sin(s.course_rad),
            s.north_m + mean * dt_s * math.cos(s.course_rad),
            s.course_rad,
            speed,
        )
        if speed >= rotate_m_s:
            self.rolling = False
            self.in_air = True
            self.air_altitude_m = 0.0
            self.altitude_target_m = self.config.altitude_m
            self.climb_rate_m_s = CLIMB_RATE_M_S
            self.autopilot.launched(self, t_s)

    def _climb(self, dt_s: float) -> None:
        step_m = self.climb_rate_m_s * dt_s
        error = self.altitude_target_m - self.air_altitude_m
        change_m = max(-step_m, min(step_m, error))
        self.air_altitude_m += change_m
        self.climb_m_s = change_m / dt_s

    @property
    def throttle(self) -> float:
        """The throttle (0..1) a TECS-like energy controller would hold: the personality's
        trim in level flight at cruise airspeed, more to fly faster, to climb (full throttle at
        ``CLIMB_RATE_M_S``) and in a banked turn (lift 1/cos(bank) times the weight), less to
        sink; full on the take-off roll, none on the ground."""
        if self.rolling:
            return 1.0
        if not self.in_air:
            return 0.0
        lim = self.config.limits
        trim = self.autopilot.trim_throttle
        speed = (self.state.speed_m_s - self.cruise_speed_m_s) / (
            lim.max_speed_m_s - lim.min_speed_m_s
        )
        climb = self.climb_m_s / CLIMB_RATE_M_S
        bank = 1.0 / math.cos(telemetry.roll_rad(self.state, self.autopilot.turn_efficiency)) - 1.0
        return max(0.0, min(1.0, trim + 0.5 * speed + (1.0 - trim) * climb + 0.5 * bank))

    def _detect(self, dt_s: float) -> None:
        """The land detector's two low-pass filters (airspeed, ground speed)."""
        moving = self.in_air or self.rolling
        airspeed = self.state.speed_m_s if moving else 0.0
        v_north, v_east = self._ground_velocity() if moving else (0.0, 0.0)
        ground = math.hypot(v_north, v_east)
        a = 1.0 - math.exp(-dt_s / AIRSPEED_FILTER_TAU_S)
        g = 1.0 - math.exp(-dt_s / GROUND_SPEED_FILTER_TAU_S)
        self._filtered_airspeed_m_s += a * (airspeed - self._filtered_airspeed_m_s)
        self._filtered_ground_speed_m_s += g * (ground - self._filtered_ground_speed_m_s)

    def step(
        self, course_cmd_rad: float, speed_cmd_m_s: float, limits: VehicleEnvelope, dt_s: float
    ) -> None:
        """Fly the commanded course and speed for ``dt_s`` within ``limits``, in the wind."""
        self.state = step(
            self.state,
            course_cmd_rad,
            speed_cmd_m_s,
            limits,
            dt_s,
            self.wind_east_m_s,
            self.wind_north_m_s,
        )

    def loiter_at(self, east_m: float, north_m: float) -> LoiterCommand:
        """The vehicle's loiter circle (radius, direction, cruise speed) around a point."""
        return LoiterCommand(
            east_m,
            north_m,
            self.loiter_radius_m,
            self.config.loiter_clockwise,
            self.cruise_speed_m_s,
        )

    def hold_here(self) -> LoiterCommand:
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

    def local_of(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        """(east, north) of a latitude/longitude in the mission frame."""
        east, north, _ = self._geodesy.to_local(lat_deg, lon_deg, self._sim.origin_alt_m)
        return east, north

    def take_off(self, t_s: float) -> None:
        """Start the take-off ``SimConfig.takeoff`` names: a ground roll, or a launch."""
        if self.in_air or self.rolling:
            return
        if self._sim.takeoff == "launch":
            self.launch(t_s)
            return
        self.rolling = True
        self.state = FixedWingState(
            self.state.east_m, self.state.north_m, self.config.start.course_rad, 0.0
        )

    def launch(self, t_s: float) -> None:
        """Into the air (as a catapult would) at its configured start course, speed, height."""
        start = self.config.start
        self.air_altitude_m = self.config.altitude_m
        self.altitude_target_m = self.config.altitude_m
        self.state = FixedWingState(
            east_m=self.state.east_m,
            north_m=self.state.north_m,
            course_rad=start.course_rad,
            speed_m_s=start.speed_m_s,
        )
        self.in_air = True
        self.autopilot.launched(self, t_s)

    def arm(self, t_s: float) -> None:
        """Arm, as MAV_CMD_COMPONENT_ARM_DISARM does (no-op when armed)."""
        self.autopilot.arm(self, t_s)

    def disarm(self) -> None:
        """Disarmed: on the ground, at rest where it is."""
        self.armed = False
        self.in_air = False
        self.rolling = False
        self.state = FixedWingState(
            self.state.east_m, self.state.north_m, self.state.course_rad, 0.0
        )

    # ---- incoming ----------------------------------------------------------------------------

    def handle(self, msg: mavlink.MAVLink_message, t_s: float, wall_s: float) -> list[Outgoing]:
        """React to one decoded message addressed to this system (or broadcast)."""
        msg_id = msg.get_msgId()
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
        if msg_id == mavlink.MAVLINK_MSG_ID_TIMESYNC and msg.tc1 == 0:
            tc1 = round(self.boot_time_s(t_s) * 1e9)
            return [(AUTOPILOT_COMPONENT, self.autopilot.timesync_answer(tc1, msg.ts1))]
        return self.autopilot.handle(self, msg, t_s, wall_s)

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
        camera = self.camera_component_id
        if target_component == camera:
            return [self._ack(command, mavlink.MAV_RESULT_UNSUPPORTED, requester, camera)]
        if target_component not in (0, AUTOPILOT_COMPONENT):
            return []
        served = self._serve(command, p, t_s)
        if served is None:
            served = self.autopilot.run_command(self, command, p, t_s, wall_s, frame)
        result, extra = served
        return [self._ack(command, result, requester), *extra]

    def _serve(
        self, command: int, p: tuple[float, ...], t_s: float
    ) -> tuple[int, list[Outgoing]] | None:
        """The commands every autopilot answers alike (messages on request, stream intervals);
        None for the others."""
        accepted = mavlink.MAV_RESULT_ACCEPTED
        if command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            reply = self._message_by_id(as_int(p[0], -1), t_s)
            if reply is None:
                return mavlink.MAV_RESULT_UNSUPPORTED, []
            return accepted, [reply]
        if command == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return accepted, [(AUTOPILOT_COMPONENT, self.autopilot.autopilot_version(self))]
        if command == mavlink.MAV_CMD_GET_HOME_POSITION:
            return accepted, [self._home_position(t_s)]
        if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            msg_id, interval_us = as_int(p[0], -1), p[1]
            if math.isnan(interval_us):
                interval_us = 0.0
            defaults = self.autopilot.stream_defaults
            if msg_id not in defaults:
                return mavlink.MAV_RESULT_UNSUPPORTED, []
            if interval_us == 0:
                self.set_stream(msg_id, defaults[msg_id], t_s)
            elif interval_us < 0:
                self.set_stream(msg_id, -1.0, t_s)
            else:
                self.set_stream(msg_id, interval_us * 1e-6, t_s)
            return accepted, []
        return None

    def set_stream(self, msg_id: int, interval_s: float | None, t_s: float) -> None:
        """Stream ``msg_id`` every ``interval_s`` (None: the telemetry rate; <= 0: off) from
        ``t_s``."""
        interval = 1.0 / self._sim.telemetry_rate_hz if interval_s is None else interval_s
        interval = -1.0 if interval <= 0.0 else interval
        self._streams[msg_id] = interval
        self._next_due[msg_id] = t_s

    def stream_interval_s(self, msg_id: int) -> float:
        """The interval message ``msg_id`` is streamed at (s; negative: off)."""
        return self._streams[msg_id]

    def next_heartbeat_at(self, t_s: float) -> None:
        """Stream the next HEARTBEAT at ``t_s`` (after one sent out of turn)."""
        self._next_due[_HEARTBEAT_ID] = t_s

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
        return self.camera_component_id, telemetry.camera_tracking_geo_status(obs, lat, lon, alt)

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
        t_s = self.boot_time_s(t_s)  # every time field counts from the vehicle's own boot
        if msg_id == _HEARTBEAT_ID:
            return self.autopilot.heartbeat(self)
        if msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return self.autopilot.autopilot_version(self)
        if msg_id == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
            return telemetry.home_position(
                *self._home_lla, self.home_east_m, self.home_north_m, t_s
            )
        if msg_id == mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            return telemetry.extended_sys_state(self.landed_state_in_air)
        if msg_id == mavlink.MAVLINK_MSG_ID_SYS_STATUS:
            return telemetry.sys_status(self._battery_fraction)
        if msg_id == mavlink.MAVLINK_MSG_ID_BATTERY_STATUS:
            return telemetry.battery_status(self._battery_fraction)
        if msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE:
            return telemetry.attitude(s, t_s, self.autopilot.turn_efficiency)
        if msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION:
            return telemetry.attitude_quaternion(s, t_s, self.autopilot.turn_efficiency)
        if msg_id == mavlink.MAVLINK_MSG_ID_WIND_COV:
            return telemetry.wind_cov(t_s, self.wind_east_m_s, self.wind_north_m_s)
        if msg_id == MSG_ID_WIND:
            return telemetry.ardupilot_wind(self.wind_east_m_s, self.wind_north_m_s)
        v_north, v_east = self._ground_velocity()
        climb = self.climb_m_s
        if msg_id == mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            return telemetry.local_position_ned(s, self.altitude_m, v_north, v_east, t_s, climb)
        if msg_id == mavlink.MAVLINK_MSG_ID_VFR_HUD:
            ground_speed = math.hypot(v_north, v_east)
            alt_amsl = self._sim.origin_alt_m + self.altitude_m
            return telemetry.vfr_hud(
                s, ground_speed, self.in_air or self.rolling, alt_amsl, self.throttle, climb
            )
        if msg_id == mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            return telemetry.global_position_int(
                geo(), self.altitude_m, v_north, v_east, s, t_s, climb
            )
        if msg_id == mavlink.MAVLINK_MSG_ID_GPS_RAW_INT:
            return telemetry.gps_raw_int(geo(), v_north, v_east, t_s)
        return None

    def _ground_velocity(self) -> tuple[float, float]:
        """(north, east) ground velocity: airspeed along the heading plus the wind drift (on
        the runway the wheels hold the track)."""
        s = self.state
        if self.rolling:
            return s.v_north_m_s, s.v_east_m_s
        return s.v_north_m_s + self.wind_north_m_s, s.v_east_m_s + self.wind_east_m_s

    def heartbeat(self) -> Outgoing:
        """This vehicle's HEARTBEAT, now (out of the stream's turn)."""
        return AUTOPILOT_COMPONENT, self.autopilot.heartbeat(self)

    def _home_position(self, t_s: float) -> Outgoing:
        return AUTOPILOT_COMPONENT, telemetry.home_position(
            *self._home_lla, self.home_east_m, self.home_north_m, self.boot_time_s(t_s)
        )

    def statustext(self, severity: int, text: str) -> Outgoing:
        return AUTOPILOT_COMPONENT, telemetry.statustext(severity, text)

    def _ack(
        self,
        command: int,
        result: int,
        requester: tuple[int, int],
        component: int = AUTOPILOT_COMPONENT,
    ) -> Outgoing:
        return component, telemetry.command_ack(command, result, requester)
