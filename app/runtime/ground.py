"""The ground station loop: the bus around the pure ground logic, plus observation sources.

A thin pump around the core's ``app.core.mission.ground.step``: statuses and local estimates from
the bus go in; a status that moves mission time (the vehicles' own) past the next tick runs one
tick, whose outbox comes out here: the fused estimate (published), the mission state (published
as ``MissionState`` when due), the recorded ``TeamSample`` and the live view; then the
observation sources that are due. The loop ends once mission time reaches ``end_t_s``.
"""

import asyncio
import dataclasses
import logging
import math
import random
import time
from collections.abc import Awaitable, Callable, Mapping, Sequence
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


class MissionSilent(Exception):
    """Raised inside the station's task group to end a mission whose vehicles all went
    silent (``GroundRuntimeParams.silent_end_s``)."""


@dataclass(frozen=True, slots=True)
class GroundRuntimeParams:
    """``silent_end_s``: once every vehicle has been silent (no status taken) for this long,
    host seconds, the mission ends (``end_reason`` says so) and the run folder is written;
    ``outage_after_s``: a silence this long is an outage, marked in the summary and the track
    file (``outages``); ``watch_period_s``: how often the silence is looked at."""

    end_t_s: float
    tick_period_s: float = 0.1
    mission_period_s: float = 0.5
    silent_end_s: float = 30.0
    outage_after_s: float = 2.0
    watch_period_s: float = 0.5


@dataclass
class GroundCounters:
    """What the station refused or failed on, one message or one tick at a time."""

    statuses_refused: int = 0  # stamped outside the window of its clock
    local_estimates_refused: int = 0  # outside it, of the wrong shape, or outliers
    message_errors: int = 0  # messages whose handling failed (logged, skipped)
    outages: int = 0  # periods with no vehicle status for ``outage_after_s`` (listed in report)


@dataclass
class Outage:
    """A period with no vehicle status (mission time; ``end_t_s`` None while it lasts)."""

    start_t_s: float
    end_t_s: float | None
    reason: str


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
        clock: Callable[[], float | None] | None = None,
        monotonic: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
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
        self._clock = clock  # the station's own mission clock (None: none)
        self._monotonic = monotonic
        self._sleep = sleep
        self._counters = GroundCounters()
        self._faults: dict[str, int] = {}
        self._last_heard: float | None = None  # host time of the last status taken
        self.outages: list[Outage] = []
        self.end_reason = ""

    @property
    def counters(self) -> GroundCounters:
        c = self._counters
        c.statuses_refused = self.state.statuses_refused
        c.local_estimates_refused = self.state.locals_refused
        c.outages = len(self.outages)
        return c

    def report(self) -> dict[str, object]:
        """The station's counters, why the mission ended and its outages (for the summary)."""
        stats = getattr(self._bus, "stats", None)
        drops = getattr(self._bus, "drops", None)
        return {
            **dataclasses.asdict(self.counters),
            "end_reason": self.end_reason,
            "outages": [dataclasses.asdict(o) for o in self.outages],
            # what its bus client dropped before the station saw it (malformed, refused ...)
            "bus": dataclasses.asdict(stats)
            if dataclasses.is_dataclass(stats) and not isinstance(stats, type)
            else None,
            "bus_drops": dict(drops) if isinstance(drops, Mapping) else None,
        }

    def _now(self) -> float | None:
        if self._clock is None:
            return None
        t = self._clock()
        return t if t is not None and math.isfinite(t) else None

    async def run(self) -> None:
        try:
            async with (
                self._bus.subscribe(topics.ALL_STATUS) as statuses,
                self._bus.subscribe(topics.ALL_LOCAL_ESTIMATES) as locals_,
                asyncio.TaskGroup() as tg,
            ):
                tg.create_task(self._hear(statuses), name="ground-statuses")
                tg.create_task(self._hear(locals_), name="ground-local-estimates")
                tg.create_task(self._watch_silence(), name="ground-silence")
                if self._external is not None:
                    tg.create_task(self._relay_external(self._external), name="ground-external")
        except* MissionComplete:
            self.end_reason = "mission complete"
            self._events.emit("mission_complete", self.state.mission_t_s)
        except* MissionSilent:
            self._events.emit(
                "mission_ended", self._mission_t(), reason=self.end_reason, detail=self.end_reason
            )
        for outage in self.outages:
            if outage.end_t_s is None:
                outage.end_t_s = self._mission_t()

    def _mission_t(self) -> float:
        t = self.state.mission_t_s
        return t if math.isfinite(t) else 0.0

    async def _watch_silence(self) -> None:
        """Outages (no vehicle status for ``outage_after_s``) and the end of a mission whose
        vehicles all went silent (``silent_end_s``), by the host's clock: a station that hears
        nothing has no mission time to go by."""
        rt = self.runtime
        while True:
            await self._sleep(rt.watch_period_s)
            if self._last_heard is None:
                continue  # nothing heard yet: the vehicles are still coming
            silent = self._monotonic() - self._last_heard
            open_ = self.outages[-1] if self.outages and self.outages[-1].end_t_s is None else None
            if silent > rt.outage_after_s and open_ is None:
                connected = getattr(self._bus, "connected", True)
                reason = "no vehicle status" + ("" if connected else " (bus down)")
                self.outages.append(Outage(self._mission_t(), None, reason))
                self._events.emit("outage", self._mission_t(), reason=reason)
            if silent > rt.silent_end_s:
                self.end_reason = (
                    f"every vehicle silent for {silent:.0f} s (limit {rt.silent_end_s:g} s)"
                )
                log.error("ground: %s: the mission ends", self.end_reason)
                raise MissionSilent

    async def _hear(self, subscription: Subscription) -> None:
        async for _topic, message in subscription:
            try:
                await self._heard(message)
            except MissionComplete:
                raise
            except Exception as exc:  # one bad message never ends the station: counted
                self._counters.message_errors += 1
                self._fault("message_failed", exc)

    def _fault(self, kind: str, error: object) -> None:
        """An error or a refusal: a log line and an event at its 1st, 2nd, 5th, 10th, ...
        occurrence (a flood must not flood the log)."""
        n = self._faults[kind] = self._faults.get(kind, 0) + 1
        if not _log_spaced(n):
            return
        detail = f"{type(error).__name__}: {error}" if isinstance(error, BaseException) else error
        log.warning("ground: %s (%d so far): %s", kind, n, detail)
        self._events.emit(kind, self._mission_t(), count=n, repeat=n > 1, detail=str(detail)[:300])

    def _heard_status(self, vehicle: int, t_s: float) -> None:
        self._last_heard = self._monotonic()
        if self.outages and self.outages[-1].end_t_s is None:
            self.outages[-1].end_t_s = t_s
            self._events.emit("outage_over", t_s, vehicle=vehicle)

    async def _heard(self, message: bus.Message) -> None:
        match message:
            case bus.VehicleStatus():
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
                    up_m=message.up_m,
                )
                now = self._now()
                if self._recorder is not None:
                    self._recorder.status(message.vehicle, report, now)
                heard = logic.HeardStatuses(((message.vehicle, report),), now)
                self.state, out = logic.step(self.state, heard, self.params, self._truth)
                if out.refused:
                    self._fault("status_refused", f"{message.sender}: t_s {message.t_s!r}")
                    return
                self._heard_status(message.vehicle, message.t_s)
                self._note_control(message)
                if out.tick_t_s is not None:
                    await self._carry(out.tick_t_s, out)
            case bus.LocalEstimate():
                local = logic.HeardLocal(local_to_core(message), self._now())
                if self._recorder is not None:
                    self._recorder.local(message.vehicle, message.t_s, local.clock_t_s)
                self.state, out = logic.step(self.state, local, self.params)
                if out.refused:
                    self._fault("local_estimate_refused", f"{message.sender} at {message.t_s!r}")
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
                detail=f"vehicle {v + 1} is flown by its pilot ({message.flight_mode}): out of the "
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
                        # relayed under the ground's name: only the ground and the vehicle's
                        # own agent may speak on its observation topic (topics.refusal)
                        relayed = message.model_copy(update={"sender": self.name})
                        await self._bus.publish(topics.observation(message.vehicle), relayed)
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


def _log_spaced(count: int) -> bool:
    """1, 2, 5, 10, 20, 50, ...: which occurrences of a repeating fault are logged."""
    if count < 1:
        return False
    while count % 10 == 0:
        count //= 10
    return count in (1, 2, 5)
