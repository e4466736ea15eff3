"""The ground station loop: the bus around the pure ground logic, plus observation sources.

Mission time is the vehicles' own time (``app.core.ground``): each status that moves it past the
next tick runs one tick: the active team, the fused estimate (published), the stage (published
as ``MissionState``), the observation sources that are due, a recorded ``TeamSample`` and the
live view. The loop ends once mission time reaches ``end_t_s``.
"""

import asyncio
import logging
import math
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from app.adapters.live_view import MissionSnapshot, VehicleRow
from app.core import ground as logic
from app.core.estimation.models import MotionModel
from app.report.summary import TeamSample, VehicleSample
from app.runtime.ports import messages as bus
from app.runtime.ports import topics
from app.runtime.ports.bus import Bus, Subscription
from app.runtime.ports.events import EventSink
from app.runtime.wire import global_to_bus, local_to_core
from sitl.target import TargetPath

log = logging.getLogger(__name__)


class MissionComplete(Exception):
    """Raised inside the station's task group to end it when mission time reaches the end."""


@dataclass(frozen=True, slots=True)
class Measurement:
    """A target observation for one vehicle at mission time ``t_s`` (from a source)."""

    t_s: float
    vehicle: int
    east_m: float
    north_m: float
    sigma_m: float


class SimulatedSensor:
    """Observations of the scripted target for vehicles without a camera (e.g. SITL autopilots):
    the true position plus Gaussian noise of ``sigma_m`` per axis, ``rate_hz`` per vehicle."""

    def __init__(self, path: TargetPath, sigma_m: float, rate_hz: float, seed: int) -> None:
        if not (sigma_m > 0.0 and rate_hz > 0.0):
            raise ValueError("sigma_m and rate_hz must be > 0")
        self._path = path
        self._sigma = sigma_m
        self._period = 1.0 / rate_hz
        self._rng = random.Random(seed)
        self._next: dict[int, float] = {}

    def due(self, t_s: float, vehicles: Sequence[int]) -> list[Measurement]:
        out = []
        for v in vehicles:
            if t_s >= self._next.get(v, -math.inf):
                self._next[v] = t_s + self._period
                truth = self._path.state_at(t_s)
                out.append(
                    Measurement(
                        t_s,
                        v,
                        truth.east_m + self._rng.gauss(0.0, self._sigma),
                        truth.north_m + self._rng.gauss(0.0, self._sigma),
                        self._sigma,
                    )
                )
        return out


class ReplaySource:
    """A measurements file played back on mission time; ``sensor`` names the vehicle index."""

    def __init__(self, rows: Sequence[Measurement]) -> None:
        self._rows = sorted(rows, key=lambda m: m.t_s)
        self._i = 0

    def due(self, t_s: float, vehicles: Sequence[int]) -> list[Measurement]:
        out = []
        while self._i < len(self._rows) and self._rows[self._i].t_s <= t_s:
            out.append(self._rows[self._i])
            self._i += 1
        return out


TickSource = SimulatedSensor | ReplaySource


@dataclass(frozen=True, slots=True)
class GroundRuntimeParams:
    end_t_s: float
    tick_period_s: float = 0.1
    mission_period_s: float = 0.5


class GroundStation:
    """Runs until mission time reaches ``end_t_s`` (then ``run`` returns) or it is cancelled."""

    def __init__(
        self,
        params: logic.GroundParams,
        runtime: GroundRuntimeParams,
        bus_client: Bus,
        events: EventSink,
        *,
        truth: TargetPath | None = None,
        sources: Sequence[TickSource] = (),
        external_observations: str | None = None,
        on_snapshot: Callable[[MissionSnapshot], None] | None = None,
        name: str = "ground",
    ) -> None:
        self.params = params
        self.runtime = runtime
        self.state = logic.GroundState()
        self.samples: list[TeamSample] = []
        self.name = name
        self._bus = bus_client
        self._events = events
        self._truth = truth
        self._sources = list(sources)
        self._external = external_observations
        self._on_snapshot = on_snapshot
        self._next_tick_t = -math.inf
        self._next_mission_t = -math.inf
        self._last_stage = ""
        self._cv = MotionModel("cv", 0.05)

    async def run(self) -> None:
        try:
            async with (
                self._bus.subscribe(topics.ALL_STATUS) as statuses,
                self._bus.subscribe(topics.ALL_LOCAL_ESTIMATES) as locals_,
                asyncio.TaskGroup() as tg,
            ):
                tg.create_task(self._hear(statuses), name="ground-statuses")
                tg.create_task(self._hear(locals_), name="ground-local-estimates")
                if self._external is not None:
                    tg.create_task(self._relay_external(self._external), name="ground-external")
        except* MissionComplete:
            self._events.emit("mission_complete", self.state.mission_t_s)

    async def _hear(self, subscription: Subscription) -> None:
        async for _topic, message in subscription:
            match message:
                case bus.VehicleStatus():
                    report = logic.VehicleReport(
                        message.t_s,
                        message.east_m,
                        message.north_m,
                        message.course_rad,
                        message.speed_m_s,
                        link_ok=message.link == "ok",
                        healthy=message.healthy,
                    )
                    self.state = logic.hear_status(self.state, message.vehicle, report)
                    if self.state.mission_t_s >= self._next_tick_t:
                        await self._tick()
                case bus.LocalEstimate():
                    self.state = logic.hear_local(self.state, local_to_core(message))
                case _:
                    pass

    async def _relay_external(self, topic_filter: str) -> None:
        """Observations published on another topic (an external tracker) go to their vehicle."""
        async with self._bus.subscribe(topic_filter) as external:
            async for _topic, message in external:
                if isinstance(message, bus.TargetObservation) and message.vehicle is not None:
                    if message.vehicle in self.params.vehicles:
                        await self._bus.publish(topics.observation(message.vehicle), message)
                    else:
                        self._events.emit(
                            "observation_dropped",
                            message.t_s,
                            reason=f"unknown vehicle {message.vehicle}",
                        )

    async def _tick(self) -> None:
        t = self.state.mission_t_s
        self._next_tick_t = t + self.runtime.tick_period_s
        self.state, fused, events = logic.tick(self.state, self.params)
        for event in events:
            self._events.emit(event.kind, event.t_s, detail=event.detail)
        if fused is not None:
            await self._bus.publish(topics.GLOBAL_ESTIMATE, global_to_bus(fused, self.name))
        stage = self.state.stage.stage.value
        if stage != self._last_stage or t >= self._next_mission_t:
            self._last_stage = stage
            self._next_mission_t = t + self.runtime.mission_period_s
            mission = bus.MissionState(
                sender=self.name,
                t_s=t,
                stage=stage,
                active=self.state.active,
                spacing_rad=logic.desired_spacing_rad(self.state),
            )
            await self._bus.publish(topics.MISSION, mission)
        for source in self._sources:
            for m in source.due(t, self.state.active):
                await self._bus.publish(
                    topics.observation(m.vehicle),
                    bus.TargetObservation(
                        sender=self.name,
                        t_s=m.t_s,
                        sensor=f"ground-{m.vehicle}",
                        vehicle=m.vehicle,
                        east_m=m.east_m,
                        north_m=m.north_m,
                        sigma_m=m.sigma_m,
                    ),
                )
        sample = self._sample(t)
        if sample is not None:
            self.samples.append(sample)
            if self._on_snapshot is not None:
                self._on_snapshot(self._snapshot(sample))
        if t >= self.runtime.end_t_s:
            raise MissionComplete

    def _estimate_at(self, t: float) -> tuple[float, float, float, float] | None:
        fused = self.state.fused
        if fused is None:
            return None
        x = self._cv.transition(t - fused.t_s) @ fused.x
        return float(x[0]), float(x[2]), float(x[1]), float(x[3])

    def _sample(self, t: float) -> TeamSample | None:
        estimate = self._estimate_at(t)
        if self._truth is not None:
            truth = self._truth.state_at(t)
            segment = self._truth.segment_at(t)
            target = (truth.east_m, truth.north_m, truth.v_east_m_s, truth.v_north_m_s)
        elif estimate is not None:
            # no truth: the orbit is scored about the estimate, which has nothing to be scored
            # against itself (an estimation error here would read 0)
            segment, target, estimate = "estimated", estimate, None
        else:
            return None
        vehicles = []
        active = set(self.state.active)
        for v, r in self.state.reports:
            dt = t - r.t_s
            vehicles.append(
                VehicleSample(
                    v,
                    v in active,
                    r.east_m + r.speed_m_s * math.sin(r.course_rad) * dt,
                    r.north_m + r.speed_m_s * math.cos(r.course_rad) * dt,
                    r.speed_m_s,
                    r.course_rad,
                )
            )
        return TeamSample(
            t, self.state.stage.stage.value, segment, *target, estimate, tuple(vehicles)
        )

    def _snapshot(self, sample: TeamSample) -> MissionSnapshot:
        dist = sample.distance_errors(self.params.radius_m)
        spacing = sample.spacing_errors()
        reports = dict(self.state.reports)
        rows = tuple(
            VehicleRow(
                v.vehicle,
                dist.get(v.vehicle, math.nan),
                math.degrees(spacing.get(v.vehicle, math.nan)),
                v.speed_m_s,
                "ok" if reports[v.vehicle].link_ok else "lost",
                v.active,
            )
            for v in sample.vehicles
        )
        return MissionSnapshot(
            sample.t_s, self.runtime.end_t_s, sample.stage, sample.target_segment, rows
        )
