"""A whole mission in one process (``standoff fly``): vehicles, links, bus, ground and agents.

``Mission(plan, out_dir).run()`` opens everything in order (simulator, MAVSDK links, bus
clients, logs), brings each vehicle to offboard control, runs the ground station and one agent
per vehicle until the scenario ends, and writes the run folder. Leaving it in any way (the end,
an error, Ctrl-C) puts every vehicle in hold and closes every log.

Mission time: 0 is when the vehicles are there to fly (the built-in simulator's start, or the
launch with external vehicles), on the host's monotonic clock times the clock rate (the
simulator's speed-up); every link maps its vehicle's boot clock onto it. ``operator``: lines an
operator types (``resume [N ...]``, ``hold [N ...]``; N the vehicle number as the events print
it, none: every vehicle), published as bus commands to the agents.
"""

import asyncio
import logging
import signal
from collections.abc import AsyncIterator, Callable, Coroutine, Sequence
from contextlib import AsyncExitStack
from pathlib import Path
from typing import Any, TypeVar

from app.adapters.bus import BrokerUrl, InProcessBroker, Will, open_bus
from app.adapters.bus.signing import MissionKey
from app.adapters.eventlog import EventLog
from app.adapters.vehicle.mavsdk.urls import validate_url
from app.compose.parts import (
    CpuMeter,
    MissionResult,
    bring_up,
    clock_rate,
    gcs_endpoint,
    gcs_ports,
    ground_station,
    open_links,
    recording_inputs,
    vehicle_agent,
    write_outputs,
)
from app.compose.simulator import simulator_process
from app.config.plan import MissionPlan
from app.errors import ConfigError
from app.report.provenance import run_block
from app.runtime.agent import VehicleAgent
from app.runtime.events import LoggingSink
from app.runtime.ground import GroundStation, Measurement
from app.runtime.ports import topics
from app.runtime.ports.bus import Bus
from app.runtime.ports.clock import SYSTEM_CLOCK, Clock, MissionClock
from app.runtime.ports.events import EventSink
from app.runtime.ports.messages import Command, LinkState
from app.runtime.ports.vehicle import VehicleLink
from app.runtime.ports.view import MissionSnapshot
from app.runtime.vehicle import hold_all, prepare_vehicle
from sitl.ports import find_free_udp_base_port, udp_ports_free
from sitl.server import SimulatorServer

log = logging.getLogger(__name__)
T = TypeVar("T")


class Mission:
    """One mission flown in this process: ``run`` flies it to its end and writes the run folder.

    Its parts (``links``, ``ground``, ``agents``, ``buses``) are public once built (``ground``
    is None until then), for whoever watches the mission while it runs. ``simulator``: a
    built-in simulator already serving the plan in this event loop, flown instead of one in a
    process of its own (sharing one interpreter with the mission; a test reaches its vehicles).
    """

    def __init__(
        self,
        plan: MissionPlan,
        out_dir: Path,
        *,
        connect: Sequence[str] = (),
        broker_url: str | None = None,
        base_port: int | None = None,
        replay: Sequence[Measurement] = (),
        on_snapshot: Callable[[MissionSnapshot], None] | None = None,
        simulator: SimulatorServer | None = None,
        clock: Clock = SYSTEM_CLOCK,
        operator: AsyncIterator[str] | None = None,
        notify: Callable[[str], None] | None = None,
    ) -> None:
        cfg = plan.config
        self.plan = plan
        self.out_dir = out_dir
        self.urls = list(connect or cfg.link.connect)
        self.builtin = not self.urls
        self.broker_url = broker_url if broker_url is not None else cfg.bus
        # a bad URL is a ConfigError here, before anything is started or written
        for url in self.urls:
            validate_url(url)
        if len(self.urls) not in (0, 1, plan.count):
            raise ConfigError(
                f"{len(self.urls)} vehicle URLs for {plan.count} vehicles: give one URL that "
                f"carries them all or one per vehicle ({plan.count})"
            )
        if self.broker_url is not None:
            BrokerUrl.parse(self.broker_url)
        self.links: dict[int, VehicleLink] = {}
        self.ground: GroundStation | None = None
        self.agents: list[VehicleAgent] = []
        self.buses: list[Bus] = []
        self.interrupted = False
        self._base_port = base_port
        self._replay = replay
        self._on_snapshot = on_snapshot
        self._simulator = simulator
        self._clock = clock
        self._operator = operator
        self._notify = notify  # a line for the operator (each vehicle link and its relay)
        self.mission_clock: MissionClock | None = None

    async def run(self) -> MissionResult:
        """Fly the plan to its end; write and return the run's results (also when interrupted)."""
        wall_start = self._clock.monotonic_s()
        cpu = CpuMeter.start()
        run = run_block(
            self.plan.config,
            started_epoch_s=self._clock.time_s(),
            speedup=clock_rate(self.plan, self.builtin),
        )
        eventlog = EventLog(self.out_dir / "events.jsonl")
        try:
            async with AsyncExitStack() as stack:
                stack.enter_context(eventlog)
                await self._fly(stack, LoggingSink(eventlog))
        finally:
            # every vehicle is in hold and every log closed by now; write the run folder
            wall_s = self._clock.monotonic_s() - wall_start
            agents_cpu_s = sum(a.counters.cpu_s for a in self.agents)
            result = write_outputs(
                self.plan,
                self.out_dir,
                self.ground,
                eventlog,
                self.links,
                wall_s,
                self.interrupted,
                self.agents,
                run=run,
                cpu=cpu.block(
                    wall_s, clock_rate(self.plan, self.builtin), self.plan.count, agents_cpu_s
                ),
            )
        return result

    async def _vehicle_urls(self, stack: AsyncExitStack) -> list[str]:
        """The vehicles' URLs: the given ones, else the built-in simulator's (started here
        in a process of its own unless one was given)."""
        plan, cfg = self.plan, self.plan.config
        if not self.builtin:
            return self.urls
        if self._simulator is not None:
            port = self._simulator.config.base_port
        else:
            port = self._base_port if self._base_port is not None else cfg.sim.base_port
            taken = gcs_ports(gcs_endpoint(plan), plan.count)
            clash = taken & set(range(port, port + plan.count))
            if self._base_port is None and (clash or not udp_ports_free(port, plan.count)):
                # another simulator or SITL is on the default ports, or the team's ports reach
                # the ground station's: take free ones
                while True:
                    port = find_free_udp_base_port(plan.count)
                    if not taken & set(range(port, port + plan.count)):
                        break
                why = f"the ground station's port {min(clash)} is among them" if clash else "busy"
                log.warning(
                    "UDP %d..%d: %s; the built-in simulator uses %d..",
                    cfg.sim.base_port,
                    cfg.sim.base_port + plan.count - 1,
                    why,
                    port,
                )
            await stack.enter_async_context(simulator_process(cfg, plan.count, port, self.out_dir))
        return [f"udpin://127.0.0.1:{port + i}" for i in range(plan.count)]

    async def _fly(self, stack: AsyncExitStack, events: EventSink) -> None:
        """Open the parts on ``stack`` and fly (``interrupted`` when cancelled in flight)."""
        plan, cfg = self.plan, self.plan.config
        urls = await self._vehicle_urls(stack)
        self.mission_clock = self._start_clock()
        events.emit(
            "mission_start",
            0.0,
            name=cfg.name,
            vehicles=plan.count,
            urls=urls,
            bus=self.broker_url or "in-process",
        )
        self.links = await stack.enter_async_context(
            open_links(
                plan,
                urls,
                range(plan.count),
                self.builtin,
                self.mission_clock,
                out_dir=self.out_dir,  # each vehicle's traffic into its .tlog, through a relay
                gcs=gcs_endpoint(plan),
                notify=self._notify,
            )
        )
        recorder = stack.enter_context(recording_inputs(plan, self.out_dir, self.builtin))
        async with asyncio.TaskGroup() as tg:
            for i, link in self.links.items():
                tg.create_task(
                    prepare_vehicle(link, bring_up(plan, i), events),
                    name=f"prepare-{link.vehicle_id}",
                )
        broker = InProcessBroker() if self.broker_url is None else None
        # [bus] mission_key_file: every part seals what it sends and takes only what is sealed
        # (one shared key, as in the multi-process mode; the logins are that mode's)
        key_file = cfg.bus_login.mission_key_file
        mission_key = MissionKey.load(key_file) if key_file is not None else None

        async def client(name: str, will: Will | None = None) -> Bus:
            bus = await stack.enter_async_context(
                open_bus(
                    self.broker_url,
                    client_id=name,
                    will=will,
                    broker=broker,
                    mission_key=mission_key,
                )
            )
            self.buses.append(bus)
            return bus

        ground = ground_station(
            plan,
            await client("ground"),
            events,
            builtin=self.builtin,
            replay=self._replay,
            on_snapshot=self._on_snapshot,
            recorder=recorder,
            clock=self._clock_now,
        )
        agents = []
        for i, link in self.links.items():
            name = topics.agent(i)
            will = Will(topics.link(i), LinkState(sender=name, t_s=0.0, online=False, vehicle=i))
            bus = await client(name, will)
            agents.append(vehicle_agent(plan, i, link, bus, events, self.builtin, recorder))
        self.agents = agents
        self.ground = ground
        try:
            async with asyncio.TaskGroup() as tg:
                helpers = [tg.create_task(a.run(), name=a.name) for a in agents]
                if self._operator is not None:
                    operator_bus = await client("operator")
                    helpers.append(
                        tg.create_task(
                            relay_operator(
                                self._operator, operator_bus, events, plan.count, self._now
                            ),
                            name="operator",
                        )
                    )
                await ground.run()
                # the end: hold every vehicle while its agent still streams setpoints, so
                # no autopilot sees offboard setpoints stop before it is told to hold
                for agent in agents:
                    agent.stand_down()
                await hold_all(self.links, events, ground.state.mission_t_s)
                for task in helpers:
                    task.cancel()
        except asyncio.CancelledError:
            self.interrupted = True
            events.emit("interrupted", ground.state.mission_t_s)
            raise

    def station_t_s(self) -> float | None:
        """The mission time the ground station has reached (None before it runs)."""
        return self.ground.state.mission_t_s if self.ground is not None else None

    def _clock_now(self) -> float | None:
        """The mission clock (None before it starts): the ground judges message times by it."""
        return self.mission_clock.now_s() if self.mission_clock is not None else None

    def _now(self) -> float:
        return self.mission_clock.now_s() if self.mission_clock is not None else 0.0

    def _start_clock(self) -> MissionClock:
        """Mission time: a simulator in this process gives its own time (exact, and it stays
        the simulator's when a loaded machine slows it); else the host's monotonic clock times
        the clock rate from now (when the vehicles are there)."""
        simulator = self._simulator
        if simulator is not None:
            return MissionClock(0.0, 1.0, lambda: simulator.time_s)
        return MissionClock.starting_now(
            clock_rate(self.plan, self.builtin), self._clock.monotonic_s
        )


#: how often, after a Ctrl-C, whether the mission still flies is looked at (s of the host)
FLYING_ON_CHECK_S = 1.0


async def fly_until_interrupted(
    run: Coroutine[Any, Any, T], mission_t: Callable[[], float | None]
) -> T:
    """Await ``run`` (a mission's ``run()``), stopped by a Ctrl-C (SIGINT) as
    ``KeyboardInterrupt``; ``mission_t``: the mission time its ground station has reached
    (None before it has one).

    The first SIGINT cancels the run (every vehicle held on the way out, the run folder
    written). A cancellation must not be lost on the way: Python 3.11's asyncio can swallow one
    that meets another event at the same instant, and the mission then flew on to its end. So
    while the ground station's mission time still moves ``FLYING_ON_CHECK_S`` after the last
    cancellation, it is cancelled again, and a run that ends normally after a SIGINT still
    ends as interrupted. A second SIGINT raises ``KeyboardInterrupt`` at once."""
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    assert task is not None
    interrupts = 0

    def check(t_then: float | None) -> None:
        if task.done():
            return
        t_now = mission_t()
        if t_now is not None and t_then is not None and t_now > t_then:
            log.warning("the mission still flies after Ctrl-C (at %.1f s): cancelled again", t_now)
            task.cancel()
        loop.call_later(FLYING_ON_CHECK_S, check, t_now)

    def on_sigint() -> None:
        nonlocal interrupts
        interrupts += 1
        if interrupts > 1:
            raise KeyboardInterrupt
        task.cancel()
        # the first look only notes the time: the station may take a status or two before
        # the cancellation reaches it
        loop.call_later(FLYING_ON_CHECK_S, check, None)

    loop.add_signal_handler(signal.SIGINT, on_sigint)
    try:
        result = await run
    except asyncio.CancelledError:
        if interrupts:
            raise KeyboardInterrupt from None
        raise
    finally:
        loop.remove_signal_handler(signal.SIGINT)
    if interrupts:
        raise KeyboardInterrupt
    return result


def parse_operator_line(line: str, vehicles: int) -> Command | None:
    """An operator's line as a bus command: ``resume``/``hold`` with optional vehicle numbers
    (from 1, as the live view and the events print them; the command carries the internal
    0-based indices); None for a blank line; ``ValueError`` otherwise."""
    words = line.split()
    if not words:
        return None
    verb, args = words[0].lower(), words[1:]
    if verb not in ("resume", "hold"):
        raise ValueError(f"unknown command {verb!r}: type 'resume [N ...]' or 'hold [N ...]'")
    try:
        numbers = tuple(int(a) for a in args)
    except ValueError:
        raise ValueError(f"vehicle numbers are 1..{vehicles}, got {args}") from None
    if any(not 1 <= n <= vehicles for n in numbers):
        raise ValueError(f"vehicle numbers are 1..{vehicles}, got {list(numbers)}")
    return Command(
        sender="operator",
        t_s=0.0,
        command="resume" if verb == "resume" else "hold",
        vehicles=tuple(n - 1 for n in numbers) or None,
    )


async def relay_operator(
    lines: AsyncIterator[str],
    bus: Bus,
    events: EventSink,
    vehicles: int,
    now: Callable[[], float] = lambda: 0.0,
) -> None:
    """Publish each operator line as a command to the agents (stamped ``now()``, mission time);
    a bad line is logged and skipped."""
    async for line in lines:
        try:
            command = parse_operator_line(line, vehicles)
        except ValueError as exc:
            log.warning("operator: %s", exc)
            continue
        if command is None:
            continue
        t = now()
        events.emit("operator_command", t, command=command.command, vehicles=command.vehicles)
        await bus.publish(topics.command(), command.model_copy(update={"t_s": t}), qos=1)
