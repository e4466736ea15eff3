"""One vehicle's agent loop: a thin pump between the vehicle link, the bus and the core's
``app.core.mission.agent.step``.

Every telemetry frame from the vehicle is one control tick (``Control``) whose command goes
straight back to the vehicle, then ``Telemetry`` (the status, when due, to the bus); the
camera's observations feed the local filter (``Observed``, the local estimate out when due) and
are published for the ground station; the fused estimate, the mission state and the teammates'
statuses arrive from the bus. Nothing here blocks the control path: a refused command is logged
and counted, a malformed message never reaches this loop (the bus drops it).

The pilot always wins: a vehicle whose mode someone else changed (RC, a ground-control station,
RTL, a failsafe) is left in that mode; the agent sends it nothing, reports it (the event
``pilot_took_over``, a warning on the terminal, ``control="pilot"`` in its bus status) and takes
it back only on an explicit ``resume`` command.

Only the newest fused estimate is applied: its subscription holds one message, so one that
arrives while an older one waits replaces it (``FUSED_QUEUE``). The teammates' statuses are
taken once per control tick, all those that came since the last in one step (``TEAM_QUEUE``).
"""

import asyncio
import logging
import math
import time
from dataclasses import dataclass

from app.core.agent import (
    ActuatorChoice,
    AgentParams,
    Command,
    OwnTelemetry,
    PhaseActuator,
    resolve_actuator,
    with_phase_actuator,
)
from app.core.estimation.backlog import merge_backlog
from app.core.estimation.messages import Observation
from app.core.mission import agent as logic
from app.core.values import replace
from app.errors import LinkError
from app.runtime.ports import messages as bus
from app.runtime.ports import topics
from app.runtime.ports.bus import Bus, Subscription
from app.runtime.ports.events import EventSink
from app.runtime.ports.record import InputRecorder
from app.runtime.ports.vehicle import (
    ClockRebased,
    CourseSpeedCommand,
    LeftOffboard,
    LinkLost,
    LinkRestored,
    OffboardLostError,
    SetpointLimited,
    SpeedLagLearned,
    TargetObservation,
    TurnLearned,
    VehicleLink,
    VehicleTelemetry,
)
from app.runtime.wire import global_to_core, local_to_bus, observation_to_core

log = logging.getLogger(__name__)

FUSED_QUEUE = 1
"""Fused estimates kept unread: the newest supersedes the others. Applying one (the main
filter's information allocation) replays the local filter's observations made since its time,
about 1 ms each, so a late one costs several times a control tick; an agent that applied every
one in turn on a loaded machine fell ever further behind (measured: 20 ms per fused estimate,
the agent's messages 18-41 s late), while the newest makes every older one redundant."""

TEAM_QUEUE = 1024
"""Teammates' statuses kept unread between two control ticks: a team of fifty at 10 Hz for two
seconds of ticks lost (the oldest go first: only each teammate's newest few are of use)."""


@dataclass(frozen=True, slots=True)
class AgentRuntimeParams:
    """Timing of the loop (vehicle time, s) and the altitude to hold (m above home).
    ``merge_window_s``: observations that queued while the agent was busy are merged into one
    per this much of their time (``merge_backlog``). ``clock_rate``: vehicle seconds per host
    second (the built-in simulator's speed-up; 1 for real vehicles), for counting how long
    frames waited (``_frame_wait``). ``load_*``: when to warn that the agent skips too many
    telemetry frames (``_watch_load``). ``phase_actuator``: the phase actuator the mission file
    asks for, resolved at start against what the vehicle's autopilot honours
    (``VehicleLink.honours_speed``; None: fly the agent parameters as given).
    ``max_fix_rate_hz``, ``fix_burst``: the camera's fixes taken from the link, at most this
    rate (by their vehicle time) after a burst of this many; the rest are dropped, counted
    (``fixes_rate_limited``): a burst of forged fixes into the vehicle's MAVLink port costs the
    filter a handful of gated updates, not a lost track.
    ``control_period_s``: the agent steers at most once per this much vehicle time, on a grid
    of it (a frame up to 30 % of a period early takes its slot); telemetry faster than that
    (PX4's 50 Hz) is coalesced: the frames between are not steered on, only counted
    (``frames_coalesced``), so the work per vehicle is that of the control rate whatever the
    telemetry rate. 0: steer on every frame."""

    altitude_m: float | None = None
    status_period_s: float = 0.1
    estimate_period_s: float = 0.2
    merge_window_s: float = 0.3
    clock_rate: float = 1.0
    load_window_s: float = 10.0
    load_warn_share: float = 0.2
    load_warn_every_s: float = 30.0
    phase_actuator: ActuatorChoice | None = None
    max_fix_rate_hz: float = 20.0
    fix_burst: int = 20
    control_period_s: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.control_period_s) and self.control_period_s >= 0.0):
            raise ValueError(
                f"control_period_s must be finite and >= 0, got {self.control_period_s!r}"
            )


#: a frame this share of the control period early still takes its slot (telemetry jitter)
CONTROL_SLOT_EARLY = 0.3


@dataclass
class AgentCounters:
    ticks: int = 0
    commands_refused: int = 0
    offboard_restarts: int = 0  # taken back on a ``resume`` after the pilot took over
    pilot_takeovers: int = 0  # times someone else changed the vehicle's mode
    course_rate_ff_held: int = 0  # wanted course rates beyond the airframe's, held to it
    observations_used: int = 0
    observations_dropped: int = 0
    observations_merged: int = 0  # queued observations folded into another (merge_backlog)
    frames_skipped: int = 0  # telemetry frames that queued while a tick ran, steered past
    #: frames that came faster than the control period: not steered on (not a sign of load)
    frames_coalesced: int = 0
    frame_wait_max_s: float = 0.0  # longest a steered frame waited for its tick (vehicle s)
    frame_wait_sum_s: float = 0.0  # summed over the ticks (mean: / ticks)
    messages_refused: int = 0  # bus messages not believed (stamped ahead, a fused estimate off)
    #: of those, refused while the agent's own vehicle was silent (its clock had stopped, so
    #: every teammate's message is "ahead"): counted, not logged one by one
    refused_while_silent: int = 0
    message_errors: int = 0  # bus messages whose handling failed (logged, skipped)
    tick_errors: int = 0  # control ticks that failed (logged, skipped)
    commands_nonfinite: int = 0  # commands with a non-finite value: the tick sent nothing
    fixes_rate_limited: int = 0  # camera fixes over the link's rate limit, dropped
    ground_silent_holds: int = 0  # holds because the ground station went silent
    fused_unread: int = 0  # fused estimates pushed out unread by a newer one (one-deep queue)
    #: teammates' statuses pushed out unread by newer ones (no control tick took them)
    statuses_unread: int = 0
    cpu_s: float = 0.0  # CPU (this thread's) spent in the agent's own work: every mission step
    wall_s: float = 0.0  # wall time the agent ran
    #: ``cpu_s`` per second of vehicle time: the share of one core the agent's work takes at
    #: 1x real time (at a speed-up the same work is done in less wall time); None before it ran
    cpu_share_at_1x: float | None = None
    #: where the course-loop identification stands (``logic.course_loop_report``; None when
    #: it is off), brought up to date with the CPU figures
    course_loop: logic.CourseLoopReport | None = None


class _FixBucket:
    """A token bucket on the fixes' own (vehicle) time: ``burst`` at once, then ``rate_hz``."""

    def __init__(self, rate_hz: float, burst: int) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0.0 and burst >= 1):
            raise ValueError(f"fix rate must be > 0 and burst >= 1, got {rate_hz!r}, {burst!r}")
        self._rate = rate_hz
        self._burst = float(burst)
        self._tokens = float(burst)
        self._t = -math.inf

    def take(self, t_s: float) -> bool:
        if not math.isfinite(t_s):
            return True  # the filter refuses it and counts it
        if math.isfinite(self._t) and t_s > self._t:
            self._tokens = min(self._burst, self._tokens + (t_s - self._t) * self._rate)
        self._t = max(self._t, t_s)
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False


@dataclass
class _LoadWindow:
    start_t: float | None = None
    frames: int = 0
    skipped: int = 0
    next_warn_t: float = -math.inf
    warned: bool = False


def _with_actuator(
    params: logic.MissionAgentParams, actuator: PhaseActuator
) -> logic.MissionAgentParams:
    """Every stage's agent parameters flying phase keeping with ``actuator``."""

    def fly(p: AgentParams) -> AgentParams:
        return with_phase_actuator(p, actuator)

    return replace(
        params,
        agent=fly(params.agent),
        standby=fly(params.standby),
        track=fly(params.track) if params.track is not None else None,
    )


class VehicleAgent:
    """Runs one vehicle until cancelled; ``run`` is the whole agent."""

    def __init__(
        self,
        params: logic.MissionAgentParams,
        link: VehicleLink,
        bus_client: Bus,
        events: EventSink,
        runtime: AgentRuntimeParams = AgentRuntimeParams(),
        recorder: InputRecorder | None = None,
    ) -> None:
        self.actuator: PhaseActuator | None = None
        if runtime.phase_actuator is not None:
            self.actuator = resolve_actuator(runtime.phase_actuator, link.honours_speed)
            params = _with_actuator(params, self.actuator)
            latest = link.latest
            events.emit(
                "phase_actuator",
                latest.t_s if latest is not None else 0.0,
                vehicle=params.vehicle,
                actuator=self.actuator,
                configured=runtime.phase_actuator,
                autopilot=link.autopilot_name,
                honours_speed=link.honours_speed,
            )
        limit = link.course_error_limit_rad
        if params.course_id is not None and limit is not None:
            # where the autopilot's own turn command saturates, the identification stops
            # fitting (``course_id``: a weak loop is not taken for a weaker one)
            params = replace(params, course_id=replace(params.course_id, command_limit_rad=limit))
        self.params = params
        self.name = topics.agent(params.vehicle)
        self.state = logic.initial_agent_state(
            params, runtime.estimate_period_s, runtime.status_period_s
        )
        self.counters = AgentCounters()
        self._link = link
        self._bus = bus_client
        self._events = events
        self._runtime = runtime
        self._recorder = recorder  # what the local filter is fed, for ``standoff replay``
        self._pilot_mode: str | None = None  # the mode someone else put the vehicle in
        self._last_t = 0.0
        self._next_slot_t = -math.inf  # the control period's next slot (vehicle time)
        self._load = _LoadWindow()
        self._fixes = _FixBucket(runtime.max_fix_rate_hz, runtime.fix_burst)
        self._faults: dict[str, int] = {}
        self._started: float | None = None  # monotonic time ``run`` began
        self._team: Subscription | None = None  # the teammates' statuses, while running

    @property
    def pilot_has_control(self) -> bool:
        """Someone else changed the vehicle's mode and no ``resume`` has come since."""
        return self._pilot_mode is not None

    def stand_down(self) -> None:
        """Stop commanding the vehicle (the mission is about to put it in hold)."""
        self.state, _ = self._step(logic.Hold(True), self.params)

    def _step(
        self, event: logic.AgentInput, params: logic.MissionAgentParams
    ) -> tuple[logic.MissionAgentState, logic.AgentOutbox]:
        """``logic.step``, its CPU time counted (``cpu_s``): the agent's own work, apart from
        the bus, the link and the other agents sharing the process."""
        started = time.thread_time()
        try:
            return logic.step(self.state, event, params)
        finally:
            self.counters.cpu_s += time.thread_time() - started

    async def run(self) -> None:
        v = self.params.vehicle
        self._started = time.monotonic()
        try:
            await self._run(v)
        finally:
            self.measure_cpu()

    def measure_cpu(self) -> None:
        """Bring the counters' ``wall_s``, ``cpu_share_at_1x`` and ``course_loop`` up to now
        (also while the agent still runs, for a process that writes its counters before it
        stops)."""
        if self._started is None:
            return
        c = self.counters
        c.course_loop = logic.course_loop_report(self.state, self.params)
        c.wall_s = time.monotonic() - self._started
        rate = self._runtime.clock_rate
        if c.wall_s > 0.0 and rate > 0.0:
            c.cpu_share_at_1x = c.cpu_s / (c.wall_s * rate)

    async def _run(self, v: int) -> None:
        async with (
            self._bus.subscribe(topics.observation(v)) as observations,
            self._bus.subscribe(topics.GLOBAL_ESTIMATE, queue_size=FUSED_QUEUE) as fused,
            self._bus.subscribe(topics.MISSION) as mission,
            self._bus.subscribe(topics.ALL_STATUS, queue_size=TEAM_QUEUE) as statuses,
            self._bus.subscribe(topics.ALL_COMMANDS) as commands,
        ):
            self._team = statuses  # taken once per control tick (``_hear_team``)
            try:
                async with asyncio.TaskGroup() as tg:
                    tg.create_task(self._control(), name=f"{self.name}-control")
                    tg.create_task(self._camera(), name=f"{self.name}-camera")
                    tg.create_task(self._link_events(), name=f"{self.name}-link-events")
                    tg.create_task(self._hear(observations), name=f"{self.name}-observations")
                    tg.create_task(self._hear(fused), name=f"{self.name}-fused")
                    tg.create_task(self._hear(mission), name=f"{self.name}-mission")
                    tg.create_task(self._hear(commands), name=f"{self.name}-commands")
            finally:
                # every fused estimate is either applied, refused (messages_refused) or this
                self.counters.fused_unread = fused.dropped
                self.counters.statuses_unread = statuses.dropped
                self._team = None

    # --- the control path -----------------------------------------------------------------

    async def _control(self) -> None:
        async for queued in self._link.telemetry():
            try:
                await self._tick(queued)
            except Exception as exc:  # one bad tick never ends the agent: counted, logged
                self.counters.tick_errors += 1
                self._fault("tick_failed", self._last_t, exc)

    async def _tick(self, queued: VehicleTelemetry) -> None:
        # steer on the newest frame: frames that queued up while the loop was busy are
        # history, and acting on each in turn would only add lag
        newest = self._link.latest
        frame = newest if newest is not None and newest.t_s > queued.t_s else queued
        t = frame.t_s
        period = self._runtime.control_period_s
        if period > 0.0 and self.counters.ticks > 0 and self._last_t < t:
            if t < self._next_slot_t - CONTROL_SLOT_EARLY * period:
                self.counters.frames_coalesced += 1
                return
            # the next slot on the grid; after a gap (or a clock jump) the grid restarts here
            slot = self._next_slot_t + period
            self._next_slot_t = slot if abs(t - self._next_slot_t) < period else t + period
        elif self.counters.ticks == 0:
            self._next_slot_t = t + period
        self._load.frames += 1
        if t <= self._last_t and self.counters.ticks > 0:
            # another message of the same instant, or one the last tick already skipped
            self.counters.frames_skipped += 1
            self._load.skipped += 1
            return
        self._last_t = t
        self._watch_load(t)
        own = OwnTelemetry(
            frame.east_m,
            frame.north_m,
            frame.course_rad,
            frame.ground_speed_m_s,
            frame.airspeed_m_s,
            frame.wind_m_s,
            frame.up_m,
            frame.climb_rate_m_s,
            self._level_up(frame),
        )
        self._frame_wait(frame)
        self._hear_team()
        try:
            self.state, out = self._step(logic.Control(t, own), self.params)
        except ValueError as exc:  # a non-finite frame: never steer on it
            self._events.emit("telemetry_rejected", t, vehicle=self.params.vehicle, reason=str(exc))
            return
        self.counters.ticks += 1
        for event in out.events:
            self._events.emit(
                event.kind, event.t_s, vehicle=self.params.vehicle, detail=event.detail
            )
            if event.kind == "ground_silent":
                await self._silent_hold(t)
        if out.command is not None and self._pilot_mode is None:
            c = out.command
            rate = c.course_rate_ff_rad_s
            # the airspeed that flies the ground speed in the estimated wind, where known
            speed = c.speed_m_s if c.airspeed_m_s is None else c.airspeed_m_s
            if not all(math.isfinite(v) for v in (c.course_rad, speed, rate, c.field_course_rad)):
                self.counters.commands_nonfinite += 1
                self._fault(
                    "command_nonfinite", t, f"course {c.course_rad!r}, speed {c.speed_m_s!r}"
                )
            else:
                await self._send(
                    t,
                    CourseSpeedCommand(
                        c.course_rad,
                        speed,
                        self._altitude(frame, c),
                        course_rate_rad_s=self._feed_forward(rate),
                        path_course_rad=c.field_course_rad,
                    ),
                )
        self.state, out = self._step(logic.Telemetry(t, own), self.params)
        if out.status is not None:
            await self._publish_status(out.status)

    def _level_up(self, frame: VehicleTelemetry) -> float | None:
        """The height about the origin the vehicle is sent to (its place in the stack), where
        the mission holds its altitude."""
        altitude = self._runtime.altitude_m
        if altitude is None:
            return None
        return frame.up_m - frame.relative_altitude_m + altitude

    def _altitude(self, frame: VehicleTelemetry, command: Command) -> float | None:
        """The altitude to hold (above home): the vehicle's place in the stack, held to the
        separation guard's band of heights (about the origin) while a teammate is near."""
        altitude = self._runtime.altitude_m
        if altitude is None or (command.min_up_m is None and command.max_up_m is None):
            return altitude
        home_up = frame.up_m - frame.relative_altitude_m  # home's height about the origin
        if command.max_up_m is not None:
            altitude = min(altitude, command.max_up_m - home_up)
        if command.min_up_m is not None:
            altitude = max(altitude, command.min_up_m - home_up)
        return altitude

    async def _silent_hold(self, t: float) -> None:
        """The ground station went silent for too long: the vehicle holds (the rule of
        ``MissionAgentParams.ground_silent_hold_s``) until a ``resume``."""
        self.counters.ground_silent_holds += 1
        log.warning("agent %d: the ground station is silent: holding", self.params.vehicle + 1)
        if self._pilot_mode is None:
            try:
                await self._link.hold()
            except LinkError as exc:
                self._events.emit(
                    "command_refused", t, vehicle=self.params.vehicle, reason=str(exc)
                )

    def _fault(self, kind: str, t: float, error: object) -> None:
        """An error in one message or one tick: an event and a log line at its 1st, 2nd, 5th,
        10th, 20th ... occurrence (a flood of them must not flood the log), counted."""
        n = self._faults[kind] = self._faults.get(kind, 0) + 1
        if not _log_spaced(n):
            return
        detail = f"{type(error).__name__}: {error}" if isinstance(error, BaseException) else error
        log.warning("agent %d: %s (%d so far): %s", self.params.vehicle + 1, kind, n, detail)
        self._events.emit(
            kind, t, vehicle=self.params.vehicle, count=n, repeat=n > 1, detail=str(detail)[:300]
        )

    def _feed_forward(self, rate_rad_s: float) -> float:
        """The wanted course's rate, held to what the airframe can turn (the field asks for
        more now and then near the circle; the vehicle cannot fly it), counted."""
        limit = self.params.agent.envelope.max_course_rate_rad_s
        if abs(rate_rad_s) <= limit:
            return rate_rad_s
        self.counters.course_rate_ff_held += 1
        return math.copysign(limit, rate_rad_s)

    def _frame_wait(self, frame: VehicleTelemetry) -> None:
        """Count how long (vehicle seconds) the frame steered on waited after it arrived, when
        the link can tell (``latest_age_s``) and it is the newest. (Steering that much further
        ahead was tried: on a machine short of CPU the mean wait was 0.07 s, the lag being in
        MAVSDK's streams before the frame reaches the app, and it bought nothing measurable.)"""
        age: float | None = getattr(self._link, "latest_age_s", None)
        if age is None or frame is not self._link.latest or not math.isfinite(age):
            return
        wait = max(0.0, age) * self._runtime.clock_rate
        c = self.counters
        c.frame_wait_max_s = max(c.frame_wait_max_s, wait)
        c.frame_wait_sum_s += wait

    def _watch_load(self, t: float) -> None:
        """Warn (an event, at most every ``load_warn_every_s``; ``repeat`` after the first, which
        alone reaches the terminal) when over the last
        ``load_window_s`` the loop skipped more than ``load_warn_share`` of its vehicle's
        telemetry frames: the agent is short of CPU and steers on late data."""
        w, rt = self._load, self._runtime
        if w.start_t is None or t < w.start_t:
            w.start_t, w.frames, w.skipped = t, 0, 0
            return
        if t - w.start_t < rt.load_window_s:
            return
        share = w.skipped / w.frames if w.frames else 0.0
        if share > rt.load_warn_share and t >= w.next_warn_t:
            w.next_warn_t = t + rt.load_warn_every_s
            self._events.emit(
                "falling_behind",
                t,
                vehicle=self.params.vehicle,
                skipped_share=round(share, 3),
                repeat=w.warned,
                detail=(
                    f"vehicle {self.params.vehicle + 1}'s agent steered on {1.0 - share:.0%} "
                    f"of its telemetry frames over {t - w.start_t:.0f} s: short of CPU, the "
                    "figures suffer (lower --speedup, or run the agents as separate processes)"
                ),
            )
            w.warned = True
        w.start_t, w.frames, w.skipped = t, 0, 0

    async def _send(self, t: float, command: CourseSpeedCommand) -> None:
        try:
            await self._link.send(command)
        except OffboardLostError:
            # the newest frame may predate the change (its mode still OFFBOARD, or none yet):
            # the mode is then not known; the link's LeftOffboard names it when it comes
            latest = self._link.latest
            mode = latest.flight_mode if latest is not None else ""
            self._took_over(mode if mode not in ("OFFBOARD", "") else "UNKNOWN", t)
        except LinkError as exc:
            self.counters.commands_refused += 1
            self._events.emit("command_refused", t, vehicle=self.params.vehicle, reason=str(exc))

    def _took_over(self, mode: str, t: float) -> None:
        """Someone else changed the vehicle's mode: leave it there, say so, send nothing."""
        if self._pilot_mode == "UNKNOWN" and mode != "UNKNOWN":
            self._pilot_mode = mode  # now known: 'resumed' says the mode it was taken from
            self._events.emit("pilot_mode", t, vehicle=self.params.vehicle, flight_mode=mode)
            return
        if self._pilot_mode is not None or self.state.holding:
            return
        self._pilot_mode = mode
        self.counters.pilot_takeovers += 1
        v = self.params.vehicle
        log.warning(
            "vehicle %d was put in %s by someone else: the mission leaves it there and sends "
            "it nothing until 'resume %d'",
            v + 1,
            mode,
            v + 1,
        )
        self._events.emit("pilot_took_over", t, vehicle=v, flight_mode=mode)

    def _control_state(self) -> str:
        if self._pilot_mode is not None:
            return "pilot"
        return "hold" if self.state.holding else "mission"

    async def _publish_status(self, status: logic.AgentStatus) -> None:
        latest = self._link.latest
        message = bus.VehicleStatus(
            sender=self.name,
            t_s=status.t_s,
            vehicle=self.params.vehicle,
            east_m=status.east_m,
            north_m=status.north_m,
            alt_m=latest.relative_altitude_m if latest is not None else 0.0,
            up_m=latest.up_m if latest is not None else None,
            climb_m_s=latest.climb_rate_m_s if latest is not None else None,
            level_up_m=self._level_up(latest) if latest is not None else None,
            course_rad=status.course_rad,
            speed_m_s=status.speed_m_s,
            phase_rad=status.phase_rad,
            stage=status.stage,
            link="ok" if self._link.link_ok else "lost",
            healthy=status.healthy,
            control=self._control_state(),
            flight_mode=(latest.flight_mode if latest is not None else "")[:40],
        )
        await self._bus.publish(topics.status(self.params.vehicle), message)

    # --- what the agent hears ---------------------------------------------------------------

    async def _camera(self) -> None:
        """The camera's observations, as they come; those that queued while the agent was busy
        are merged (``merge_backlog``) so that a backlog costs one filter update per
        ``merge_window_s`` of it instead of one per observation."""
        pending: list[TargetObservation] = []
        ready = asyncio.Event()
        done = False

        async def read() -> None:
            nonlocal done
            try:
                async for seen in self._link.observations():
                    if not self._fixes.take(seen.t_s):
                        self.counters.fixes_rate_limited += 1
                        self._fault("fix_rate_limited", seen.t_s, "camera fixes over the limit")
                        continue
                    pending.append(seen)
                    ready.set()
            finally:
                done = True
                ready.set()

        async with asyncio.TaskGroup() as tg:
            tg.create_task(read(), name=f"{self.name}-camera-read")
            while not (done and not pending):
                await ready.wait()
                ready.clear()
                batch = pending[:]
                pending.clear()
                try:
                    await self._take_fixes(batch)
                except Exception as exc:  # one bad batch never ends the camera: counted
                    self.counters.message_errors += 1
                    self._fault("fix_failed", self._last_t, exc)

    async def _take_fixes(self, batch: list[TargetObservation]) -> None:
        sensor = self.params.sensor
        observations = [Observation(s.t_s, sensor, s.east_m, s.north_m, s.sigma_m) for s in batch]
        merged = merge_backlog(
            observations, self._runtime.merge_window_s, self.params.local.default_sigma_m
        )
        self.counters.observations_merged += len(observations) - len(merged)
        for obs in merged:
            used = await self._use_observation(obs)
            if used:
                await self._publish_observation(obs)

    async def _publish_observation(self, obs: Observation) -> None:
        sigma = obs.sigma_m
        message = bus.TargetObservation(
            sender=self.name,
            t_s=obs.t_s,
            sensor=f"camera-{self.params.vehicle}",
            vehicle=self.params.vehicle,
            east_m=obs.east_m,
            north_m=obs.north_m,
            sigma_m=sigma
            if sigma is not None and sigma > 0.0
            else self.params.local.default_sigma_m,
        )
        await self._bus.publish(topics.observation(self.params.vehicle), message)

    async def _use_observation(self, obs: Observation) -> bool:
        """Feed one observation to the local filter (and its estimate out when due); whether
        it was used."""
        if self._recorder is not None:
            self._recorder.observation(self.params.vehicle, obs, self.state.now_t_s)
        self.state, out = self._step(logic.Observed(obs), self.params)
        report = out.report
        if report is not None and not report.used:
            self.counters.observations_dropped += 1
            self._events.emit(
                "observation_dropped",
                obs.t_s if math.isfinite(obs.t_s) else self._last_t,
                vehicle=self.params.vehicle,
                outcome=report.outcome,
                reason=report.reason,
            )
            return False
        self.counters.observations_used += 1
        if out.estimate is not None:
            await self._bus.publish(
                topics.local_estimate(self.params.vehicle),
                local_to_bus(out.estimate, self.params.vehicle, self.name),
            )
        return True

    async def _hear(self, subscription: Subscription) -> None:
        async for _topic, message in subscription:
            try:
                await self._heard(message)
            except Exception as exc:  # one bad message never ends the agent: counted, logged
                self.counters.message_errors += 1
                self._fault("message_failed", self._last_t, exc)

    async def _heard(self, message: bus.Message) -> None:
        out: logic.AgentOutbox | None = None
        match message:
            case bus.TargetObservation() if message.sender != self.name:
                await self._use_observation(observation_to_core(message, self.params.vehicle))
            case bus.GlobalEstimate():
                heard = logic.HeardFused(global_to_core(message))
                if self._recorder is not None:
                    self._recorder.fused(
                        self.params.vehicle, heard.estimate.t_s, self.state.now_t_s
                    )
                self.state, out = self._step(heard, self.params)
            case bus.MissionState():
                mission = logic.HeardMission(message.stage, message.active, message.t_s)
                self.state, out = self._step(mission, self.params)
                if out.stage is not None:
                    self._events.emit(
                        "agent_stage",
                        message.t_s,
                        vehicle=self.params.vehicle,
                        stage=out.stage.value,
                    )
            case bus.Command() if (
                message.vehicles is None or self.params.vehicle in message.vehicles
            ):
                await self._obey(message)
            case _:
                pass
        if out is not None and out.refused:
            self.counters.messages_refused += 1
            if not self._link.link_ok:
                self.counters.refused_while_silent += 1
                return
            self._fault(
                "message_refused",
                self._last_t,
                f"{type(message).__name__} from {message.sender}: {out.refused}",
            )

    def _hear_team(self) -> None:
        """The teammates' statuses that came since the last tick, in one step: hearing each
        as it came woke the agent and stepped its state once per status, which for a team
        of n is n^2 wake-ups and steps per status period over the process."""
        if self._team is None:
            return
        fixes: list[tuple[int, logic.TeammateFix]] = []
        senders: dict[int, str] = {}
        for _topic, message in self._team.drain():
            if not isinstance(message, bus.VehicleStatus) or message.vehicle == self.params.vehicle:
                continue
            senders[message.vehicle] = message.sender
            fixes.append(
                (
                    message.vehicle,
                    logic.TeammateFix(
                        message.t_s,
                        message.east_m,
                        message.north_m,
                        message.course_rad,
                        message.speed_m_s,
                        message.up_m,
                        message.climb_m_s,
                        message.level_up_m,
                    ),
                )
            )
        if not fixes:
            return
        try:
            self.state, out = self._step(logic.HeardTeammates(tuple(fixes)), self.params)
        except Exception as exc:  # one bad batch never ends the agent: counted, logged
            self.counters.message_errors += 1
            self._fault("message_failed", self._last_t, exc)
            return
        for vehicle, why in out.refused_teammates:
            self.counters.messages_refused += 1
            if not self._link.link_ok:
                self.counters.refused_while_silent += 1
                continue
            self._fault(
                "message_refused", self._last_t, f"VehicleStatus from {senders[vehicle]}: {why}"
            )

    async def _obey(self, message: bus.Command) -> None:
        t = self._last_t
        self._events.emit("command", t, vehicle=self.params.vehicle, command=message.command)
        try:
            if message.command in ("hold", "shutdown"):
                self.state, _ = self._step(logic.Hold(True), self.params)
                if self._pilot_mode is None:  # a vehicle the pilot has stays in their mode
                    await self._link.hold()
            elif message.command == "resume" and self._pilot_mode is not None:
                await self._take_back(t)
            elif message.command == "resume" and self.state.holding:
                self.state, _ = self._step(logic.Hold(False), self.params)
                latest = self._link.latest
                course = latest.course_rad if latest is not None else 0.0
                await self._link.start_offboard(
                    CourseSpeedCommand(
                        course,
                        self.params.agent.envelope.cruise_speed_m_s,
                        self._runtime.altitude_m,
                    )
                )
        except LinkError as exc:
            self._events.emit("command_refused", t, vehicle=self.params.vehicle, reason=str(exc))

    async def _take_back(self, t: float) -> None:
        """``resume`` after the pilot took over: offboard again from the vehicle's course."""
        latest = self._link.latest
        course = latest.course_rad if latest is not None else 0.0
        await self._link.start_offboard(
            CourseSpeedCommand(
                course, self.params.agent.envelope.cruise_speed_m_s, self._runtime.altitude_m
            )
        )
        mode, self._pilot_mode = self._pilot_mode, None
        if self.state.holding:  # a hold asked for meanwhile is over too
            self.state, _ = self._step(logic.Hold(False), self.params)
        self.counters.offboard_restarts += 1
        # stamped like pilot_took_over: the vehicle's newest frame (the loop may lag behind it)
        t = max(t, latest.t_s) if latest is not None else t
        self._events.emit("resumed", t, vehicle=self.params.vehicle, from_mode=mode)

    async def _link_events(self) -> None:
        async for event in self._link.events():
            match event:
                case LinkLost():
                    self._events.emit(
                        "link_lost", event.t_s, vehicle=self.params.vehicle, silent_s=event.silent_s
                    )
                case LinkRestored():
                    self._events.emit("link_restored", event.t_s, vehicle=self.params.vehicle)
                case LeftOffboard() if self.state.holding:
                    pass  # the hold this agent stood down for, not the vehicle leaving on its own
                case LeftOffboard():
                    self._events.emit(
                        "LeftOffboard", event.t_s, vehicle=self.params.vehicle, detail=repr(event)
                    )
                    self._took_over(event.flight_mode, event.t_s)
                case ClockRebased():
                    self._events.emit(
                        "clock_rebased",
                        event.t_s,
                        vehicle=self.params.vehicle,
                        reason=event.reason,
                        boot_s=event.boot_s,
                        previous_boot_s=event.previous_boot_s,
                        offset_s=round(event.offset_s, 3),
                    )
                case TurnLearned():
                    self._events.emit(
                        "turn_efficiency_learned",
                        event.t_s,
                        vehicle=self.params.vehicle,
                        efficiency=round(event.efficiency, 3),
                        samples=event.samples,
                        turning_s=round(event.turning_s, 1),
                    )
                case SpeedLagLearned():
                    self._events.emit(
                        "speed_lag_learned",
                        event.t_s,
                        vehicle=self.params.vehicle,
                        tau_s=round(event.tau_s, 2),
                        samples=event.samples,
                    )
                case SetpointLimited() if not _log_spaced(event.count):
                    pass  # counted in the link's summary; the log gets the 1st, 2nd, 5th, 10th...
                case _:
                    self._events.emit(
                        type(event).__name__,
                        event.t_s,
                        vehicle=self.params.vehicle,
                        detail=repr(event),
                    )


def _log_spaced(count: int) -> bool:
    """1, 2, 5, 10, 20, 50, 100, ...: which of a repeating event's occurrences are logged (at
    50 Hz a limiter that acts on every setpoint would write 14,000 lines a mission)."""
    if count < 1:
        return False
    while count % 10 == 0:
        count //= 10
    return count in (1, 2, 5)
