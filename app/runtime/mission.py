"""A whole mission in one process (``standoff fly``): vehicles, links, bus, ground and agents.

``run_mission`` takes a ``MissionPlan`` (``app.config.plan``), opens everything in order
(simulator, MAVSDK links, bus clients, logs), brings each vehicle to offboard control, runs the
ground station and one agent per vehicle until the scenario ends, and writes the run folder. Leaving it in any way (the end, an error, Ctrl-C)
puts every vehicle in hold and closes every log.
"""

import asyncio
import contextlib
import dataclasses
import json
import logging
import math
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from contextlib import AsyncExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from app.adapters.bus import BrokerUrl, Bus, InProcessBroker, Will, open_bus
from app.adapters.eventlog import EventLog
from app.adapters.tlog import TlogSample, TlogWriter
from app.adapters.vehicle.mavsdk.hub import MavsdkHub
from app.adapters.vehicle.mavsdk.link import LinkConfig
from app.adapters.vehicle.mavsdk.urls import validate_url
from app.config.plan import MissionPlan, sim_config
from app.errors import LinkError
from app.report.summary import TeamSample, summarize
from app.report.track import TrackRow, write_track_csv
from app.runtime.agent import AgentRuntimeParams, VehicleAgent
from app.runtime.events import LoggingSink
from app.runtime.ground import (
    GroundRuntimeParams,
    GroundStation,
    Measurement,
    ReplaySource,
    SimulatedSensor,
    TickSource,
)
from app.runtime.ports import topics
from app.runtime.ports.events import EventSink
from app.runtime.ports.messages import LinkState
from app.runtime.ports.vehicle import CourseSpeedCommand, GeodeticOrigin, VehicleLink
from app.runtime.sim_process import simulator_process
from sitl.ports import find_free_udp_base_port, udp_ports_free
from sitl.server import SimulatorServer

log = logging.getLogger(__name__)


@dataclass
class MissionResult:
    out_dir: Path
    summary: dict[str, Any]
    samples: list[TeamSample] = field(default_factory=list)
    interrupted: bool = False


Hook = Callable[["MissionContext"], Awaitable[None] | None]


@dataclass
class MissionContext:
    """What hooks (fault injection in tests, operator actions) can reach while a mission runs."""

    plan: MissionPlan
    sim: SimulatorServer | None
    links: dict[int, VehicleLink]
    ground: GroundStation
    agents: list[VehicleAgent]
    buses: list[Bus]


def observation_sources(plan: MissionPlan, replay: Sequence[Measurement] = ()) -> list[TickSource]:
    obs = plan.config.observations
    if obs.source == "simulated":
        return [SimulatedSensor(plan.target, obs.sigma_m, obs.rate_hz, obs.seed)]
    if obs.source == "replay":
        return [ReplaySource(replay)]
    return []


#: a vehicle farther than this from the mission's origin is taken for a wrong ``[origin]``
MAX_DISTANCE_FROM_ORIGIN_M = 50_000.0


async def prepare_vehicle(link: VehicleLink, plan: MissionPlan, events: EventSink) -> None:
    """Health, arm, take off, first setpoint, offboard: the MAVSDK idiom, each step checked.

    A vehicle more than ``MAX_DISTANCE_FROM_ORIGIN_M`` from the mission's origin is refused
    before it is armed: the mission is planned in metres about that origin (a SITL's home
    differs from one autopilot to the next), and it would send the vehicle there."""
    cfg = plan.config.link
    frame = await link.wait_ready(cfg.connect_timeout_s)
    distance = math.hypot(frame.east_m, frame.north_m)
    if distance > MAX_DISTANCE_FROM_ORIGIN_M:
        origin = plan.config.origin
        raise LinkError(
            f"vehicle {link.vehicle_id} is {distance / 1000.0:.0f} km from the mission's origin "
            f"({origin.lat_deg:.6f}, {origin.lon_deg:.6f}), at ({frame.latitude_deg:.6f}, "
            f"{frame.longitude_deg:.6f}): set [origin] in the mission config to where the "
            "vehicles are"
        )
    await link.arm()
    await link.take_off(cfg.take_off_timeout_s)
    latest = link.latest or frame
    first = CourseSpeedCommand(
        latest.course_rad, plan.config.limits.cruise_speed_m_s, cfg.altitude_m
    )
    await link.start_offboard(first)
    events.emit("offboard", latest.t_s, vehicle=link.vehicle_id - 1, autopilot=link.autopilot_name)


async def record_tlog(link: VehicleLink, writer: TlogWriter) -> None:
    async for f in link.telemetry():
        writer.write(
            TlogSample(
                f.t_s,
                f.latitude_deg,
                f.longitude_deg,
                f.altitude_m,
                f.relative_altitude_m,
                f.ground_speed_m_s * math.cos(f.course_rad),
                f.ground_speed_m_s * math.sin(f.course_rad),
                f.course_rad,
                f.ground_speed_m_s,
                armed=f.armed,
                mode=f.flight_mode.lower(),
            )
        )


async def hold_all(links: dict[int, VehicleLink], events: EventSink, t_s: float) -> None:
    """Put every vehicle in hold (a refusal is logged, not raised: the others still hold)."""
    for i, link in links.items():
        try:
            await link.hold()
        except LinkError as exc:
            events.emit("hold_refused", t_s, vehicle=i, reason=str(exc))


async def run_hooks(hooks: Sequence[tuple[float, Hook]], ctx: MissionContext) -> None:
    pending = sorted(hooks, key=lambda h: h[0])
    while pending:
        t = ctx.ground.state.mission_t_s
        while pending and t >= pending[0][0]:
            _, hook = pending.pop(0)
            result = hook(ctx)
            if result is not None:
                await result
        await asyncio.sleep(0.02)


@contextlib.asynccontextmanager
async def open_links(
    plan: MissionPlan, urls: Sequence[str], autopilot: str | None, stack: AsyncExitStack
) -> AsyncIterator[dict[int, VehicleLink]]:
    cfg = plan.config
    origin = GeodeticOrigin(cfg.origin.lat_deg, cfg.origin.lon_deg, cfg.origin.alt_m)
    hub = await stack.enter_async_context(MavsdkHub(urls, origin))
    link_config = LinkConfig(
        plan.setpoint_limits,
        autopilot=autopilot,  # type: ignore[arg-type]  # validated by the config schema
        link_timeout_s=cfg.link.link_timeout_s,
    )
    links: dict[int, VehicleLink] = {}
    for i in range(plan.count):
        links[i] = await stack.enter_async_context(
            hub.link(i + 1, link_config, timeout_s=cfg.link.connect_timeout_s)
        )
    yield links


async def run_mission(
    plan: MissionPlan,
    out_dir: Path,
    *,
    connect: Sequence[str] = (),
    broker_url: str | None = None,
    base_port: int | None = None,
    replay: Sequence[Measurement] = (),
    hooks: Sequence[tuple[float, Hook]] = (),
    on_snapshot: Callable[[Any], None] | None = None,
    sim_mode: Literal["process", "inline"] = "process",
) -> MissionResult:
    """Fly the plan to its end; write and return the run's results (also when interrupted).

    The built-in simulator (when no ``connect`` URLs are given) runs in its own process by
    default; ``sim_mode="inline"`` runs it in this event loop, where hooks can reach it (fault
    injection in tests) at the cost of sharing one interpreter with the mission.
    """
    cfg = plan.config
    urls = list(connect or cfg.link.connect)
    builtin = not urls
    autopilot = None if cfg.link.autopilot == "auto" else cfg.link.autopilot
    if builtin:
        autopilot = autopilot or "velocity"  # the built-in simulator takes velocity setpoints
    broker_url = broker_url if broker_url is not None else cfg.bus
    # a bad URL is a ConfigError here, before anything is started or written
    for url in urls:
        validate_url(url)
    if broker_url is not None:
        BrokerUrl.parse(broker_url)
    ground: GroundStation | None = None
    links: dict[int, VehicleLink] = {}
    agents: list[VehicleAgent] = []
    interrupted = False
    wall_start = time.monotonic()
    eventlog = EventLog(out_dir / "events.jsonl")
    try:
        async with AsyncExitStack() as stack:
            stack.enter_context(eventlog)
            events: EventSink = LoggingSink(eventlog)
            sim: SimulatorServer | None = None
            if builtin:
                port = base_port if base_port is not None else cfg.sim.base_port
                if base_port is None and not udp_ports_free(port, plan.count):
                    # another simulator or SITL is on the default ports: take free ones
                    port = find_free_udp_base_port(plan.count)
                    log.warning(
                        "UDP %d.. busy: the built-in simulator uses %d..", cfg.sim.base_port, port
                    )
                if sim_mode == "inline":
                    sim = await stack.enter_async_context(SimulatorServer(sim_config(plan, port)))
                else:
                    await stack.enter_async_context(
                        simulator_process(cfg, plan.count, port, out_dir)
                    )
                urls = [f"udpin://127.0.0.1:{port + i}" for i in range(plan.count)]
            events.emit(
                "mission_start",
                0.0,
                name=cfg.name,
                vehicles=plan.count,
                urls=urls,
                bus=broker_url or "in-process",
            )
            links = await stack.enter_async_context(open_links(plan, urls, autopilot, stack))
            async with asyncio.TaskGroup() as tg:
                for link in links.values():
                    tg.create_task(
                        prepare_vehicle(link, plan, events), name=f"prepare-{link.vehicle_id}"
                    )
            broker = InProcessBroker() if broker_url is None else None

            async def client(name: str, will: Will | None = None) -> Bus:
                if broker_url is None:
                    return await stack.enter_async_context(
                        open_bus(None, client_id=name, will=will, broker=broker)
                    )
                return await stack.enter_async_context(
                    open_bus(broker_url, client_id=name, will=will)
                )

            ground_bus = await client("ground")
            ground = GroundStation(
                plan.ground,
                GroundRuntimeParams(end_t_s=plan.end_t_s),
                ground_bus,
                events,
                truth=plan.target if builtin or cfg.observations.source == "simulated" else None,
                sources=observation_sources(plan, replay),
                external_observations=cfg.observations.external_topic
                if cfg.observations.source == "external"
                else None,
                on_snapshot=on_snapshot,
            )
            buses = [ground_bus]
            for i, link in links.items():
                name = f"agent-{i}"
                will = Will(
                    topics.link(i), LinkState(sender=name, t_s=0.0, online=False, vehicle=i)
                )
                agent_bus = await client(name, will)
                buses.append(agent_bus)
                agents.append(
                    VehicleAgent(
                        plan.agents[i],
                        link,
                        agent_bus,
                        events,
                        AgentRuntimeParams(
                            altitude_m=cfg.link.altitude_m,
                            clock_rate=cfg.sim.speedup if builtin else 1.0,
                        ),
                    )
                )
            ctx = MissionContext(plan, sim, links, ground, agents, buses)
            tlogs = [
                stack.enter_context(
                    TlogWriter(out_dir / f"vehicle-{i + 1}.tlog", i + 1, time.time())
                )
                for i in links
            ]
            try:
                async with asyncio.TaskGroup() as tg:
                    helpers = [tg.create_task(a.run(), name=a.name) for a in agents]
                    helpers += [
                        tg.create_task(record_tlog(link, tlogs[i]), name=f"tlog-{i + 1}")
                        for i, link in links.items()
                    ]
                    if hooks:
                        helpers.append(tg.create_task(run_hooks(hooks, ctx), name="hooks"))
                    await ground.run()
                    # the end: hold every vehicle while its agent still streams setpoints, so
                    # no autopilot sees offboard setpoints stop before it is told to hold
                    for agent in agents:
                        agent.stand_down()
                    await hold_all(links, events, ground.state.mission_t_s)
                    for task in helpers:
                        task.cancel()
            except asyncio.CancelledError:
                interrupted = True
                events.emit("interrupted", ground.state.mission_t_s)
                raise
    finally:
        # every vehicle is in hold and every log closed by now; write the run folder
        wall_s = time.monotonic() - wall_start
        result = write_outputs(plan, out_dir, ground, eventlog, links, wall_s, interrupted, agents)
    return result


def _fusion_counters(ground: GroundStation | None) -> dict[str, int] | None:
    """What the ground's main filter received and refused: local estimates older than the
    newest it had from that vehicle, and ones built on an older allocation than it last gave."""
    if ground is None:
        return None
    main = ground.state.main
    return {
        "local_estimates_taken": main.received,
        "out_of_order_dropped": main.out_of_order_dropped,
        "stale_basis_dropped": main.stale_basis_dropped,
    }


def write_outputs(
    plan: MissionPlan,
    out_dir: Path,
    ground: GroundStation | None,
    eventlog: EventLog,
    links: dict[int, VehicleLink],
    wall_s: float,
    interrupted: bool,
    agents: Sequence[VehicleAgent] = (),
) -> MissionResult:
    samples = ground.samples if ground is not None else []
    summary = summarize(
        samples,
        plan.config.radius_m,
        plan.config.tracking_command_s,
        plan.ground.stages.radius_tolerance_m,
        plan.ground.stages.spacing_tolerance_rad,
    )
    counters = {
        str(i): dataclasses.asdict(c)
        for i, link in links.items()
        if dataclasses.is_dataclass(c := getattr(link, "counters", None))
        and not isinstance(c, type)
    }
    summary.update(
        {
            "mission": plan.config.name,
            "vehicles": plan.count,
            "end_t_s": plan.end_t_s,
            "mission_t_s": ground.state.mission_t_s
            if ground is not None and math.isfinite(ground.state.mission_t_s)
            else None,
            "wall_s": wall_s,
            "interrupted": interrupted,
            "events": dict(eventlog.counts),
            "links": counters,
            "agents": {str(a.params.vehicle): dataclasses.asdict(a.counters) for a in agents},
            "fusion": _fusion_counters(ground),
        }
    )
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    nan = math.nan
    rows = [
        TrackRow(
            s.t_s,
            v.vehicle,
            v.east_m,
            v.north_m,
            v.course_rad,
            v.speed_m_s,
            s.target_east_m,
            s.target_north_m,
            (float(v.active), *(s.estimate[:2] if s.estimate is not None else (nan, nan))),
        )
        for s in samples
        for v in s.vehicles
    ]
    write_track_csv(
        out_dir / "track.csv", rows, extra_columns=("active", "estimate_east_m", "estimate_north_m")
    )
    _add_stage_column(out_dir / "track.csv", samples)
    if samples:
        from app.report.mission_plots import plot_mission  # matplotlib: 0.45 s, at the end only

        plot_mission(samples, plan.config.radius_m, out_dir)
    return MissionResult(out_dir, summary, samples, interrupted)


def _add_stage_column(path: Path, samples: Sequence[TeamSample]) -> None:
    lines = path.read_text(encoding="utf-8").splitlines()
    stages = [s.stage for s in samples for _ in s.vehicles]
    out = [lines[0] + ",stage"] + [
        f"{line},{stage}" for line, stage in zip(lines[1:], stages, strict=True)
    ]
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
