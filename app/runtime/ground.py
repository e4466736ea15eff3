"""The ground station loop: the bus around the pure ground logic, plus observation sources.

A thin pump around the core's ``app.core.mission.ground.step``: statuses and local estimates from
the bus go in; a status that moves mission time (the vehicles' own) past the next tick runs one
tick, whose outbox comes out here: the fused estimate (published), the mission state (published
as ``MissionState`` when due), the recorded ``TeamSample`` and the live view; then the
observation sources that are due. The loop ends once mission time reaches ``end_t_s``.
"""

import asyncio
import logging
import math
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from app.core.mission import ground as logic
from app.core.mission.team import TeamSample
from app.core.target import TargetMotion
from app.runtime.ports import messages as bus
from app.runtime.ports import topics
from app.runtime.ports.bus import Bus, Subscription
from app.runtime.ports.events import EventSink
from app.runtime.ports.record import InputRecorder
from app.runtime.ports.view import MissionSnapshot, VehicleRow
from app.runtime.wire import global_to_bus, local_to_core

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

    def __init__(self, path: TargetMotion, sigma_m: float, rate_hz: float, seed: int) -> None:
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


def _link_label(link_ok: bool, piloted: bool) -> str:
    """The live view's link column: a vehicle its pilot flies is heard, not lost."""
    if not link_ok:
        return "lost"
    return "pilot" if piloted else "ok"


class GroundStation:
    """Runs until mission time reaches ``end_t_s`` (then ``run`` returns) or it is cancelled."""

    def __init__(
        self,
        params: logic.GroundParams,
        runtime: GroundRuntimeParams,
        bus_client: Bus,
        events: EventSink,
        *,
        truth: TargetMotion | None = None,
        sources: Sequence[TickSource] = (),
        external_observations: str | None = None,
        on_snapshot: Callable[[MissionSnapshot], None] | None = None,
        name: str = "ground",
        recorder: InputRecorder | None = None,
    ) -> None:
        self.params = params
        self.runtime = runtime
        self.state = logic.initial_ground_state(runtime.tick_period_s, runtime.mission_period_s)
        self.samples: list[TeamSample] = []
        self.name = name
        self._bus = bus_client
        self._events = events
        self._truth = truth
        self._sources = list(sources)
        self._external = external_observations
        self._on_snapshot = on_snapshot
        self._piloted: set[int] = set()
        self._recorder = recorder  # what the fusion and the stages are fed (``standoff replay``)

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
                    self._note_control(message)
                    report = logic.VehicleReport(
                        message.t_s,
                        message.east_m,
                        message.north_m,
                        message.course_rad,
                        message.speed_m_s,
                        link_ok=message.link == "ok",
                        # flown by its pilot: heard (not lost), but out of the formation until
                        # its agent is told to resume
                        healthy=message.healthy and message.control != "pilot",
                    )
                    if self._recorder is not None:
                        self._recorder.status(message.vehicle, report)
                    heard = logic.HeardStatuses(((message.vehicle, report),))
                    self.state, out = logic.step(self.state, heard, self.params, self._truth)
                    if out.tick_t_s is not None:
                        await self._carry(out.tick_t_s, out)
                case bus.LocalEstimate():
                    local = logic.HeardLocal(local_to_core(message))
                    if self._recorder is not None:
                        self._recorder.local(message.vehicle, message.t_s)
                    self.state, _ = logic.step(self.state, local, self.params)
                case _:
                    pass

    def _note_control(self, message: bus.VehicleStatus) -> None:
        """An event when a vehicle's pilot takes it (or the mission takes it back)."""
        v, piloted = message.vehicle, message.control == "pilot"
        if piloted == (v in self._piloted):
            return
        if piloted:
            self._piloted.add(v)
            self._events.emit(
                "vehicle_with_pilot",
                message.t_s,
                vehicle=v,
                flight_mode=message.flight_mode,
                detail=f"vehicle {v} is flown by its pilot ({message.flight_mode}): out of the "
                "formation, not lost",
            )
        else:
            self._piloted.discard(v)
            self._events.emit("vehicle_back_from_pilot", message.t_s, vehicle=v)

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

    async def _carry(self, t: float, out: logic.GroundOutbox) -> None:
        """Send and record what the station's tick at mission time ``t`` put in its outbox,
        then the observation sources that are due."""
        for event in out.events:
            self._events.emit(event.kind, event.t_s, detail=event.detail)
        if out.fused is not None:
            await self._bus.publish(topics.GLOBAL_ESTIMATE, global_to_bus(out.fused, self.name))
        if (update := out.mission) is not None:
            mission = bus.MissionState(
                sender=self.name,
                t_s=update.t_s,
                stage=update.stage,
                active=update.active,
                spacing_rad=update.spacing_rad,
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
        if out.sample is not None:
            self.samples.append(out.sample)
            if self._on_snapshot is not None:
                self._on_snapshot(self._snapshot(out.sample))
        if t >= self.runtime.end_t_s:
            raise MissionComplete

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
                _link_label(reports[v.vehicle].link_ok, v.vehicle in self._piloted),
                v.active,
            )
            for v in sample.vehicles
        )
        return MissionSnapshot(
            sample.t_s, self.runtime.end_t_s, sample.stage, sample.target_segment, rows
        )
