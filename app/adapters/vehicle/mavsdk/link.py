"""One vehicle over MAVSDK 4.x: the link's state machine (telemetry, offboard, link loss).

Kinematic telemetry is read from GLOBAL_POSITION_INT through MavlinkDirect, so that every frame
carries the vehicle's own ``time_boot_ms`` with a consistent position and velocity; given a
mission clock, the link maps that boot time onto it (``clockmap.BootClockMap``: one offset per
vehicle, from the host's receive times) and stamps every frame and observation with mission time,
so that vehicles booted at different times agree. Flight mode and armed state come from the
autopilot's HEARTBEAT (decoded by the autopilot adapter); airspeed from VFR_HUD; health and
in-air from the Telemetry plugin; target observations from CAMERA_TRACKING_GEO_STATUS. The
messages are decoded by ``app.adapters.vehicle.mavsdk.telemetry``. Every MAVSDK exception is
translated into ``LinkError`` here, with ``from exc``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from collections.abc import Callable, Mapping
from contextlib import AsyncExitStack, aclosing
from dataclasses import dataclass, field, replace
from types import TracebackType
from typing import Any

from mavsdk import System
from mavsdk.asyncio import MavsdkError
from mavsdk.asyncio import System as AsyncSystem
from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.autopilot import Autopilot
from mavsdk.plugins.mavlink_direct import MavlinkDirect, MavlinkDirectError, MavlinkMessage
from mavsdk.plugins.offboard import Offboard
from pymavlink.dialects.v20 import common as mavlink

from app.adapters.vehicle.autopilots.arduplane import ArduPlaneAdapter
from app.adapters.vehicle.autopilots.base import (
    MAVSDK_GCS_SYSTEM_ID,
    AutopilotAdapter,
    AutopilotName,
    VehicleState,
    choose_autopilot,
)
from app.adapters.vehicle.autopilots.limits import SentSetpoint, SetpointLimits, limit_setpoint
from app.adapters.vehicle.autopilots.px4 import Px4FixedWingAdapter
from app.adapters.vehicle.autopilots.velocity import VelocityAdapter
from app.adapters.vehicle.mavsdk import telemetry
from app.adapters.vehicle.mavsdk.broadcast import Broadcast, Subscription
from app.adapters.vehicle.mavsdk.clockmap import BootClockMap, Rebase
from app.adapters.vehicle.mavsdk.direct import LoopInbox, LoopMavlinkDirect, LoopOffboard
from app.adapters.vehicle.mavsdk.timesync import LinkDelay, follow
from app.errors import LinkError
from app.runtime.ports.vehicle import (
    ClockRebased,
    CourseSpeedCommand,
    GeodeticOrigin,
    LeftOffboard,
    LinkEvent,
    LinkLost,
    LinkRestored,
    OffboardLostError,
    SetpointLimited,
    SpeedLagLearned,
    TargetObservation,
    TurnLearned,
    VehicleClockReset,
    VehicleTelemetry,
)

log = logging.getLogger(__name__)

#: an autopilot wind estimate older than this (wall s) is no longer given with the frames
WIND_STALE_S = 10.0
#: a bank (ATTITUDE) older than this (s) is not given to the adapter
ROLL_STALE_S = 1.0


#: what MAVSDK reports before it has heard the autopilot's HEARTBEAT
GENERIC_AUTOPILOTS: tuple[Autopilot, ...] = (Autopilot.GENERIC, Autopilot.UNKNOWN)


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """How one vehicle link behaves.

    ``autopilot``: force an adapter (None: chosen from what the vehicle reports).
    ``link_timeout_s``: wall-clock silence after which the link is declared lost.
    ``camera_component_id``: the component whose CAMERA_TRACKING_GEO_STATUS counts (None: any).
    ``airborne_altitude_m``: above this height over home the vehicle counts as in the air even
    before its landed state (EXTENDED_SYS_STATE, often 1 Hz) says so.
    ``px4_offboard_loss_action``: COM_OBL_RC_ACT to set on PX4 (None: leave it alone).
    ``arduplane_gcs_failsafe``: on ArduPlane, set SYSID_MYGCS to our system id and make the GCS
    failsafe return the aircraft (False: leave SYSID_MYGCS, FS_GCS_ENABL, FS_LONG_ACTN alone).
    ``arduplane_airspeed_check``: on ArduPlane, refuse a vehicle whose AIRSPEED_MIN..MAX does
    not hold the mission's speeds (False: do not read them).
    ``arduplane_turn_learning``: on ArduPlane, size the turn limit and the heading command on
    the turn efficiency learned in flight (``ArduPlaneAdapter.learn_turn_efficiency``);
    ``arduplane_speed_learning``: lead its speed commands through the airspeed's learned lag
    (``learn_speed_lag``; off by default).
    ``px4_airspeed_via_trim``: on PX4, fly the commanded airspeed by writing FW_AIRSPD_TRIM
    (``Px4FixedWingAdapter.airspeed_via_trim_param``; off by default: a parameter write per
    change, at most one per 5 s).
    ``px4_telemetry_rates_hz``: on PX4, the message rates to ask for (by MAVLink name; put
    back at PX4's own rates at the end; None: PX4's own rates, 50 Hz position on an onboard
    link); ``autopilots.px4.px4_mission_rates``.
    ``heartbeat_timeout_s``: when MAVSDK still reports a generic autopilot at connection (it
    found the vehicle by another message before its first HEARTBEAT: ArduPilot sends HEARTBEAT
    at 1 Hz and streams faster), how long to wait for the autopilot's HEARTBEAT before choosing
    the adapter.
    ``clock_window_s``: how much mission time of receive times the boot-clock offset is the least
    of (``BootClockMap``); ``clock_reset_s``: a boot time going back by more than this, or leaping
    ahead of the host's clock by more, is a new boot clock.
    ``restore_timeout_s``: how long the exit path waits for the adapter to put back the
    parameters it changed.
    ``timesync_period_s``: how often (wall s) a TIMESYNC request measures the link's round trip
    (``timesync.LinkDelay``); with a mission clock, every frame's stamp is then moved back by
    the measured one-way delay, at most ``delay_step_s`` per frame (0: not measured, frames
    stamped when they arrive).
    """

    limits: SetpointLimits
    autopilot: AutopilotName | None = None
    link_timeout_s: float = 2.0
    mode_confirm_timeout_s: float = 3.0
    hold_timeout_s: float = 3.0
    clock_reset_s: float = 5.0
    camera_component_id: int | None = mavlink.MAV_COMP_ID_CAMERA
    autopilot_component_id: int = mavlink.MAV_COMP_ID_AUTOPILOT1
    px4_offboard_loss_action: int | None = 5
    arduplane_gcs_failsafe: bool = True
    arduplane_airspeed_check: bool = True
    arduplane_turn_learning: bool = True
    arduplane_speed_learning: bool = False
    px4_airspeed_via_trim: bool = False
    px4_telemetry_rates_hz: Mapping[str, float] | None = None
    airborne_altitude_m: float = 5.0
    hold_on_exit: bool = True
    queue_size: int = 256
    heartbeat_timeout_s: float = 3.0
    clock_window_s: float = 10.0
    restore_timeout_s: float = 5.0
    timesync_period_s: float = 1.0
    delay_step_s: float = 0.005

    def __post_init__(self) -> None:
        for name in ("timesync_period_s", "delay_step_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
        for name in (
            "link_timeout_s",
            "mode_confirm_timeout_s",
            "hold_timeout_s",
            "clock_reset_s",
            "heartbeat_timeout_s",
            "clock_window_s",
            "restore_timeout_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if self.queue_size < 1:
            raise ValueError(f"queue_size must be >= 1, got {self.queue_size}")


@dataclass(slots=True)
class LinkCounters:
    """What a link dropped or changed, counted (the event log reads these at the end);
    ``turn_efficiency``, ``speed_lag_s``: the ArduPlane adapter's last learned ones (None: not
    learned)."""

    frames: int = 0
    stale_frames: int = 0
    malformed: int = 0
    observations: int = 0
    observations_dropped: int = 0
    setpoints: int = 0
    setpoints_limited: int = 0
    link_losses: int = 0
    left_offboard: int = 0
    clock_rebases: int = 0
    limited_by: dict[str, int] = field(default_factory=dict)
    turn_efficiency: float | None = None
    speed_lag_s: float | None = None
    #: TIMESYNC answers taken, the least round trip (s) and the one-way delay the frames'
    #: stamps are moved back by (s; mission time)
    timesync_answers: int = 0
    round_trip_min_s: float | None = None
    link_delay_s: float = 0.0


class MavsdkVehicleLink:
    """One vehicle over MAVSDK; an async context manager that runs its readers in a TaskGroup.

    Built by ``MavsdkHub.link``; see ``app.runtime.ports.vehicle.VehicleLink`` for the contract.
    ``clock`` is the host's monotonic clock (link silence, frame age); ``mission_clock`` reads
    mission time on the host (``app.runtime.ports.clock.MissionClock``): given, every frame is
    stamped with its boot time mapped onto it; None (or while it returns None: its epoch is not
    known yet), with the vehicle's own boot time. ``inbox`` hands the subscribed messages to the
    loop (the hub's, shared by its links; None: one of the link's own).
    """

    def __init__(
        self,
        system: System,
        system_id: int,
        origin: GeodeticOrigin,
        config: LinkConfig,
        clock: Callable[[], float] = time.monotonic,
        gcs_system_id: int = MAVSDK_GCS_SYSTEM_ID,
        mission_clock: Callable[[], float | None] | None = None,
        *,
        inbox: LoopInbox | None = None,
    ) -> None:
        self._system = system
        self._inbox = inbox
        self._mission_clock = mission_clock
        self._boot_clock = BootClockMap(config.clock_window_s, config.clock_reset_s)
        self._delay = LinkDelay()
        self._airspeed_m_s: float | None = None
        #: the autopilot's newest bank (ATTITUDE roll, rad) and the link-clock time it came
        self._roll_rad: float | None = None
        self._roll_at_s = -math.inf
        #: the autopilot's newest wind estimate and the monotonic time it came
        self._wind: tuple[float, float] | None = None
        self._wind_at_s = -math.inf
        self._gcs_system_id = gcs_system_id
        self._id = system_id
        self._origin = origin
        self._config = config
        self._clock = clock
        self.counters = LinkCounters()
        self._telemetry: Broadcast[VehicleTelemetry] = Broadcast(
            f"vehicle {system_id} telemetry", config.queue_size
        )
        self._observations: Broadcast[TargetObservation] = Broadcast(
            f"vehicle {system_id} observations", config.queue_size
        )
        self._events: Broadcast[LinkEvent] = Broadcast(
            f"vehicle {system_id} events", config.queue_size
        )
        self._latest: VehicleTelemetry | None = None
        self._last_rx: float | None = None
        self._link_ok = False
        # after a link loss: whether a HEARTBEAT has come since (its mode is known again)
        self._heard_since_loss = True
        self._mode = "UNKNOWN"
        self._armed = False
        self._in_air = False
        self._global_ok = False
        self._local_ned: tuple[float, float, float] | None = None
        self._offboard = "idle"  # idle | starting | active | left
        self._hold_altitude_m = 0.0
        self._previous: SentSetpoint | None = None
        self._limited_burst = False
        self._changed = asyncio.Condition()
        self._send_lock = asyncio.Lock()
        self._stack = AsyncExitStack()
        self._tasks: list[asyncio.Task[None]] = []
        self._adapter: AutopilotAdapter | None = None

    # -- properties ------------------------------------------------------------------------

    @property
    def vehicle_id(self) -> int:
        return self._id

    @property
    def autopilot_name(self) -> str:
        return self._require_adapter().name

    @property
    def readers(self) -> tuple[str, ...]:
        """The link's reader tasks by name ("position", "airspeed", ...; "attitude" for
        ArduPlane, "local-position" for PX4), in the order they started."""
        prefix = f"vehicle{self._id}-"
        return tuple(task.get_name().removeprefix(prefix) for task in self._tasks)

    @property
    def honours_speed(self) -> bool:
        return self._require_adapter().honours_speed

    @property
    def course_error_limit_rad(self) -> float | None:
        return getattr(self._require_adapter(), "course_error_limit_rad", None)

    @property
    def latest(self) -> VehicleTelemetry | None:
        return self._latest

    @property
    def latest_age_s(self) -> float | None:
        """Host seconds since the newest frame arrived (None before the first): how long it has
        waited for the agent, which on a busy machine is most of the lag it steers with."""
        return None if self._last_rx is None else self._clock() - self._last_rx

    @property
    def link_ok(self) -> bool:
        return self._link_ok

    @property
    def flight_mode(self) -> str:
        return self._mode

    def _require_adapter(self) -> AutopilotAdapter:
        if self._adapter is None:
            raise LinkError(f"vehicle {self._id}: link not open (use it as 'async with')")
        return self._adapter

    # -- lifecycle -------------------------------------------------------------------------

    async def __aenter__(self) -> MavsdkVehicleLink:
        async with AsyncExitStack() as stack:
            try:
                system = AsyncSystem(self._system)
                inbox = self._inbox or LoopInbox(asyncio.get_running_loop())
                self._tel = TelemetryAsync(system)
                self._action = ActionAsync(system)
                self._offboard_plugin = LoopOffboard(Offboard(self._system))
                self._direct = LoopMavlinkDirect(MavlinkDirect(self._system), inbox)
                self._param = ParamAsync(system)
                autopilot = self._system.autopilot_type()
                vehicle = self._system.vehicle_type()
                if self._config.autopilot is None and autopilot in GENERIC_AUTOPILOTS:
                    await self._first_heartbeat()
                    autopilot = self._system.autopilot_type()
                    vehicle = self._system.vehicle_type()
            except (MavsdkError, RuntimeError) as exc:
                raise LinkError(f"vehicle {self._id}: cannot open its plugins: {exc}") from exc
            name = choose_autopilot(autopilot, vehicle, self._config.autopilot, self._id)
            self._adapter = self._build_adapter(name)
            log.info(
                "vehicle %d: autopilot %s, vehicle type %s -> adapter %s",
                self._id,
                autopilot.name,
                vehicle.name,
                name,
            )
            group = await stack.enter_async_context(asyncio.TaskGroup())
            readers = {
                "heartbeat": self._read_heartbeat(),
                "position": self._read_global_position(),
                "airspeed": self._read_airspeed(),
                "wind": self._read_wind(name),
                "health": self._read_health(),
                "in-air": self._read_in_air(),
                "observations": self._read_observations(),
                "watchdog": self._watchdog(),
            }
            # each message read costs a call from MAVSDK's one callback thread into Python, which
            # waits for the interpreter while the agents step: read only what the adapter uses
            # (the bank for ArduPlane's turn fit, the local position for PX4's setpoints)
            if name == "arduplane":
                readers["attitude"] = self._read_attitude()
            if name == "px4-fixed-wing":
                readers["local-position"] = self._read_local_position()
            if self._config.timesync_period_s > 0.0:
                readers["timesync"] = self._read_timesync()
                readers["timesync-requests"] = self._request_timesync()
            for reader, coro in readers.items():
                self._tasks.append(group.create_task(coro, name=f"vehicle{self._id}-{reader}"))
            self._stack = stack.pop_all()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        try:
            if self._config.hold_on_exit and self._offboard in ("starting", "active"):
                await self._hold_on_exit(failing=exc is not None)
        finally:
            try:
                await self._restore_params()  # after the hold, while the readers still run
            finally:
                for task in self._tasks:
                    task.cancel()
            try:
                suppressed = await self._stack.__aexit__(exc_type, exc, tb)
            finally:
                self._telemetry.close()
                self._observations.close()
                self._events.close()
        return suppressed

    async def _hold_on_exit(self, *, failing: bool) -> None:
        if not self._link_ok:
            log.warning("vehicle %d: link lost, cannot put it in hold on exit", self._id)
            return
        try:
            async with asyncio.timeout(self._config.hold_timeout_s):
                await self.hold()
        except (LinkError, TimeoutError) as exc:
            log.error("vehicle %d: hold on exit failed: %s", self._id, exc)
            if not failing:
                raise LinkError(f"vehicle {self._id}: hold on exit failed: {exc}") from exc

    async def _restore_params(self) -> None:
        """Put back the parameters the adapter changed (after the hold, bounded in time); a
        failure is logged, never raised: the link is closing anyway."""
        adapter = self._adapter
        if adapter is None:
            return
        if not self._link_ok:
            log.error(
                "vehicle %d: link lost, the parameters the mission changed are not restored",
                self._id,
            )
            return
        try:
            async with asyncio.timeout(self._config.restore_timeout_s):
                await adapter.restore_params()
        except (LinkError, MavsdkError, TimeoutError) as exc:
            log.error(
                "vehicle %d: restoring its parameters failed: %s",
                self._id,
                exc or f"no answer within {self._config.restore_timeout_s} s",
            )

    def _build_adapter(self, name: AutopilotName) -> AutopilotAdapter:
        limits = self._config.limits
        if name == "px4-fixed-wing":
            return Px4FixedWingAdapter(
                vehicle_id=self._id,
                offboard=self._offboard_plugin,
                commands=self._direct,
                params=self._param,
                limits=limits,
                target_component=self._config.autopilot_component_id,
                offboard_loss_action=self._config.px4_offboard_loss_action,
                airspeed_via_trim_param=self._config.px4_airspeed_via_trim,
                telemetry_rates_hz=self._config.px4_telemetry_rates_hz,
            )
        if name == "arduplane":
            return ArduPlaneAdapter(
                vehicle_id=self._id,
                commands=self._direct,
                params=self._param,
                limits=limits,
                gcs_system_id=self._gcs_system_id if self._config.arduplane_gcs_failsafe else None,
                check_airspeed_range=self._config.arduplane_airspeed_check,
                learn_turn_efficiency=self._config.arduplane_turn_learning,
                learn_speed_lag=self._config.arduplane_speed_learning,
                on_turn_learned=self._turn_learned,
                on_speed_lag_learned=self._speed_lag_learned,
                target_component=self._config.autopilot_component_id,
            )
        return VelocityAdapter(vehicle_id=self._id, offboard=self._offboard_plugin, limits=limits)

    # -- streams ---------------------------------------------------------------------------

    def telemetry(self) -> Subscription[VehicleTelemetry]:
        return self._telemetry.subscribe()

    def observations(self) -> Subscription[TargetObservation]:
        return self._observations.subscribe()

    def events(self) -> Subscription[LinkEvent]:
        return self._events.subscribe()

    async def _notify(self) -> None:
        async with self._changed:
            self._changed.notify_all()

    async def _wait_for(self, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
        try:
            async with asyncio.timeout(timeout_s):
                async with self._changed:
                    await self._changed.wait_for(predicate)
        except TimeoutError as exc:
            raise LinkError(f"vehicle {self._id}: {what} within {timeout_s} s") from exc

    # -- readers (tasks) -------------------------------------------------------------------

    async def _first_heartbeat(self) -> None:
        """Wait (``heartbeat_timeout_s`` at most) for the autopilot's first HEARTBEAT, by which
        MAVSDK knows which autopilot it is; on time-out the vehicle stays generic."""
        try:
            async with (
                asyncio.timeout(self._config.heartbeat_timeout_s),
                aclosing(self._direct.subscribe_message("HEARTBEAT")) as messages,
            ):
                async for message in messages:
                    if message.component_id == self._config.autopilot_component_id:
                        break
            await asyncio.sleep(0)  # MAVSDK's own handler of the same message runs first
        except TimeoutError:
            log.warning(
                "vehicle %d: no HEARTBEAT from its autopilot within %.1f s; it is taken for a "
                "generic autopilot",
                self._id,
                self._config.heartbeat_timeout_s,
            )

    async def _read_heartbeat(self) -> None:
        adapter = self._require_adapter()
        async with aclosing(self._direct.subscribe_message("HEARTBEAT")) as messages:
            async for message in messages:
                if message.component_id != self._config.autopilot_component_id:
                    continue
                try:
                    custom_mode, armed = telemetry.heartbeat_modes(telemetry.fields(message))
                except (ValueError, KeyError, TypeError) as exc:
                    self._malformed("HEARTBEAT", exc)
                    continue
                self._mode = adapter.mode_name(custom_mode)
                self._armed = armed
                if self._offboard == "active" and self._mode != adapter.control_mode:
                    self._offboard = "left"
                    self.counters.left_offboard += 1
                    t_s = self._latest.t_s if self._latest else 0.0
                    log.error(
                        "vehicle %d left %s on its own: now in %s",
                        self._id,
                        adapter.control_mode,
                        self._mode,
                    )
                    self._events.publish(LeftOffboard(self._id, t_s, self._mode))
                self._heard_since_loss = True
                await self._notify()

    async def _read_global_position(self) -> None:
        async with aclosing(self._direct.subscribe_message("GLOBAL_POSITION_INT")) as messages:
            async for message in messages:
                if message.component_id != self._config.autopilot_component_id:
                    continue
                try:
                    frame = self._frame(telemetry.fields(message))
                except (ValueError, KeyError, TypeError) as exc:
                    self._malformed("GLOBAL_POSITION_INT", exc)
                    continue
                if frame is None:
                    continue
                self._last_rx = self._clock()
                if not self._link_ok:
                    if self._latest is not None and not self._heard_since_loss:
                        # back, but in a mode unknown until its next HEARTBEAT (1 Hz on
                        # ArduPilot): its failsafe may have taken it; restored only then, after
                        # the mode change is reported, so it is not readmitted for a second
                        frame = replace(frame, link_ok=False)
                    else:
                        if self._latest is not None:
                            log.warning("vehicle %d: link restored at t=%.2f", self._id, frame.t_s)
                            self._events.publish(LinkRestored(self._id, frame.t_s))
                        self._link_ok = True
                self._latest = frame
                self.counters.frames += 1
                self._telemetry.publish(frame)
                await self._notify()

    def _frame(self, f: dict[str, Any]) -> VehicleTelemetry | None:
        """A GLOBAL_POSITION_INT as the next frame; None for a late or repeated one (counted).

        With a mission clock its time is the boot time mapped onto it (a reboot re-bases the
        offset: an event, and mission time goes on); while that clock has no epoch yet (it
        returns None) and without one, the boot time, and time going back by ``clock_reset_s``
        or more is a reboot: an event, and a new start."""
        t_s = telemetry.time_boot_s(f)
        host_t = self._mission_clock() if self._mission_clock is not None else None
        previous = self._latest
        if host_t is not None:
            t_s, rebase = self._boot_clock.update(t_s, host_t)
            t_s -= self._delay_correction()
            if rebase is not None:
                if previous is not None:  # a new base: nothing before it to be late against
                    self._previous = None
                if rebase.reason != "first":
                    self._rebased(rebase, t_s)
            elif previous is not None and t_s <= previous.t_s:
                self.counters.stale_frames += 1
                return None
        elif previous is not None and t_s <= previous.t_s:
            if previous.t_s - t_s < self._config.clock_reset_s:
                self.counters.stale_frames += 1
                return None
            log.warning("vehicle %d: clock reset %.2f -> %.2f s", self._id, previous.t_s, t_s)
            self._events.publish(VehicleClockReset(self._id, t_s, previous.t_s))
            self._previous = None
        return telemetry.global_position(
            f,
            self._id,
            self._origin,
            flight_mode=self._mode,
            armed=self._armed,
            landed_state_in_air=self._in_air,
            airborne_altitude_m=self._config.airborne_altitude_m,
            t_s=t_s,
            airspeed_m_s=self._airspeed_m_s,
            wind_m_s=self._current_wind(),
        )

    def _delay_correction(self) -> float:
        """The one-way delay this frame's stamp is moved back by: the measured one
        (``LinkDelay.one_way_s``; 0 before the first answer), followed at most
        ``delay_step_s`` per frame."""
        c = self.counters
        wanted = self._delay.one_way_s or 0.0
        c.link_delay_s = follow(c.link_delay_s, wanted, self._config.delay_step_s)
        return c.link_delay_s

    def _host_time(self) -> float:
        """The host's time the round trips are measured on: mission time where there is a
        mission clock (the frames' stamps are), else the monotonic clock."""
        mission = self._mission_clock() if self._mission_clock is not None else None
        return self._clock() if mission is None else mission

    async def _request_timesync(self) -> None:
        """A TIMESYNC request (tc1 = 0, ts1 unique) every ``timesync_period_s`` of wall time."""
        period = self._config.timesync_period_s
        adapter_component = self._config.autopilot_component_id
        while True:
            ts1 = time.monotonic_ns()
            self._delay.sent(ts1, self._host_time())
            fields = {
                "tc1": 0,
                "ts1": ts1,
                "target_system": self._id,
                "target_component": adapter_component,
            }
            message = MavlinkMessage(
                message_name="TIMESYNC",
                target_system_id=self._id,
                target_component_id=adapter_component,
                fields_json=json.dumps(fields),
            )
            try:
                await self._direct.send_message(message)
            except (MavsdkError, MavlinkDirectError, RuntimeError) as exc:
                log.debug("vehicle %d: TIMESYNC request not sent: %s", self._id, exc)
            await asyncio.sleep(period)

    async def _read_timesync(self) -> None:
        """Answers to our TIMESYNC requests (tc1 != 0, ts1 ours); the vehicle's own requests
        (tc1 = 0) and answers to others' are not ours to take."""
        async with aclosing(self._direct.subscribe_message("TIMESYNC")) as messages:
            async for message in messages:
                try:
                    f = telemetry.fields(message)
                    tc1, ts1 = int(f["tc1"]), int(f["ts1"])
                except (ValueError, KeyError, TypeError) as exc:
                    self._malformed("TIMESYNC", exc)
                    continue
                if tc1 == 0:
                    continue
                if self._delay.answered(ts1, self._host_time()) is not None:
                    c = self.counters
                    c.timesync_answers = self._delay.answers
                    one_way = self._delay.one_way_s
                    c.round_trip_min_s = None if one_way is None else 2.0 * one_way

    def _current_wind(self) -> tuple[float, float] | None:
        """The autopilot's wind, unless it has not come for ``WIND_STALE_S`` (PX4 sends it at
        0.5-1 Hz, ArduPlane with its EXTRA3 stream)."""
        if time.monotonic() - self._wind_at_s > WIND_STALE_S:
            return None
        return self._wind

    def _rebased(self, rebase: Rebase, t_s: float) -> None:
        self.counters.clock_rebases += 1
        log.warning(
            "vehicle %d: boot clock %s (%.2f -> %.2f s): offset %.3f -> %.3f s, mission time "
            "goes on",
            self._id,
            "reset" if rebase.reason == "reboot" else "jumped",
            rebase.previous_boot_s if rebase.previous_boot_s is not None else math.nan,
            rebase.boot_s,
            rebase.previous_offset_s if rebase.previous_offset_s is not None else math.nan,
            rebase.offset_s,
        )
        self._events.publish(
            ClockRebased(
                self._id,
                t_s,
                rebase.reason,
                rebase.boot_s,
                rebase.previous_boot_s,
                rebase.offset_s,
                rebase.previous_offset_s,
            )
        )

    async def _read_airspeed(self) -> None:
        async with aclosing(self._direct.subscribe_message("VFR_HUD")) as messages:
            async for message in messages:
                if message.component_id != self._config.autopilot_component_id:
                    continue
                try:
                    self._airspeed_m_s = telemetry.vfr_hud_airspeed(telemetry.fields(message))
                except (ValueError, KeyError, TypeError) as exc:
                    self._malformed("VFR_HUD", exc)

    def _turn_learned(self, t_s: float, efficiency: float, samples: int, turning_s: float) -> None:
        self.counters.turn_efficiency = round(efficiency, 3)
        self._events.publish(TurnLearned(self._id, t_s, efficiency, samples, turning_s))

    def _speed_lag_learned(self, t_s: float, tau_s: float, samples: int) -> None:
        self.counters.speed_lag_s = round(tau_s, 2)
        self._events.publish(SpeedLagLearned(self._id, t_s, tau_s, samples))

    async def _read_attitude(self) -> None:
        async with aclosing(self._direct.subscribe_message("ATTITUDE")) as messages:
            async for message in messages:
                if message.component_id != self._config.autopilot_component_id:
                    continue
                try:
                    roll = telemetry.attitude_roll(telemetry.fields(message))
                except (ValueError, KeyError, TypeError) as exc:
                    self._malformed("ATTITUDE", exc)
                    continue
                if roll is not None:
                    self._roll_rad, self._roll_at_s = roll, self._clock()

    async def _read_wind(self, adapter: str) -> None:
        """The autopilot's wind estimate: WIND_COV from PX4, WIND (ardupilotmega) from
        ArduPilot."""
        name, decode = (
            ("WIND", telemetry.ardupilot_wind)
            if adapter == "arduplane"
            else ("WIND_COV", telemetry.wind_cov)
        )
        async with aclosing(self._direct.subscribe_message(name)) as messages:
            async for message in messages:
                if message.component_id != self._config.autopilot_component_id:
                    continue
                try:
                    wind = decode(telemetry.fields(message))
                except (ValueError, KeyError, TypeError) as exc:
                    self._malformed(name, exc)
                    continue
                if wind is not None:
                    self._wind, self._wind_at_s = wind, time.monotonic()

    async def _read_local_position(self) -> None:
        async with aclosing(self._direct.subscribe_message("LOCAL_POSITION_NED")) as messages:
            async for message in messages:
                if message.component_id != self._config.autopilot_component_id:
                    continue
                try:
                    self._local_ned = telemetry.local_position_ned(telemetry.fields(message))
                except (ValueError, KeyError, TypeError) as exc:
                    self._malformed("LOCAL_POSITION_NED", exc)

    async def _read_health(self) -> None:
        async with aclosing(self._tel.subscribe_health()) as healths:
            async for health in healths:
                self._global_ok = bool(health.is_global_position_ok)
                await self._notify()

    async def _read_in_air(self) -> None:
        async with aclosing(self._tel.subscribe_in_air()) as states:
            async for in_air in states:
                self._in_air = bool(in_air)
                await self._notify()

    async def _read_observations(self) -> None:
        wanted = self._config.camera_component_id
        name = "CAMERA_TRACKING_GEO_STATUS"
        async with aclosing(self._direct.subscribe_message(name)) as messages:
            async for message in messages:
                if wanted is not None and message.component_id != wanted:
                    continue
                try:
                    observation = self._observation(telemetry.fields(message))
                except (ValueError, KeyError, TypeError) as exc:
                    self._malformed(name, exc)
                    continue
                if observation is None:
                    self.counters.observations_dropped += 1
                    continue
                self.counters.observations += 1
                self._observations.publish(observation)

    def _observation(self, f: dict[str, Any]) -> TargetObservation | None:
        latest = self._latest
        t_s = None if latest is None else latest.t_s
        return telemetry.tracking_observation(f, self._id, self._origin, t_s)

    async def _watchdog(self) -> None:
        period = self._config.link_timeout_s / 4.0
        while True:
            await asyncio.sleep(period)
            last = self._last_rx
            if last is None or not self._link_ok:
                continue
            silent = self._clock() - last
            if silent > self._config.link_timeout_s:
                self._link_ok = False
                self._heard_since_loss = False
                self.counters.link_losses += 1
                latest = self._latest
                t_s = latest.t_s if latest else 0.0
                log.error("vehicle %d: link lost (no telemetry for %.1f s)", self._id, silent)
                if latest is not None:
                    self._latest = replace(latest, link_ok=False)
                    self._telemetry.publish(self._latest)
                self._events.publish(LinkLost(self._id, t_s, silent))
                await self._notify()

    def _malformed(self, what: str, exc: Exception) -> None:
        self.counters.malformed += 1
        log.warning("vehicle %d: malformed %s dropped: %s", self._id, what, exc)

    # -- commands --------------------------------------------------------------------------

    async def wait_ready(self, timeout_s: float) -> VehicleTelemetry:
        await self._wait_for(
            lambda: self._latest is not None and self._link_ok and self._global_ok,
            timeout_s,
            "no telemetry with a healthy global position",
        )
        await self._require_adapter().prepare()
        latest = self._latest
        assert latest is not None
        return latest

    async def arm(self) -> None:
        self._require_adapter()
        if self._armed:
            return
        try:
            await self._action.arm()
        except ActionError as exc:
            raise LinkError(f"vehicle {self._id}: arm refused: {exc.result.name}") from exc

    def _airborne(self) -> bool:
        latest = self._latest
        return self._in_air or (latest is not None and latest.in_air)

    async def take_off(self, timeout_s: float, altitude_m: float | None = None) -> None:
        adapter = self._require_adapter()
        # decide on a frame newer than the call: arming may just have launched the vehicle
        before = self._latest
        with contextlib.suppress(LinkError):
            await self._wait_for(
                lambda: self._latest is not before and self._latest is not None,
                min(timeout_s, self._config.link_timeout_s),
                "no fresh telemetry",
            )
        if self._airborne():
            return
        latest = self._latest
        if isinstance(adapter, ArduPlaneAdapter):
            # MAVSDK's takeoff sends NAV_TAKEOFF, which ArduPlane refuses unless a QuadPlane
            await adapter.take_off()
        elif isinstance(adapter, Px4FixedWingAdapter) and altitude_m is not None and latest:
            # PX4 climbs to MIS_TAKEOFF_ALT (the SIH airplane: about 20 m) unless NAV_TAKEOFF
            # names an altitude: the vehicle's own altitude (its place in the stack), so the
            # hand-over height is reached without a parameter write
            home_amsl = latest.altitude_m - latest.relative_altitude_m
            await adapter.take_off(
                latest.latitude_deg, latest.longitude_deg, home_amsl + altitude_m
            )
        else:
            try:
                await self._action.takeoff()
            except ActionError as exc:
                raise LinkError(f"vehicle {self._id}: take-off refused: {exc.result.name}") from exc
        await self._wait_for(self._airborne, timeout_s, "not in the air after take-off")

    def _state(self) -> VehicleState:
        latest = self._latest
        if latest is None:
            raise LinkError(f"vehicle {self._id}: no telemetry yet")
        return VehicleState(
            t_s=latest.t_s,
            course_rad=latest.course_rad,
            relative_altitude_m=latest.relative_altitude_m,
            local_ned_m=self._local_ned,
            flying_speed_m_s=(
                latest.airspeed_m_s if latest.airspeed_m_s is not None else latest.ground_speed_m_s
            ),
            roll_rad=(self._roll_rad if self._clock() - self._roll_at_s <= ROLL_STALE_S else None),
        )

    async def start_offboard(self, first: CourseSpeedCommand) -> None:
        adapter = self._require_adapter()
        async with self._send_lock:
            state = self._state()
            self._previous = SentSetpoint(state.t_s, state.course_rad, first.speed_m_s)
            self._hold_altitude_m = (
                first.altitude_m if first.altitude_m is not None else state.relative_altitude_m
            )
            setpoint = self._limit(first, state.t_s)
            self._offboard = "starting"
            try:
                await adapter.start(setpoint, self._altitude(setpoint), state)
                self._record(setpoint, state.t_s)
                await self._confirm_mode(adapter.control_mode)
            except BaseException:
                self._offboard = "idle"
                raise
            self._offboard = "active"

    async def _confirm_mode(self, mode: str) -> None:
        timeout_s = self._config.mode_confirm_timeout_s
        try:
            await self._wait_for(lambda: self._mode == mode, timeout_s, f"no {mode}")
        except LinkError as exc:
            raise LinkError(
                f"vehicle {self._id} accepted {mode} but still reports {self._mode} "
                f"after {timeout_s} s"
            ) from exc

    def _altitude(self, command: CourseSpeedCommand) -> float:
        if command.altitude_m is not None:
            self._hold_altitude_m = command.altitude_m
        return self._hold_altitude_m

    def _limit(self, command: CourseSpeedCommand, t_s: float) -> CourseSpeedCommand:
        limited, reasons = limit_setpoint(command, t_s, self._previous, self._config.limits)
        if reasons:
            self.counters.setpoints_limited += 1
            for reason in reasons:
                by_kind = self.counters.limited_by
                by_kind[reason.kind] = by_kind.get(reason.kind, 0) + 1
            detail = "; ".join(str(reason) for reason in reasons)
            level = logging.DEBUG if self._limited_burst else logging.WARNING
            log.log(
                level,
                "vehicle %d: setpoint limited (%d so far): %s",
                self._id,
                self.counters.setpoints_limited,
                detail,
            )
            self._events.publish(
                SetpointLimited(self._id, t_s, detail, self.counters.setpoints_limited)
            )
        self._limited_burst = bool(reasons)
        return limited

    def _record(self, setpoint: CourseSpeedCommand, t_s: float) -> None:
        self._previous = SentSetpoint(t_s, setpoint.course_rad, setpoint.speed_m_s)
        self.counters.setpoints += 1

    async def send(self, command: CourseSpeedCommand) -> None:
        adapter = self._require_adapter()
        async with self._send_lock:
            if self._offboard == "left":
                raise OffboardLostError(
                    f"vehicle {self._id} left {adapter.control_mode} (now {self._mode}); "
                    "call start_offboard again to take it back"
                )
            if self._offboard != "active":
                raise LinkError(f"vehicle {self._id}: start_offboard before send")
            state = self._state()
            setpoint = self._limit(command, state.t_s)
            await adapter.send(setpoint, self._altitude(setpoint), state)
            self._record(setpoint, state.t_s)

    async def hold(self) -> None:
        """Stop offboard and hold; a vehicle that left offboard on its own (someone else changed
        its mode) is left in that mode: the pilot always wins."""
        adapter = self._require_adapter()
        async with self._send_lock:
            if self._offboard == "left":
                log.warning(
                    "vehicle %d: left in %s (not ours to hold: someone else chose it)",
                    self._id,
                    self._mode,
                )
                return
            # the vehicle leaving offboard from now on is this hold, not a change on its own
            before, self._offboard = self._offboard, "idle"
            try:
                await adapter.stop()
            except BaseException:
                self._offboard = before
                raise
