"""The parts of a mission, built in one place for ``fly``, ``ground`` and ``agent`` alike: the
vehicle links, the ground station, the agents, their logs, and the run folder at the end."""

import dataclasses
import logging
import math
import resource
import time
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.adapters.eventlog import EventLog
from app.adapters.observations_log import ObservationLog, observations_file
from app.adapters.vehicle.autopilots.px4 import px4_mission_rates
from app.adapters.vehicle.mavsdk.hub import MavsdkHub
from app.adapters.vehicle.mavsdk.link import LinkConfig
from app.adapters.vehicle.mavsdk.relay_process import RelayProcess, RelaySpec
from app.adapters.vehicle.mavsdk.urls import UdpEndpoint, parse_gcs_endpoint, udp_endpoint_of_url
from app.config.plan import MissionPlan
from app.core.mission.team import TeamSample
from app.report.run_folder import write_run_config, write_run_folder
from app.report.summary import vehicle_key
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
from app.runtime.ports.events import EventSink
from app.runtime.ports.record import InputRecorder
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
        camera_component_id=cfg.link.camera_component_id,
        arduplane_turn_learning=cfg.link.arduplane_turn_learning,
        arduplane_speed_learning=cfg.link.arduplane_speed_learning,
        px4_airspeed_via_trim=cfg.link.px4_airspeed_via_trim,
        px4_telemetry_rates_hz=(
            None if (rate := cfg.link.px4_telemetry_rate_hz) is None else px4_mission_rates(rate)
        ),
        timesync_period_s=cfg.link.timesync_period_s,
    )


def clock_rate(plan: MissionPlan, builtin: bool) -> float:
    """Mission seconds per host second: the built-in simulator's speed-up, else 1."""
    return plan.config.sim.speedup if builtin else 1.0


def gcs_ports(gcs: UdpEndpoint | None, count: int) -> frozenset[int]:
    """The UDP ports on this host that the ground-station side of ``count`` vehicles' relays
    sends to or listens on (``gcs_endpoint``): a ``udpout`` to this host's port, or a
    ``udpin`` base and the ``count - 1`` above it. A built-in simulator's vehicle on one of them
    would hear the relays' copies of every vehicle's traffic as its own (at 14540 + i,
    vehicle 11's port is QGroundControl's 14550)."""
    if gcs is None:
        return frozenset()
    if gcs.mode == "udpin":
        return frozenset(range(gcs.port, gcs.port + count))
    local = gcs.host in ("localhost", "0.0.0.0") or gcs.host.startswith("127.")
    return frozenset({gcs.port}) if local else frozenset()


def gcs_endpoint(plan: MissionPlan) -> UdpEndpoint | None:
    """Where a ground station beside the app sees the vehicles (``[link] gcs_forward``; None:
    nowhere)."""
    spec = plan.config.link.gcs_forward
    return None if spec in ("", "off") else parse_gcs_endpoint(spec)


@asynccontextmanager
async def open_links(
    plan: MissionPlan,
    urls: Sequence[str],
    vehicles: Sequence[int],
    builtin: bool,
    mission_clock: Callable[[], float | None] | None = None,
    *,
    out_dir: Path | None = None,
    gcs: UdpEndpoint | None = None,
    notify: Callable[[str], None] | None = None,
) -> AsyncIterator[dict[int, VehicleLink]]:
    """One MAVSDK hub on ``urls`` and a link to each of ``vehicles`` (0-based: system id i+1),
    every vehicle's boot clock mapped onto ``mission_clock`` (``MissionClock``).

    With ``out_dir`` or ``gcs``, every UDP connection goes through a ``MavlinkRelay`` (all of
    them in one process of their own, ``RelayProcess``): each
    vehicle's traffic, both ways, recorded in ``out_dir/vehicle-{i+1}.tlog`` from the links'
    opening (the take-off and the climb to the hand-over are in the flight log), and served to
    the ground station at ``gcs``. ``notify``: a line per connection for the operator."""
    cfg = plan.config
    origin = GeodeticOrigin(cfg.origin.lat_deg, cfg.origin.lon_deg, cfg.origin.alt_m)
    config = link_config(plan, builtin)
    async with AsyncExitStack() as stack:
        app_urls = list(urls)
        specs = relay_specs(urls, vehicles, gcs) if out_dir is not None or gcs is not None else {}
        if specs:
            tlogs = (
                {i + 1: out_dir / f"vehicle-{i + 1}.tlog" for i in vehicles}
                if out_dir is not None
                else {}
            )
            # the relays in a process of their own: no tick of this interpreter delays a datagram
            relays = await stack.enter_async_context(RelayProcess(list(specs.values()), tlogs))
            for k, relayed in zip(specs, relays.links, strict=True):
                app_urls[k] = relayed.app_url
                if notify is not None:
                    notify(f"  {relayed.description}")
        hub = await stack.enter_async_context(
            MavsdkHub(app_urls, origin, mission_clock=mission_clock)
        )
        links: dict[int, VehicleLink] = {}
        for i in vehicles:
            links[i] = await stack.enter_async_context(
                hub.link(i + 1, config, timeout_s=cfg.link.connect_timeout_s)
            )
        yield links


def relay_specs(
    urls: Sequence[str], vehicles: Sequence[int], gcs: UdpEndpoint | None
) -> dict[int, RelaySpec]:
    """The relay of each connection the relay can open (by its index in ``urls``); the others
    (``tcpin``, serial) are flown directly, with no flight log and no ground station."""
    # each connection one vehicle: vehicle i's own ground-station port, and its system id
    one_each = len(urls) == len(vehicles)
    specs: dict[int, RelaySpec] = {}
    for k, url in enumerate(urls):
        endpoint = udp_endpoint_of_url(url)
        if endpoint is None:
            _log.warning(
                "%s is flown directly: the relay (flight log, ground station) takes UDP and TCP "
                "client URLs only",
                url,
            )
            continue
        specs[k] = RelaySpec(
            endpoint,
            gcs=gcs,
            gcs_index=vehicles[k] if one_each else k,
            system_ids=frozenset({vehicles[k] + 1}) if one_each else frozenset(),
            name=f"relay {url}",
        )
    return specs


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
    recorder: InputRecorder | None = None,
    clock: Callable[[], float | None] | None = None,
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
        truth=plan.target if scored_against_truth(plan, builtin) else None,
        sources=observation_sources(plan, replay),
        external_observations=cfg.observations.external_topic
        if cfg.observations.source == "external"
        else None,
        on_snapshot=on_snapshot,
        name=name,
        recorder=recorder,
        clock=clock,
    )


def scored_against_truth(plan: MissionPlan, builtin: bool) -> bool:
    """Whether the run's figures are scored against the plan's target path (the built-in
    simulator flies it, or the ground simulates the observations), else about the estimate."""
    return builtin or plan.config.observations.source == "simulated"


def recording_inputs(
    plan: MissionPlan, out_dir: Path, builtin: bool, role: str = "mission"
) -> ObservationLog:
    """The run folder's ``config.json`` (the resolved mission file; by the whole mission or the
    ground) and the recorder (to enter) of what ``standoff replay`` re-runs: ``role`` is
    ``mission`` (``observations.jsonl``), ``ground`` or ``agent-<N>`` (each its own file)."""
    agent = role.startswith("agent")
    if not agent:
        write_run_config(out_dir, plan.config)
    truth = scored_against_truth(plan, builtin) and not agent
    return ObservationLog(out_dir / observations_file(role), plan.count, truth=truth, role=role)


def vehicle_agent(
    plan: MissionPlan,
    vehicle: int,
    link: VehicleLink,
    bus: Bus,
    events: EventSink,
    builtin: bool,
    recorder: InputRecorder | None = None,
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
            control_period_s=control_period_s(cfg.link.control_rate_hz),
        ),
        recorder=recorder,
    )


def control_period_s(rate_hz: float) -> float:
    """The agents' control period for ``[link] control_rate_hz`` (0: every frame)."""
    return 1.0 / rate_hz if rate_hz > 0.0 else 0.0


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
        "allocations_ignored": main.allocations_ignored,
    }


@dataclass(frozen=True, slots=True)
class CpuMeter:
    """The CPU this process and its finished child processes (the simulator, each vehicle's
    mavsdk_server) have used since ``start``: the whole app's share of the machine."""

    process_s: float
    children_s: float

    @classmethod
    def start(cls) -> "CpuMeter":
        return cls(time.process_time(), _children_cpu_s())

    def block(
        self, wall_s: float, rate: float, vehicles: int, agents_cpu_s: float
    ) -> dict[str, Any]:
        """The ``cpu`` block of the summary: seconds used, and per vehicle the share of one
        core at 1x real time (``rate``: vehicle seconds per wall second, the speed-up)."""
        process = time.process_time() - self.process_s
        children = _children_cpu_s() - self.children_s
        vehicle_s = wall_s * rate * max(vehicles, 1)

        def share(cpu_s: float) -> float | None:
            return cpu_s / vehicle_s if vehicle_s > 0.0 else None

        return {
            "process_s": process,
            "children_s": children,
            "agents_s": agents_cpu_s,
            "speedup": rate,
            "per_vehicle_at_1x": {
                "agents": share(agents_cpu_s),
                "process": share(process),
                "with_children": share(process + children),
            },
        }


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def write_outputs(
    plan: MissionPlan,
    out_dir: Path,
    ground: GroundStation | None,
    eventlog: EventLog,
    links: Mapping[int, VehicleLink],
    wall_s: float,
    interrupted: bool,
    agents: Sequence[VehicleAgent] = (),
    *,
    run: Mapping[str, Any] | None = None,
    remote: Mapping[int, Mapping[str, Any]] | None = None,
    cpu: Mapping[str, Any] | None = None,
) -> MissionResult:
    """The run folder (``write_run_folder``) from what the ground recorded and the parts
    counted. ``run``: how the run was made (``app.report.provenance.run_block``); ``remote``:
    per vehicle, the ``link`` and ``agent`` counters of agents in other processes (their
    ``agent-N.json``), merged in beside this process's own; ``cpu``: ``CpuMeter.block``.
    Vehicles are keyed from 1."""
    remote = remote or {}
    link_counters = {i: c for i, link in links.items() if (c := counters_of(link)) is not None}
    agent_counters = {a.params.vehicle: dataclasses.asdict(a.counters) for a in agents}
    for i, blocks in remote.items():
        if isinstance(blocks.get("link"), dict):
            link_counters.setdefault(i, blocks["link"])
        if isinstance(blocks.get("agent"), dict):
            agent_counters.setdefault(i, blocks["agent"])
    samples = ground.samples if ground is not None else []
    mission_t = ground.state.mission_t_s if ground is not None else math.nan
    summary = write_run_folder(
        out_dir,
        samples,
        radius_m=plan.config.radius_m,
        tracking_command_s=plan.config.tracking_command_s,
        radius_tolerance_m=plan.ground.stages.radius_tolerance_m,
        spacing_tolerance_rad=plan.ground.stages.spacing_tolerance_rad,
        outages=[(o.start_t_s, o.end_t_s, o.reason) for o in ground.outages]
        if ground is not None
        else (),
        extra={
            "run": dict(run) if run is not None else None,
            "mission": plan.config.name,
            "vehicles": plan.count,
            "end_t_s": plan.end_t_s,
            "mission_t_s": mission_t if math.isfinite(mission_t) else None,
            "wall_s": wall_s,
            "cpu": dict(cpu) if cpu is not None else None,
            "interrupted": interrupted,
            "events": dict(eventlog.counts),
            "links": {vehicle_key(i): c for i, c in sorted(link_counters.items())},
            "agents": {vehicle_key(i): c for i, c in sorted(agent_counters.items())},
            "fusion": _fusion_counters(ground),
            "ground": ground.report() if ground is not None else None,
            "phase_actuators": {
                vehicle_key(a.params.vehicle): a.actuator for a in agents if a.actuator is not None
            },
            "vehicle_altitudes_m": {
                vehicle_key(i): plan.config.link.vehicle_altitude_m(i) for i in range(plan.count)
            },
        },
    )
    return MissionResult(out_dir, summary, samples, interrupted)
