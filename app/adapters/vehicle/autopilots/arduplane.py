"""The ArduPlane adapter: GUIDED with the guided slew commands, and the GCS failsafe made to
return the aircraft; and ArduPlane's flight mode names."""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Awaitable, Callable, Mapping
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
    ParamJournal,
    ParamPort,
    Sleep,
    VehicleState,
    check_message_rates,
    check_speed_range,
    command_int,
    command_long,
    course_deg_0_360,
    read_param_number,
    request_message_rates,
    send_checked_command,
)
from app.adapters.vehicle.autopilots.limits import SetpointLimits
from app.adapters.vehicle.autopilots.speed_lag import SpeedLag, SpeedLagParams
from app.adapters.vehicle.autopilots.turn_efficiency import (
    GRAVITY_M_S2,
    TurnEfficiency,
    TurnEfficiencyParams,
)
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
#: the least GUIDED_CHANGE_HEADING param3 ArduPlane takes (m/s^2; ``MAX(param3, 0.05f)``)
MIN_LATERAL_ACCEL_M_S2: Final = 0.05
#: GUIDED's heading loop gain: bank (centidegrees) per radian of course-over-ground error
GUIDED_P: Final = "GUIDED_P"
#: the most course error a linearised heading command asks of ArduPlane (rad)
MAX_LINEARISED_ERROR_RAD: Final = math.radians(80.0)
#: the rate asked for each message the link steers or reports on (Hz), unless told otherwise:
#: ArduPlane streams them at 1 Hz (or its SRn_ rates) to a GCS that does not ask
DEFAULT_TELEMETRY_RATE_HZ: Final = 10.0
#: GLOBAL_POSITION_INT is what the link steers on (position, velocity, time_boot_ms); ATTITUDE
#: (bank) and VFR_HUD (airspeed) are what the hand-over and the course-loop identification read.
#: HEARTBEAT is not asked: it stays at 1 Hz.
TELEMETRY_MESSAGES: Final = ("GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD")
#: how long to wait after the GCS id is ours before the GCS failsafe is enabled: 2.5 periods of
#: MAVSDK's 1 Hz heartbeat, so that ArduPlane has counted one from the new id (see ``prepare``)
GCS_HEARTBEAT_WAIT_S: Final = 2.5


def arduplane_telemetry_rates(rate_hz: float = DEFAULT_TELEMETRY_RATE_HZ) -> dict[str, float]:
    """Every message of ``TELEMETRY_MESSAGES`` at ``rate_hz``."""
    return dict.fromkeys(TELEMETRY_MESSAGES, rate_hz)


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
#: 1: ArduPlane ignores every packet not from SYSID_MYGCS (or its own system)
SYSID_ENFORCE: Final = "SYSID_ENFORCE"


@dataclass(slots=True)
class ArduPlaneAdapter:
    """ArduPlane GUIDED: course over ground, airspeed and altitude by the guided slew commands.

    Each goes out when it changes by more than its deadband; ArduPlane keeps the last one until
    the mode changes. The speed is flown as commanded (GUIDED_CHANGE_SPEED, ``honours_speed``).
    The heading command's param3 is the lateral acceleration the envelope allows at the speed
    flown, a = v * max course rate (m/s^2), v the larger of the commanded speed and the speed
    the airframe flies now: ArduPlane banks at most atan(a / g) (mode_guided.cpp
    ``ModeGuided::update``), and a coordinated turn at that bank turns at g tan(bank) / v =
    the envelope's course rate, the rate the guidance was built for. (Sized on the commanded
    speed alone, a vehicle still slowing down from 18 to a commanded 10 m/s was held to
    0.14 rad/s in real 4.6.2 SITL, and the course loop's gain was identified low.) The heading
    command is sent again when that limit changes by more than ``accel_deadband`` (10 %).
    With ``linearise_heading`` (and GUIDED_P read in ``prepare``) the course sent is the one
    that makes GUIDED's P loop turn at the rate the guidance assumes (``linearised_course``).

    **Turn efficiency.** Both of those take the turn at a bank to be the coordinated one,
    g tan(bank) / v. Real ArduPlane 4.6.2 SITL turned at 0.70 of it at every airspeed, so the
    bank limit held it to 0.14 rad/s for an envelope of 0.2 and the aircraft orbited 40-70 m
    outside a 90 m circle. With ``learn_turn_efficiency`` every frame the adapter sends on
    (GUIDED only) goes to a ``TurnEfficiency`` fit (course rate against g tan(bank) / v, the
    bank from ATTITUDE, over intervals of steady bank only: real ArduPlane's bank hunts, and
    the intervals where it changes read high); once it is ready the acceleration limit is
    v * max course rate / eta and the linearised command banks atan(k e v / (eta g)), so the
    envelope's course rate is what is flown. The fit is logged when it is first ready and
    whenever eta moves by more than ``efficiency_report_change`` (10 %). eta is at least 0.4
    (``TurnEfficiencyParams``), and ArduPlane itself caps the bank at ROLL_LIMIT_DEG.

    **Speed lag.** Real 4.6.2's airspeed followed GUIDED_CHANGE_SPEED about 3 s late (TECS).
    With ``learn_speed_lag`` every frame goes to a ``SpeedLag`` fit (the airspeed's change
    against the command in force); once it is ready the speed sent is the wanted one led
    through that lag (``SpeedLag.lead``: airspeed + (tau / 2 s)(wanted - airspeed), at most 3
    times), within the envelope's speed range, so that the airspeed closes on the wanted speed
    in about 2 s. Logged when first learned and when tau moves by 20 %. Opt-in
    (``learn_speed_lag`` is False by default): on real 4.6.2 it showed no gain in two runs and
    the learned lag drifted upward (docs/vehicle-link.md).
    The altitude command's param3 is 0: ArduPlane 4.6's GUIDED altitude slew
    (``ModeGuided::update_target_altitude``) gives TECS the *current* altitude moved toward
    the command by param3 x 0.1 s every 0.1 s, so at 3 m/s TECS saw 0.3 m of error and the
    aircraft climbed 0.05 m/s (real SITL: 25-43 m all mission for a 100 m command). With 0
    ("maximum rate", 1000 m/s) TECS gets the command and climbs at its own TECS_CLMB_MAX.
    Take-off is TAKEOFF mode: ArduPlane refuses MAV_CMD_NAV_TAKEOFF (which MAVSDK's
    ``Action.takeoff`` sends) unless it is a QuadPlane.

    **Telemetry.** ``prepare`` asks for ``telemetry_rates_hz`` (default every message of
    ``TELEMETRY_MESSAGES`` at 10 Hz) with MAV_CMD_SET_MESSAGE_INTERVAL, on this link only
    (GCS_Common.cpp ``set_message_interval``); each ACK is logged, a refusal is a warning (the
    message then comes at ArduPlane's own rate, 1 Hz by default). ArduPlane denies an interval
    shorter than its main loop allows (50 Hz loop: above 40 Hz). None asks for nothing.

    **GCS failsafe.** GUIDED has no setpoint stream and so no offboard-loss failsafe: if the app
    dies the aircraft flies its last course for ever unless ArduPlane's GCS failsafe catches it.
    Stock ArduPlane has it off (FS_GCS_ENABL 0), counts only heartbeats from SYSID_MYGCS (255,
    not MAVSDK's 245) and, in GUIDED, continues through it (FS_LONG_ACTN 0). So before take-off
    ``prepare`` reads the three and sets SYSID_MYGCS to ``gcs_system_id``, FS_LONG_ACTN 0 to 1
    (RTL) and then FS_GCS_ENABL 0 or 3 to 1 (heartbeat), logging each change; other values are
    the operator's and are kept. The order matters: ArduPlane raises the failsafe when
    FS_GCS_ENABL is on and its last heartbeat from SYSID_MYGCS (``sysid_myggcs_last_seen``,
    set at boot and by ``GCS_MAVLINK::handle_heartbeat`` only for that id) is more than
    FS_LONG_TIMEOUT (5 s) old (system.cpp ``Plane::check_long_failsafe``). Enabled the moment
    after the id changed, before a heartbeat from the new id arrived, it fires at once on a
    vehicle booted more than 5 s ago. So FS_GCS_ENABL is written only ``gcs_heartbeat_wait_s``
    (2.5 s, two and a half of MAVSDK's 1 Hz heartbeats) after the id is ours. A read or write
    that fails is a ``LinkError`` naming the parameter: a vehicle that cannot be made to return
    is refused. ``gcs_system_id`` None leaves all three alone (a warning is logged). ArduPilot
    4.7 renamed SYSID_MYGCS to MAV_GCS_SYSID (with MAV_GCS_SYSID_HI, the top of a range of GCS
    ids when not below it): when SYSID_MYGCS cannot be read, that one is checked and set
    instead (a range that holds ``gcs_system_id`` is kept).

    **QGroundControl beside the app.** SYSID_MYGCS becomes the app's own id (MAVSDK's 245), not
    QGC's 255. That does not lock QGC out: ArduPlane takes packets from every system unless
    SYSID_ENFORCE is 1 (GCS_Common.cpp ``GCS_MAVLINK::accept_packet``), so QGC at 255 still
    changes modes, takes over, reads and writes parameters and flies missions. What it loses
    while the id is ours: RC_CHANNELS_OVERRIDE and MANUAL_CONTROL (its virtual joystick), which
    ArduPlane takes only from SYSID_MYGCS (``handle_rc_channels_override``,
    ``handle_manual_control``), and its heartbeats no longer hold off the GCS failsafe. With
    SYSID_ENFORCE 1 every GCS but the app is ignored while the id is ours; that is logged as a
    warning. ``restore_params`` gives the vehicle back its originals, FS_GCS_ENABL first and
    SYSID_MYGCS last, so the failsafe is off before the id it counts goes back.

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
    accel_deadband: float = 0.1
    linearise_heading: bool = True
    learn_turn_efficiency: bool = True
    turn_efficiency_params: TurnEfficiencyParams = field(default_factory=TurnEfficiencyParams)
    efficiency_report_change: float = 0.1
    learn_speed_lag: bool = False
    #: told (t_s, tau_s, samples) whenever the speed lag is logged
    on_speed_lag_learned: Callable[[float, float, int], None] | None = None
    speed_lag_params: SpeedLagParams = field(default_factory=SpeedLagParams)
    #: told (t_s, eta, samples, turning_s) whenever the efficiency is logged
    on_turn_learned: Callable[[float, float, int, float], None] | None = None
    telemetry_rates_hz: Mapping[str, float] | None = field(
        default_factory=arduplane_telemetry_rates
    )
    gcs_heartbeat_wait_s: float = GCS_HEARTBEAT_WAIT_S
    sleep: Sleep = asyncio.sleep
    name: AutopilotName = "arduplane"
    _course_sent: float | None = field(default=None, init=False)
    _accel_sent: float | None = field(default=None, init=False)
    #: GUIDED_P as read in ``prepare`` (centidegrees of bank per radian); None: not linearised
    _guided_p: float | None = field(default=None, init=False)
    _speed_sent: float | None = field(default=None, init=False)
    _turn: TurnEfficiency = field(init=False)
    _speed_lag: SpeedLag = field(init=False)
    _speed_lag_reported: float | None = field(default=None, init=False)
    #: the efficiency last logged (None: not yet ready)
    _efficiency_reported: float | None = field(default=None, init=False)
    _altitude_sent: float | None = field(default=None, init=False)
    _journal: ParamJournal = field(init=False)

    def __post_init__(self) -> None:
        if self.telemetry_rates_hz is not None:
            check_message_rates(self.telemetry_rates_hz)
        wait = self.gcs_heartbeat_wait_s
        if not (math.isfinite(wait) and wait >= 0.0):
            raise ValueError(f"gcs_heartbeat_wait_s must be finite and >= 0, got {wait!r}")
        self._journal = ParamJournal(self.vehicle_id)
        self._turn = TurnEfficiency(self.turn_efficiency_params)
        self._speed_lag = SpeedLag(self.speed_lag_params)

    @property
    def speed_lag_s(self) -> float | None:
        """The airspeed's learned time constant behind the speed command (None: not yet, or
        not learning)."""
        return self._speed_lag.tau_s if self.learn_speed_lag else None

    def led_speed(self, wanted_m_s: float, state: VehicleState) -> float:
        """The speed to send for ``wanted_m_s``: led through the learned lag, within the
        envelope's speed range (``wanted_m_s`` as it is until the lag is learned)."""
        if not self.learn_speed_lag:
            return wanted_m_s
        led = self._speed_lag.lead(wanted_m_s, state.flying_speed_m_s)
        envelope = self.limits.envelope
        return max(envelope.min_speed_m_s, min(envelope.max_speed_m_s, led))

    def _observe_speed(self, state: VehicleState) -> None:
        sent = self._speed_sent
        if not self.learn_speed_lag or sent is None:
            return
        self._speed_lag = self._speed_lag.update(state.t_s, state.flying_speed_m_s, sent)
        tau, last = self._speed_lag.tau_s, self._speed_lag_reported
        if tau is None or (last is not None and abs(tau - last) <= 0.2 * last):
            return
        self._speed_lag_reported = tau
        log.info(
            "vehicle %d: airspeed follows the speed command with a %.1f s lag (%d samples): "
            "speed commands led through it",
            self.vehicle_id,
            tau,
            self._speed_lag.samples,
        )
        if self.on_speed_lag_learned is not None:
            self.on_speed_lag_learned(state.t_s, tau, self._speed_lag.samples)

    @property
    def turn_efficiency(self) -> float:
        """eta the bank limit and the linearised command are sized with (1 until learned or
        when not learning)."""
        return self._turn.efficiency if self.learn_turn_efficiency else 1.0

    def observe(self, state: VehicleState) -> None:
        """Feed one frame to the turn-efficiency fit; log it when it is new or has moved."""
        if not self.learn_turn_efficiency:
            return
        self._turn = self._turn.update(
            state.t_s, state.course_rad, state.roll_rad, state.flying_speed_m_s
        )
        if not self._turn.ready:
            return
        eta, last = self._turn.efficiency, self._efficiency_reported
        if last is not None and abs(eta - last) <= self.efficiency_report_change * last:
            return
        self._efficiency_reported = eta
        log.info(
            "vehicle %d: turns at %.2f of the coordinated rate for its bank (%d samples at a "
            "steady bank, %.0f s turning; %d left out while the bank changed): bank limit and "
            "heading command sized for it",
            self.vehicle_id,
            eta,
            self._turn.samples,
            self._turn.turning_s,
            self._turn.unsteady,
        )
        if self.on_turn_learned is not None:
            self.on_turn_learned(state.t_s, eta, self._turn.samples, self._turn.turning_s)

    @property
    def honours_speed(self) -> bool:
        return True

    @property
    def course_error_limit_rad(self) -> float | None:
        """W / k (the envelope's rate limit over its assumed gain) once the heading command is
        linearised: from that wanted error on, the bank asked for is the limit sent in param3,
        so ArduPlane's turn is saturated whatever its real gain. None when not linearised
        (the saturating error then depends on the airspeed)."""
        if self._guided_p is None:
            return None
        envelope = self.limits.envelope
        return min(envelope.max_course_rate_rad_s / envelope.course_gain_per_s, math.pi)

    def mode_name(self, custom_mode: int) -> str:
        return arduplane_mode_name(custom_mode)

    @property
    def control_mode(self) -> str:
        return "GUIDED"

    async def prepare(self) -> None:
        if self.linearise_heading:
            await self._read_guided_p()
        if self.check_airspeed_range:
            await check_speed_range(
                self.params,
                self.vehicle_id,
                self.limits,
                (AIRSPEED_MIN, ARSPD_FBW_MIN),
                (AIRSPEED_MAX, ARSPD_FBW_MAX),
                "this ArduPlane takes airspeeds",
            )
        if self.telemetry_rates_hz:
            await request_message_rates(
                self.commands, self.vehicle_id, self.target_component, self.telemetry_rates_hz
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
        if await self._ensure_param(
            name,
            lambda value: value == gcs or value <= gcs <= high,
            gcs,
            f"so that the GCS failsafe counts this ground station's heartbeats (system {gcs})",
            current,
        ):
            await self._warn_if_others_are_ignored(gcs, current)
        await self._ensure_param(
            FS_LONG_ACTN,
            lambda value: value != FS_LONG_ACTN_CONTINUE,
            FS_LONG_ACTN_RTL,
            "so that the GCS failsafe returns (RTL) instead of flying the last GUIDED course on",
        )
        await self._ensure_param(
            FS_GCS_ENABL,
            lambda value: value not in FS_GCS_ENABL_NOT_IN_GUIDED,
            FS_GCS_ENABL_HEARTBEAT,
            "so that losing this ground station's heartbeats raises the GCS failsafe in GUIDED",
            before_write=self._wait_for_our_heartbeat,
        )

    async def _read_guided_p(self) -> None:
        found = await read_param_number(self.params, GUIDED_P)
        p = None if found is None else found[1]
        if p is None or not (math.isfinite(p) and p > 0.0):
            log.warning(
                "vehicle %d: %s %s: heading commands sent as the course wanted (not linearised;"
                " the course loop's gain then varies as 1 / airspeed)",
                self.vehicle_id,
                GUIDED_P,
                "unreadable" if p is None else f"= {p!r}",
            )
            self._guided_p = None
            return
        self._guided_p = p
        log.info(
            "vehicle %d: %s = %g: heading commands linearised to the course loop's k = %.2f /s",
            self.vehicle_id,
            GUIDED_P,
            p,
            self.limits.envelope.course_gain_per_s,
        )

    def linearised_course(self, course_rad: float, state: VehicleState, speed_m_s: float) -> float:
        """The course to send so that ArduPlane turns as the loop guidance assumes.

        GUIDED banks P x (course error) (``ModeGuided::update``; P = GUIDED_P centidegrees per
        radian, stock 5000: 0.87 rad of bank per radian) and a coordinated turn at that bank
        turns at g tan(bank) / V: a course-loop gain g P' / V that halves from 10 to 20 m/s.
        Guidance assumes rate = k e with k the envelope's ``course_gain_per_s``. So for the
        wanted error e = wrap(command - course) this sends the error e' with
        P' e' = atan(k e V / (eta g)), eta the ``turn_efficiency``: ArduPlane then turns at k e
        at any airspeed V (the speed flown, else the commanded one). Unchanged when GUIDED_P was
        not read."""
        p = self._guided_p
        if p is None:
            return course_rad
        bank_per_rad = math.radians(p / 100.0)
        speed = speed_m_s
        if state.flying_speed_m_s is not None and math.isfinite(state.flying_speed_m_s):
            speed = max(state.flying_speed_m_s, 1.0)
        error = wrap_pi(course_rad - state.course_rad)
        k = self.limits.envelope.course_gain_per_s
        eta = self.turn_efficiency
        wanted = math.atan(k * error * speed / (eta * GRAVITY_M_S2)) / bank_per_rad
        wanted = max(-MAX_LINEARISED_ERROR_RAD, min(MAX_LINEARISED_ERROR_RAD, wanted))
        return wrap_pi(state.course_rad + wanted)

    async def _wait_for_our_heartbeat(self) -> None:
        """Let ArduPlane count a heartbeat from the GCS id before its failsafe is enabled."""
        log.info(
            "vehicle %d: waiting %.1f s for it to hear our heartbeat before enabling %s",
            self.vehicle_id,
            self.gcs_heartbeat_wait_s,
            FS_GCS_ENABL,
        )
        await self.sleep(self.gcs_heartbeat_wait_s)

    async def _warn_if_others_are_ignored(self, gcs: int, previous: int) -> None:
        try:
            enforced = await self.params.get_param_int(SYSID_ENFORCE)
        except ParamError:
            return
        if enforced:
            log.warning(
                "vehicle %d: %s is 1: while the GCS id is %d, the vehicle ignores every other "
                "ground station (system %d before, a QGroundControl at 255); restored at the end",
                self.vehicle_id,
                SYSID_ENFORCE,
                gcs,
                previous,
            )

    async def restore_params(self) -> None:
        """Write back what ``prepare`` changed: FS_GCS_ENABL, then FS_LONG_ACTN, then the GCS id
        (the reverse of the order they were set), so the failsafe is off before the id it
        counts changes. Failures are logged; nothing is raised."""
        await self._journal.restore(self.params)

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
        before_write: Callable[[], Awaitable[None]] | None = None,
    ) -> bool:
        """Read ``name`` (unless its ``current`` value is given); when it is not acceptable
        (await ``before_write`` and) set it to ``wanted``, record its original for
        ``restore_params`` and say why. True when it was changed."""
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
            return False
        if before_write is not None:
            await before_write()
        try:
            await self.params.set_param_int(name, wanted)
        except ParamError as exc:
            raise LinkError(
                f"vehicle {self.vehicle_id}: cannot set {name} from {current} to {wanted}: "
                f"{exc.result.name}; refusing a vehicle whose GCS failsafe cannot be made to "
                "return it"
            ) from exc
        self._journal.record(name, current)
        log.warning(
            "vehicle %d: set %s from %d to %d %s (restored at the end)",
            self.vehicle_id,
            name,
            current,
            wanted,
            why,
        )
        return True

    def mode_command(self, custom_mode: int) -> MavlinkMessage:
        return command_long(
            self.vehicle_id,
            self.target_component,
            mavlink.MAV_CMD_DO_SET_MODE,
            (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode),
        )

    def lateral_accel_limit(self, speed_m_s: float, flying_speed_m_s: float | None) -> float:
        """v * max course rate / eta (m/s^2), v the larger of the commanded speed and the speed
        flown (when known and finite), eta the ``turn_efficiency``, at least ArduPlane's floor
        of 0.05."""
        speed = speed_m_s
        if flying_speed_m_s is not None and math.isfinite(flying_speed_m_s):
            speed = max(speed, flying_speed_m_s)
        rate = self.limits.envelope.max_course_rate_rad_s
        return max(speed * rate / self.turn_efficiency, MIN_LATERAL_ACCEL_M_S2)

    def heading_command(
        self, course_rad: float, speed_m_s: float, flying_speed_m_s: float | None = None
    ) -> MavlinkMessage:
        """GUIDED_CHANGE_HEADING: param1 course over ground, param2 the course (deg, [0, 360)),
        param3 the lateral acceleration limit (``lateral_accel_limit``; the envelope's rate
        whether or not the setpoints' course change is limited)."""
        return command_int(
            self.vehicle_id,
            self.target_component,
            mavlink.MAV_CMD_GUIDED_CHANGE_HEADING,
            (
                mavlink.HEADING_TYPE_COURSE_OVER_GROUND,
                course_deg_0_360(course_rad),
                self.lateral_accel_limit(speed_m_s, flying_speed_m_s),
                0.0,
            ),
        )

    def speed_command(self, speed_m_s: float) -> MavlinkMessage:
        """GUIDED_CHANGE_SPEED: param3 the slew of ArduPlane's airspeed target (m/s^2), the
        envelope's acceleration, or 0 ("at once", 1000 m/s^2) while the speed is led through
        the learned lag: a slewed target would slow the led command down, the fit would read
        that as more lag, and lead harder (real 4.6.2, ap8: tau 3-4 s learned first, 7-8 s by
        the end)."""
        slew = 0.0 if self.learn_speed_lag else self.limits.envelope.max_accel_m_s2
        return command_int(
            self.vehicle_id,
            self.target_component,
            mavlink.MAV_CMD_GUIDED_CHANGE_SPEED,
            (mavlink.SPEED_TYPE_AIRSPEED, speed_m_s, slew, 0.0),
        )

    def altitude_command(self, altitude_m: float) -> MavlinkMessage:
        return command_int(
            self.vehicle_id,
            self.target_component,
            mavlink.MAV_CMD_GUIDED_CHANGE_ALTITUDE,
            (0.0, 0.0, 0.0, 0.0),  # param3 0: TECS's own climb rate (class docstring)
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
        self._course_sent = self._accel_sent = self._speed_sent = self._altitude_sent = None
        await self.send(setpoint, altitude_m, state)

    async def send(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        # the course that goes out (linearised, it moves as the vehicle turns even for a
        # constant wanted course, and comes to it as the error closes) is what the deadband
        # compares with the last one sent
        self.observe(state)
        self._observe_speed(state)
        course, accel_sent = self._course_sent, self._accel_sent
        sent = self.linearised_course(setpoint.course_rad, state, setpoint.speed_m_s)
        accel = self.lateral_accel_limit(setpoint.speed_m_s, state.flying_speed_m_s)
        if (
            course is None
            or accel_sent is None
            or abs(wrap_pi(sent - course)) > self.course_deadband_rad
            or abs(accel - accel_sent) > self.accel_deadband * accel_sent
        ):
            await self._send(
                self.heading_command(sent, setpoint.speed_m_s, state.flying_speed_m_s),
                "GUIDED_CHANGE_HEADING",
            )
            self._course_sent, self._accel_sent = sent, accel
        speed, wanted = self._speed_sent, self.led_speed(setpoint.speed_m_s, state)
        if speed is None or abs(wanted - speed) > self.speed_deadband_m_s:
            await self._send(self.speed_command(wanted), "GUIDED_CHANGE_SPEED")
            self._speed_sent = wanted
        alt = self._altitude_sent
        if alt is None or abs(altitude_m - alt) > self.altitude_deadband_m:
            await self._send(self.altitude_command(altitude_m), "GUIDED_CHANGE_ALTITUDE")
            self._altitude_sent = altitude_m

    async def stop(self) -> None:
        await self._send(self.mode_command(ARDUPLANE_LOITER), "mode change to LOITER")
