"""The mission as separate processes over MQTT: one ground station, one agent per vehicle.

``run_ground`` is the ground-station process (``standoff ground``): its bus client ``ground``,
optionally the built-in simulator beside it, the ``GroundStation`` until mission time reaches the
end, then a ``shutdown`` command to every agent and the run folder (summary, track, plots, the
ground's events). ``run_agent`` is one vehicle's process (``standoff agent --vehicle N``): its
bus client ``agent-N`` (N: the vehicle's MAVLink system id, its index + 1; last will:
``LinkState(online=False)``), a MAVSDK link to that vehicle alone, the same ``prepare_vehicle``
and ``VehicleAgent`` that ``standoff fly`` runs, its own ``vehicle-N.tlog``,
``events-agent-N.jsonl`` and ``agent-N.json``. An agent stops on the
ground's ``shutdown`` or on SIGINT/SIGTERM; either way it stops commanding its vehicle and puts it
in hold at once (the link tries again as it closes if that was refused), then unwinds and says
``LinkState(online=False)`` before leaving the bus. A second signal to either process stops it at
once (still closing its logs).

Mission time: the ground station announces the mission's epoch (``MissionEpoch``, retained on
``topics.MISSION_EPOCH``: the wall-clock time of mission time 0, once its simulator, if any, is
up, and the clock rate); each agent opens its vehicle link at once (frames carry the vehicle's
boot time meanwhile), waits for the epoch before it arms the vehicle, and from then maps its
vehicle's boot clock onto ``(wall time - epoch) * rate``. The processes therefore agree on mission
time to the accuracy of their hosts' clock sync (NTP), however long ago the vehicles booted. The
ground marks the epoch ``ended`` as it leaves, so an agent started for the next mission waits for
the next ground station (a ground that crashed leaves its epoch: start the ground first then).
"""

import asyncio
import contextlib
import dataclasses
import json
import logging
import math
import signal
from collections.abc import AsyncIterator, Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import AsyncExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.adapters.bus import Backoff, Birth, BrokerUrl, Bus, MqttBus, Subscription, Will, open_bus
from app.adapters.eventlog import EventLog
from app.compose.parts import (
    MissionResult,
    bring_up,
    clock_rate,
    counters_of,
    gcs_endpoint,
    ground_station,
    open_links,
    recording_inputs,
    vehicle_agent,
    write_outputs,
)
from app.compose.simulator import simulator_process
from app.config.plan import MissionPlan
from app.errors import BusError, ConfigError, LinkError, StandoffError
from app.report.provenance import run_block
from app.runtime.agent import VehicleAgent
from app.runtime.events import LoggingSink
from app.runtime.ground import GroundStation, Measurement
from app.runtime.ports import topics
from app.runtime.ports.clock import SYSTEM_CLOCK, Clock, MissionClock
from app.runtime.ports.events import EventSink
from app.runtime.ports.messages import Command, LinkState, MissionEpoch
from app.runtime.ports.vehicle import VehicleLink
from app.runtime.ports.view import MissionSnapshot
from app.runtime.vehicle import prepare_vehicle

log = logging.getLogger(__name__)

GROUND_CLIENT = topics.GROUND
SHUTDOWN_GRACE_S = 15.0  # wall time the ground waits for the agents to hold and go offline
HOLD_TIMEOUT_S = 5.0  # wall time a stopping agent waits for its vehicle to accept the hold
EPOCH_TIMEOUT_S = 120.0  # wall time an agent waits for the ground station's mission epoch
# reconnect tries at most every second: a mission's broker is back within ~1 s of its return
BUS_BACKOFF = Backoff(initial_s=0.1, factor=2.0, max_s=1.0)

Notify = Callable[[str], None]


def _quiet(_line: str) -> None:
    return None


# --- stopping: the end of the mission, a shutdown command, or a signal ---------------------------


class StopFlag:
    """Why a process should stop: set once (the first reason wins); awaitable."""

    def __init__(self) -> None:
        self.reason = ""
        self.signum: signal.Signals | None = None
        self.forced = False  # a second signal: stop at once
        self._event = asyncio.Event()

    @property
    def is_set(self) -> bool:
        return self._event.is_set()

    def set(self, reason: str) -> None:
        if not self._event.is_set():
            self.reason = reason
            self._event.set()

    async def wait(self) -> str:
        await self._event.wait()
        return self.reason


@contextlib.contextmanager
def stop_on_signals(stop: StopFlag) -> Iterator[None]:
    """SIGINT/SIGTERM set ``stop`` (an orderly stop); a second one cancels the current task,
    which the process functions turn into ``KeyboardInterrupt`` (see ``_forced``)."""
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    signals = (signal.SIGINT, signal.SIGTERM)

    def on_signal(signum: signal.Signals) -> None:
        if stop.is_set and stop.signum is not None and task is not None:
            log.warning("second %s: stopping at once", signum.name)
            stop.forced = True
            task.cancel()
            return
        stop.signum = signum
        stop.set(signum.name)

    for signum in signals:
        loop.add_signal_handler(signum, on_signal, signum)
    try:
        yield
    finally:
        for signum in signals:
            loop.remove_signal_handler(signum)


@contextlib.contextmanager
def _forced(stop: StopFlag) -> Iterator[None]:
    """The cancellation a second signal causes leaves as ``KeyboardInterrupt`` (exit 130)."""
    try:
        yield
    except asyncio.CancelledError:
        if stop.forced:
            raise KeyboardInterrupt from None
        raise


def _first_error(group: BaseExceptionGroup[Any]) -> BaseException:
    """The first leaf of an exception group (what a task group's caller wants to report)."""
    first: BaseException = group
    while isinstance(first, BaseExceptionGroup):
        first = first.exceptions[0]
    return first


@contextlib.asynccontextmanager
async def _plain_errors() -> AsyncIterator[None]:
    """Re-raise the project's own error out of a task group's exception group, as itself."""
    try:
        yield
    except BaseExceptionGroup as group:
        first = _first_error(group)
        if isinstance(first, StandoffError | asyncio.CancelledError | KeyboardInterrupt):
            raise first from group
        raise


def _broker_name(url: str) -> str:
    """The broker URL without its password (for logs and the event file)."""
    return str(BrokerUrl.parse(url))


# --- on the bus: presence and reconnections ---------------------------------------------------


def _mission_bus(
    broker_url: str,
    client: str,
    vehicle: int | None = None,
    bus_options: Mapping[str, Any] | None = None,
) -> Bus:
    """A process's bus client, its presence kept on ``topics.link(...)`` as a retained state.

    Its birth (``online``, on every connection) and last will (``vanished``) are retained, as is
    the ``online: false`` it publishes as it leaves (``_leave_bus``): whoever subscribes later
    (a ground station started after its agents, or one that reconnects after them when the
    broker restarts) learns who is there. A broker going down publishes its clients' wills;
    their births after the restart say ``online`` again.

    The client is its identity: it publishes only as ``client``, on its own topics
    (``topics.refusal``); ``bus_options`` (``login``, ``tls_context``) log it in as it.
    """
    topic = topics.link(client if vehicle is None else vehicle)

    def state(online: bool, reason: str = "") -> LinkState:
        return LinkState(sender=client, t_s=0.0, online=online, vehicle=vehicle, reason=reason)

    return open_bus(
        broker_url,
        client_id=client,
        will=Will(topic, state(False, "vanished"), qos=1, retain=True),
        birth=Birth(topic, state(True), qos=1, retain=True),
        backoff=BUS_BACKOFF,
        identity=client,
        **(bus_options or {}),
    )


async def _leave_bus(bus: Bus, state: LinkState) -> None:
    """Publish ``state`` (``online: false``, why) as the retained presence; a broker out of
    reach is logged, not raised: the process is leaving anyway."""
    topic = topics.link(state.sender if state.vehicle is None else state.vehicle)
    try:
        await bus.publish(topic, state, qos=1, retain=True)
    except BusError as exc:
        log.warning("%s could not say it is going offline: %s", state.sender, exc)


async def _watch_bus(bus: Bus, events: EventSink, mission_t: Callable[[], float]) -> None:
    """Each loss of the broker and each reconnection, as an event in the process's log."""
    if not isinstance(bus, MqttBus):
        return
    losses, connections = bus.losses, bus.connections
    while True:
        await bus.wait_for_change()
        if bus.losses > losses:
            losses = bus.losses
            events.emit("bus_lost", mission_t(), broker=str(bus.url), losses=losses)
        if bus.connections > connections:
            connections = bus.connections
            events.emit("bus_reconnected", mission_t(), connections=connections)


# --- the ground station -----------------------------------------------------------------------


class TeamPresence:
    """Which agents are on the bus, from their ``LinkState`` messages (births and last wills).

    The states are retained (``_mission_bus``), so agents that started before the ground station
    subscribed are heard too; ``expect`` also adds the vehicles the station has heard from
    (their statuses) to the online set, unless they last said they were going offline.
    """

    def __init__(self, events: EventSink) -> None:
        self.online: set[int] = set()
        self.offline: set[int] = set()
        self.seen: set[int] = set()
        self._events = events
        self._changed = asyncio.Event()

    async def watch(self, subscription: Subscription) -> None:
        async for _topic, message in subscription:
            if not isinstance(message, LinkState) or message.vehicle is None:
                continue
            v = message.vehicle
            self.seen.add(v)
            if message.online:
                self.online.add(v)
                self.offline.discard(v)
            else:
                self.online.discard(v)
                self.offline.add(v)
            self._events.emit(
                "agent_online" if message.online else "agent_offline",
                message.t_s,
                vehicle=v,
                sender=message.sender,
                reason=message.reason,
            )
            self._changed.set()

    def expect(self, vehicles: Iterable[int]) -> None:
        """Count ``vehicles`` as online unless they last said they were going offline."""
        heard = set(vehicles) - self.offline
        self.seen |= heard
        self.online |= heard

    async def all_offline(self) -> None:
        while self.online:
            self._changed.clear()
            await self._changed.wait()


async def run_ground(
    plan: MissionPlan,
    out_dir: Path,
    broker_url: str,
    *,
    sitl_base_port: int | None = None,
    replay: Sequence[Measurement] = (),
    on_snapshot: Callable[[MissionSnapshot], None] | None = None,
    notify: Notify = _quiet,
    shutdown_grace_s: float = SHUTDOWN_GRACE_S,
    clock: Clock = SYSTEM_CLOCK,
    bus_options: Mapping[str, Any] | None = None,
) -> MissionResult:
    """The ground-station process: run the mission to its end, stop the agents, write the run.

    ``sitl_base_port``: also run the built-in simulator for the plan on these UDP ports (the
    agents then connect to ``udpin://127.0.0.1:{port + i}``). Without it the vehicles and their
    agents are elsewhere. The simulated truth (for the summary's errors) is the plan's target
    path when the vehicles are the built-in simulator (``--sitl``, or a config without
    ``connect`` URLs) or when the ground simulates the observations. Returns the results, also
    when stopped by a signal (``interrupted``). ``bus_options``: the broker login
    (``app.cli._login.bus_options``).
    """
    cfg = plan.config
    builtin = sitl_base_port is not None or not cfg.link.connect
    eventlog = EventLog(out_dir / "events.jsonl")
    ground: GroundStation | None = None
    interrupted = False
    stop = StopFlag()
    wall_start = clock.monotonic_s()
    run = run_block(
        cfg, started_epoch_s=clock.time_s(), speedup=clock_rate(plan, builtin), process="ground"
    )
    try:
        async with AsyncExitStack() as stack:
            stack.enter_context(_forced(stop))
            stack.enter_context(eventlog)
            stack.enter_context(stop_on_signals(stop))
            events: EventSink = LoggingSink(eventlog)
            recorder = stack.enter_context(recording_inputs(plan, out_dir, builtin, "ground"))
            bus = await stack.enter_async_context(
                _mission_bus(broker_url, GROUND_CLIENT, None, bus_options)
            )
            presence = TeamPresence(events)
            link_states = await stack.enter_async_context(bus.subscribe(topics.ALL_LINKS))
            if sitl_base_port is not None:
                await stack.enter_async_context(
                    simulator_process(cfg, plan.count, sitl_base_port, out_dir)
                )
                ports = f"{sitl_base_port}..{sitl_base_port + plan.count - 1}"
                notify(f"built-in simulator running: {plan.count} vehicles on UDP ports {ports}")
            epoch = MissionEpoch(
                sender=GROUND_CLIENT,
                t_s=0.0,
                epoch_s=clock.time_s(),
                rate=clock_rate(plan, builtin),
            )
            await bus.publish(topics.MISSION_EPOCH, epoch, qos=1, retain=True)
            stack.push_async_callback(_end_epoch, bus, epoch)
            events.emit(
                "mission_start",
                0.0,
                name=cfg.name,
                vehicles=plan.count,
                bus=_broker_name(broker_url),
                simulator=sitl_base_port,
                epoch_s=epoch.epoch_s,
                clock_rate=epoch.rate,
            )
            ground = ground_station(
                plan,
                bus,
                events,
                builtin=builtin,
                replay=replay,
                on_snapshot=on_snapshot,
                name=GROUND_CLIENT,
                recorder=recorder,
                # its own mission clock: statuses are judged by it, never move it (#14)
                clock=MissionClock(epoch.epoch_s, epoch.rate, clock.time_s).now_s,
            )
            notify(f"ground station ready on {_broker_name(broker_url)}: waiting for the agents")
            shutdown = _Shutdown(bus, ground, presence, events, notify)
            try:
                async with _plain_errors(), asyncio.TaskGroup() as tg:
                    watcher = tg.create_task(presence.watch(link_states), name="ground-presence")
                    bus_watch = tg.create_task(
                        _watch_bus(bus, events, lambda: _mission_t(ground)), name="ground-bus"
                    )
                    station = tg.create_task(ground.run(), name="ground-station")
                    station.add_done_callback(lambda _t: stop.set("mission complete"))
                    reason = await stop.wait()
                    interrupted = not station.done()
                    station.cancel()
                    if interrupted:
                        events.emit("interrupted", _mission_t(ground), reason=reason)
                    await shutdown.send()
                    await shutdown.wait_offline(shutdown_grace_s)
                    watcher.cancel()
                    bus_watch.cancel()
            finally:
                if not shutdown.sent:  # the station failed or a second signal: still stop them
                    with contextlib.suppress(BusError, TimeoutError):
                        async with asyncio.timeout(2.0):
                            await shutdown.send()
    finally:
        # the agents hold their vehicles and the simulator is stopped; write the run folder
        wall_s = clock.monotonic_s() - wall_start
        remote = agent_files(out_dir, plan.count)
        result = write_outputs(
            plan, out_dir, ground, eventlog, {}, wall_s, interrupted, run=run, remote=remote
        )
    return result


def agent_files(out_dir: Path, count: int) -> dict[int, dict[str, Any]]:
    """The counters (``link``, ``agent``, ``bus``) each agent wrote to ``agent-N.json`` in
    ``out_dir`` as it stopped (before it went offline), by vehicle index: the agents that share
    the ground's run folder. A file missing (an agent elsewhere, or still running) or unreadable
    is left out, the latter with a warning."""
    found: dict[int, dict[str, Any]] = {}
    for i in range(count):
        path = out_dir / f"{topics.agent(i)}.json"
        try:
            document = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            continue
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            log.warning("%s: cannot read the agent's counters: %s", path, exc)
            continue
        counters = document.get("counters") if isinstance(document, dict) else None
        if isinstance(counters, dict):
            found[i] = counters
        else:
            log.warning("%s: no counters in it", path)
    return found


async def _end_epoch(bus: Bus, epoch: MissionEpoch) -> None:
    """Mark the retained epoch ended (a broker out of reach is logged: the ground is leaving)."""
    try:
        ended = epoch.model_copy(update={"ended": True})
        await bus.publish(topics.MISSION_EPOCH, ended, qos=1, retain=True)
    except BusError as exc:
        log.warning("ground could not mark its mission epoch ended: %s", exc)


class DeferredMissionClock:
    """A mission clock whose epoch comes later (the ground station's): None until ``set``."""

    def __init__(self) -> None:
        self.clock: MissionClock | None = None

    def set(self, clock: MissionClock) -> None:
        self.clock = clock

    def __call__(self) -> float | None:
        return self.clock.now_s() if self.clock is not None else None


async def _next_frame(link: VehicleLink, timeout_s: float) -> None:
    """Wait for the vehicle's next telemetry frame (a silent one fails in ``wait_ready``)."""
    async with contextlib.aclosing(link.telemetry()) as frames:  # released: no queue left
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                async for _frame in frames:
                    return


async def wait_for_epoch(
    subscription: Subscription, clock: Clock, timeout_s: float = EPOCH_TIMEOUT_S
) -> MissionClock:
    """The mission clock the ground station announced (its retained ``MissionEpoch``)."""
    try:
        async with asyncio.timeout(timeout_s):
            async for _topic, message in subscription:
                if isinstance(message, MissionEpoch) and not message.ended:
                    return MissionClock(message.epoch_s, message.rate, clock.time_s)
    except TimeoutError as exc:
        raise LinkError(
            f"no mission epoch from the ground station within {timeout_s:.0f} s: start "
            "'standoff ground' on the same broker"
        ) from exc
    raise BusError("the bus closed before the ground station's mission epoch arrived")


def _mission_t(ground: GroundStation) -> float:
    """Mission time so far; 0 before the first status (the state's time is -inf then)."""
    t = ground.state.mission_t_s
    return t if math.isfinite(t) else 0.0


class _Shutdown:
    """The end of a mission for the team: a ``shutdown`` command (QoS 1) to every agent, then
    waiting for them to hold their vehicles and go offline."""

    def __init__(
        self,
        bus: Bus,
        ground: GroundStation,
        presence: TeamPresence,
        events: EventSink,
        notify: Notify,
    ) -> None:
        self.sent = False
        self._bus = bus
        self._ground = ground
        self._presence = presence
        self._events = events
        self._notify = notify

    async def send(self) -> None:
        t = _mission_t(self._ground)
        self._presence.expect(v for v, _report in self._ground.state.reports)
        try:
            await self._bus.publish(
                topics.command(), Command(sender=GROUND_CLIENT, t_s=t, command="shutdown"), qos=1
            )
        except BusError as exc:
            self._events.emit("shutdown_not_sent", t, reason=str(exc))
            self._notify(f"could not send the shutdown command: {exc}")
            raise
        self.sent = True
        self._events.emit("shutdown_sent", t, agents=sorted(self._presence.online))
        self._notify(f"mission over at t = {t:.1f} s: shutdown sent to the agents")

    async def wait_offline(self, grace_s: float) -> None:
        t = _mission_t(self._ground)
        try:
            async with asyncio.timeout(grace_s):
                await self._presence.all_offline()
        except TimeoutError:
            online = sorted(self._presence.online)
            self._events.emit("agents_still_online", t, vehicles=online)
            self._notify(f"agents still online after {grace_s:.0f} s: {online}")
        else:
            self._notify(f"every agent stopped ({len(self._presence.seen)} seen)")
        await _leave_bus(
            self._bus,
            LinkState(sender=GROUND_CLIENT, t_s=t, online=False, reason="mission over"),
        )


# --- one vehicle's agent ----------------------------------------------------------------------


@dataclass
class AgentResult:
    """How an agent process ended and what it counted."""

    vehicle: int
    reason: str  # "shutdown", "SIGINT", "SIGTERM", or why the vehicle link ended
    stopped_by: signal.Signals | None = None
    held: bool = False  # the vehicle accepted the hold the agent sent as it stopped
    counters: dict[str, Any] = field(default_factory=dict)


def agent_url(
    plan: MissionPlan, vehicle: int, connect_url: str | None, base_port: int | None
) -> str:
    """The vehicle's MAVSDK URL: ``connect_url``; else the config's URL for this vehicle (one
    per vehicle); else the built-in simulator's port ``base_port + vehicle``."""
    if not 0 <= vehicle < plan.count:
        raise ConfigError(
            f"vehicle index {vehicle} is out of range: the mission has {plan.count} vehicles"
            f" (0..{plan.count - 1})"
        )
    if connect_url is not None:
        return connect_url
    urls = plan.config.link.connect
    if urls:
        if len(urls) != plan.count:
            raise ConfigError(
                f"the config lists {len(urls)} connect URLs for {plan.count} vehicles;"
                " give this vehicle's with --connect"
            )
        return urls[vehicle]
    port = base_port if base_port is not None else plan.config.sim.base_port
    return f"udpin://127.0.0.1:{port + vehicle}"


async def run_agent(
    plan: MissionPlan,
    vehicle: int,
    broker_url: str,
    connect_url: str,
    out_dir: Path,
    *,
    builtin_simulator: bool = False,
    notify: Notify = _quiet,
    clock: Clock = SYSTEM_CLOCK,
    bus_options: Mapping[str, Any] | None = None,
) -> AgentResult:
    """One agent process: fly ``vehicle`` (0-based) until the ground's shutdown or a signal.

    Opens the bus first (an unreachable broker fails before the vehicle is touched), then a
    MAVSDK link to system id ``vehicle + 1`` on ``connect_url``, brings it to offboard control
    and runs its ``VehicleAgent``. ``builtin_simulator``: the vehicle is the built-in simulator
    (velocity setpoints) unless the config names an autopilot. Raises the project's errors
    (``BusError``, ``LinkError``, ``ConfigError``) as themselves. ``bus_options``: the broker
    login (``app.cli._login.bus_options``).
    """
    if not 0 <= vehicle < plan.count:
        raise ConfigError(f"vehicle index {vehicle} is out of range 0..{plan.count - 1}")
    name = topics.agent(vehicle)
    stop = StopFlag()
    result = AgentResult(vehicle, "")
    async with AsyncExitStack() as stack:
        stack.enter_context(_forced(stop))
        eventlog = stack.enter_context(EventLog(out_dir / f"events-{name}.jsonl"))
        events: EventSink = LoggingSink(eventlog)
        stack.enter_context(stop_on_signals(stop))
        bus = await stack.enter_async_context(_mission_bus(broker_url, name, vehicle, bus_options))
        commands = await stack.enter_async_context(bus.subscribe(topics.ALL_COMMANDS))
        epochs = await stack.enter_async_context(bus.subscribe(topics.MISSION_EPOCH))
        events.emit(
            "agent_start", 0.0, vehicle=vehicle, url=connect_url, bus=_broker_name(broker_url)
        )
        flight = _Flight(plan, vehicle, bus, events, notify, clock, epochs)
        try:
            async with _plain_errors(), asyncio.TaskGroup() as tg:
                listener = tg.create_task(
                    _watch_shutdown(commands, vehicle, stop), name=f"{name}-shutdown"
                )
                bus_watch = tg.create_task(
                    _watch_bus(bus, events, lambda: flight.last_t_s), name=f"{name}-bus"
                )
                flying = tg.create_task(
                    flight.fly(connect_url, out_dir, builtin_simulator), name=f"{name}-flight"
                )
                flying.add_done_callback(lambda _t: stop.set("vehicle link closed"))
                result.reason = await stop.wait()
                result.stopped_by = stop.signum
                listener.cancel()
                bus_watch.cancel()
                if not flying.done():
                    # hold first, while the agent's loops still run: unwinding them (bus
                    # unsubscribes, logs) takes long enough on a loaded machine for the
                    # vehicle's offboard failsafe to act first
                    result.held = await flight.hold(result.reason)
                events.emit(
                    "agent_stop",
                    flight.last_t_s,
                    vehicle=vehicle,
                    reason=result.reason,
                    held=result.held,
                )
                flying.cancel()  # were the hold refused, the link tries again as it closes
        finally:
            result.counters = flight.counters(bus)
            (out_dir / f"{name}.json").write_text(
                json.dumps(dataclasses.asdict(result), indent=2, default=str) + "\n"
            )
            await _leave_bus(
                bus,
                LinkState(
                    sender=name,
                    t_s=flight.last_t_s,
                    online=False,
                    vehicle=vehicle,
                    reason=result.reason or "error",
                ),
            )
    return result


async def _watch_shutdown(commands: Subscription, vehicle: int, stop: StopFlag) -> None:
    async for _topic, message in commands:
        if (
            isinstance(message, Command)
            and message.command == "shutdown"
            and (message.vehicles is None or vehicle in message.vehicles)
        ):
            stop.set("shutdown")
            return


class _Flight:
    """The vehicle side of an agent process: link, offboard, tlog, and the agent loop."""

    def __init__(
        self,
        plan: MissionPlan,
        vehicle: int,
        bus: Bus,
        events: EventSink,
        notify: Notify,
        clock: Clock,
        epochs: Subscription,
    ) -> None:
        self._plan = plan
        self._clock = clock
        self._epochs = epochs
        self._vehicle = vehicle
        self._bus = bus
        self._events = events
        self._notify = notify
        self._link: VehicleLink | None = None
        self._agent: VehicleAgent | None = None

    @property
    def last_t_s(self) -> float:
        latest = self._link.latest if self._link is not None else None
        return latest.t_s if latest is not None else 0.0

    async def hold(self, reason: str) -> bool:
        """Stop commanding the vehicle and put it in hold now; whether it accepted.

        Only once the agent flies (under offboard control): before that the link, as it
        closes, holds a vehicle whose offboard start was under way. Bounded by
        ``HOLD_TIMEOUT_S``; a refusal or a timeout is an event and an error in the log.
        """
        link, agent = self._link, self._agent
        if link is None or agent is None:
            return False
        if agent.pilot_has_control:
            self._events.emit("hold", self.last_t_s, vehicle=self._vehicle, reason="left to pilot")
            return True  # left in the mode its pilot chose
        agent.stand_down()
        i = self._vehicle
        try:
            async with asyncio.timeout(HOLD_TIMEOUT_S):
                await link.hold()
        except (LinkError, TimeoutError) as exc:
            detail = str(exc) or f"no answer within {HOLD_TIMEOUT_S:.0f} s"
            log.error("agent %d: vehicle %d did not take the hold: %s", i + 1, i + 1, detail)
            self._events.emit("hold_refused", self.last_t_s, vehicle=i, reason=detail)
            return False
        self._events.emit("hold", self.last_t_s, vehicle=i, reason=reason)
        return True

    def counters(self, bus: Bus) -> dict[str, Any]:
        out: dict[str, Any] = {"bus": dataclasses.asdict(bus.stats)}
        if self._agent is not None:
            self._agent.measure_cpu()
            out["agent"] = dataclasses.asdict(self._agent.counters)
        if (link_counters := counters_of(self._link)) is not None:
            out["link"] = link_counters
        return out

    async def fly(self, url: str, out_dir: Path, builtin: bool) -> None:
        plan, i = self._plan, self._vehicle
        self._notify(f"agent {i + 1}: waiting for vehicle {i + 1} on {url}")
        mission_clock = DeferredMissionClock()
        async with AsyncExitStack() as stack:
            links = await stack.enter_async_context(
                open_links(
                    plan,
                    [url],
                    [i],
                    builtin,
                    mission_clock,
                    out_dir=out_dir,  # the vehicle's traffic into its .tlog, through a relay
                    gcs=gcs_endpoint(plan),
                )
            )
            link = self._link = links[i]
            self._notify(f"agent {i + 1}: waiting for the ground station's mission epoch")
            epoch = await wait_for_epoch(self._epochs, self._clock)
            mission_clock.set(epoch)
            await _next_frame(link, plan.config.link.connect_timeout_s)  # on the mission clock
            self._events.emit(
                "mission_epoch", epoch.now_s(), vehicle=i, epoch_s=epoch.epoch_s, rate=epoch.rate
            )
            await prepare_vehicle(link, bring_up(plan, i), self._events)
            self._notify(f"agent {i + 1}: vehicle {i + 1} under offboard control")
            recorder = stack.enter_context(
                recording_inputs(plan, out_dir, builtin, topics.agent(i))
            )
            self._agent = vehicle_agent(plan, i, link, self._bus, self._events, builtin, recorder)
            await self._agent.run()
