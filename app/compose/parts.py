"""The parts of a mission, built in one place for ``fly``, ``ground`` and ``agent`` alike: the
vehicle links, the ground station, the agents, their logs, and the run folder at the end."""

import asyncio
import dataclasses
import logging
import math
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.adapters.eventlog import EventLog
from app.adapters.tlog import TlogWriter, record_tlog
from app.adapters.vehicle.mavsdk.hub import MavsdkHub
from app.adapters.vehicle.mavsdk.link import LinkConfig
from app.config.plan import MissionPlan
from app.core.mission.team import TeamSample
from app.report.run_folder import write_run_folder
from app.runtime.agent import AgentRuntimeParams, VehicleAgent
from app.runtime.ground import (
    GroundRuntimeParams,
    GroundStation,
    Measurement,
    ReplaySource,
    SimulatedSensor,
    TickSource,
)
from app.runtime.ports.bus import Bus
from app.runtime.ports.clock import Clock
from app.runtime.ports.events import EventSink
from app.runtime.ports.vehicle import GeodeticOrigin, VehicleLink
from app.runtime.ports.view import MissionSnapshot
from app.runtime.vehicle import BringUp

_log = logging.getLogger(__name__)


@dataclass
class MissionResult:
    out_dir: Path
    summary: dict[str, Any]
    samples: list[TeamSample] = field(default_factory=list)
    interrupted: bool = False


def bring_up(plan: MissionPlan, vehicle: int) -> BringUp:
    """How this mission brings vehicle ``vehicle`` (0-based) to offboard control
    (``prepare_vehicle``): at its own altitude of the stack, handed over only in the air."""
    cfg = plan.config
    min_airspeed = cfg.link.handover_min_airspeed_m_s
    return BringUp(
        connect_timeout_s=cfg.link.connect_timeout_s,
        take_off_timeout_s=cfg.link.take_off_timeout_s,
        altitude_m=cfg.link.vehicle_altitude_m(vehicle),
        cruise_speed_m_s=cfg.limits.cruise_speed_m_s,
        origin_lat_deg=cfg.origin.lat_deg,
        origin_lon_deg=cfg.origin.lon_deg,
        handover_min_height_m=cfg.link.handover_min_height_m,
        handover_min_airspeed_m_s=min_airspeed
        if min_airspeed is not None
        else cfg.limits.min_speed_m_s,
        handover_timeout_s=cfg.link.handover_timeout_s,
    )


def link_config(plan: MissionPlan, builtin: bool) -> LinkConfig:
    """The vehicle links' settings; the built-in simulator takes velocity setpoints unless the
    config names an autopilot."""
    cfg = plan.config
    autopilot = None if cfg.link.autopilot == "auto" else cfg.link.autopilot
    if builtin:
        autopilot = autopilot or "velocity"
    return LinkConfig(
        plan.setpoint_limits,
        autopilot=autopilot,
        link_timeout_s=cfg.link.link_timeout_s,
        clock_window_s=cfg.link.clock_window_s,
    )


def clock_rate(plan: MissionPlan, builtin: bool) -> float:
    """Mission seconds per host second: the built-in simulator's speed-up, else 1."""
    return plan.config.sim.speedup if builtin else 1.0


@asynccontextmanager
async def open_links(
    plan: MissionPlan,
    urls: Sequence[str],
    vehicles: Sequence[int],
    builtin: bool,
    mission_clock: Callable[[], float | None] | None = None,
) -> AsyncIterator[dict[int, VehicleLink]]:
    """One MAVSDK hub on ``urls`` and a link to each of ``vehicles`` (0-based: system id i+1),
    every vehicle's boot clock mapped onto ``mission_clock`` (``MissionClock``)."""
    cfg = plan.config
    origin = GeodeticOrigin(cfg.origin.lat_deg, cfg.origin.lon_deg, cfg.origin.alt_m)
    config = link_config(plan, builtin)
    async with AsyncExitStack() as stack:
        hub = await stack.enter_async_context(MavsdkHub(urls, origin, mission_clock=mission_clock))
        links: dict[int, VehicleLink] = {}
        for i in vehicles:
            links[i] = await stack.enter_async_context(
                hub.link(i + 1, config, timeout_s=cfg.link.connect_timeout_s)
            )
        yield links


def observation_sources(plan: MissionPlan, replay: Sequence[Measurement] = ()) -> list[TickSource]:
    obs = plan.config.observations
    if obs.source == "simulated":
        return [SimulatedSensor(plan.target, obs.sigma_m, obs.rate_hz, obs.seed)]
    if obs.source == "replay":
        return [ReplaySource(replay)]
    return []


def ground_station(
    plan: MissionPlan,
    bus: Bus,
    events: EventSink,
    *,
    builtin: bool,
    replay: Sequence[Measurement] = (),
    on_snapshot: Callable[[MissionSnapshot], None] | None = None,
    name: str = "ground",
) -> GroundStation:
    """The ground station of the plan. The simulated truth (for the summary's errors) is the
    plan's target path when the vehicles are the built-in simulator or the ground simulates the
    observations."""
    cfg = plan.config
    return GroundStation(
        plan.ground,
        GroundRuntimeParams(end_t_s=plan.end_t_s),
        bus,
        events,
        truth=plan.target if builtin or cfg.observations.source == "simulated" else None,
        sources=observation_sources(plan, replay),
        external_observations=cfg.observations.external_topic
        if cfg.observations.source == "external"
        else None,
        on_snapshot=on_snapshot,
        name=name,
    )


def vehicle_agent(
    plan: MissionPlan, vehicle: int, link: VehicleLink, bus: Bus, events: EventSink, builtin: bool
) -> VehicleAgent:
    """Vehicle ``vehicle``'s agent, at its own altitude of the stack, its phase actuator the
    file's choice resolved against what its autopilot honours; on the built-in simulator its
    clock runs ``speedup`` times the host's."""
    cfg = plan.config
    return VehicleAgent(
        plan.agents[vehicle],
        link,
        bus,
        events,
        AgentRuntimeParams(
            altitude_m=cfg.link.vehicle_altitude_m(vehicle),
            clock_rate=clock_rate(plan, builtin),
            phase_actuator=plan.phase_actuator,
        ),
    )


def tlog_writer(out_dir: Path, vehicle: int, clock: Clock) -> TlogWriter:
    """Vehicle ``vehicle``'s ``vehicle-{vehicle+1}.tlog``, stamped from now."""
    return TlogWriter(out_dir / f"vehicle-{vehicle + 1}.tlog", vehicle + 1, clock.time_s())


@asynccontextmanager
async def recording_tlogs(
    links: Mapping[int, VehicleLink], out_dir: Path, clock: Clock
) -> AsyncIterator[None]:
    """Every link's telemetry into its ``vehicle-{i+1}.tlog`` for the block (opened as the
    links are, so that the take-off and the climb to the hand-over are in the flight log)."""
    async with AsyncExitStack() as stack:
        writers = {i: stack.enter_context(tlog_writer(out_dir, i, clock)) for i in links}
        tasks = [
            asyncio.create_task(record_tlog(link, writers[i]), name=f"tlog-{i + 1}")
            for i, link in links.items()
        ]
        try:
            yield
        finally:
            for task in tasks:
                task.cancel()
            for task, outcome in zip(
                tasks, await asyncio.gather(*tasks, return_exceptions=True), strict=True
            ):
                if isinstance(outcome, Exception):
                    _log.error("%s stopped early: %s", task.get_name(), outcome)


def counters_of(thing: object) -> dict[str, Any] | None:
    """The ``counters`` dataclass of a link or an agent, as a dict (None when it has none)."""
    c = getattr(thing, "counters", None)
    if dataclasses.is_dataclass(c) and not isinstance(c, type):
        return dataclasses.asdict(c)
    return None


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
    links: Mapping[int, VehicleLink],
    wall_s: float,
    interrupted: bool,
    agents: Sequence[VehicleAgent] = (),
) -> MissionResult:
    """The run folder (``write_run_folder``) from what the ground recorded and the parts
    counted."""
    samples = ground.samples if ground is not None else []
    mission_t = ground.state.mission_t_s if ground is not None else math.nan
    summary = write_run_folder(
        out_dir,
        samples,
        radius_m=plan.config.radius_m,
        tracking_command_s=plan.config.tracking_command_s,
        radius_tolerance_m=plan.ground.stages.radius_tolerance_m,
        spacing_tolerance_rad=plan.ground.stages.spacing_tolerance_rad,
        extra={
            "mission": plan.config.name,
            "vehicles": plan.count,
            "end_t_s": plan.end_t_s,
            "mission_t_s": mission_t if math.isfinite(mission_t) else None,
            "wall_s": wall_s,
            "interrupted": interrupted,
            "events": dict(eventlog.counts),
            "links": {
                str(i): c for i, link in links.items() if (c := counters_of(link)) is not None
            },
            "agents": {str(a.params.vehicle): dataclasses.asdict(a.counters) for a in agents},
            "fusion": _fusion_counters(ground),
            "phase_actuators": {
                str(a.params.vehicle): a.actuator for a in agents if a.actuator is not None
            },
            "vehicle_altitudes_m": {
                str(i): plan.config.link.vehicle_altitude_m(i) for i in range(plan.count)
            },
        },
    )
    return MissionResult(out_dir, summary, samples, interrupted)
