"""The mission fast simulation against the async run on one seed, on a virtual clock.

Both fly ``configs/test-short.toml`` (seed 1) on the same eq. (2) plant from the same starts,
with the same seeded cameras (sigma^2 = 10 m^2 per axis, one observation per vehicle every
0.1 s at the times the fast simulation takes them), and both pump the core's one mission state
machine (``app.core.mission``). The async run is the live code path with its I/O swapped for
tests' own: the ``VehicleAgent`` and ``GroundStation`` loops of ``app.runtime`` over the
in-process bus (its codec and topics included), each agent on a queue-fed vehicle link
(``tests/support/fake_link.py``). The test is the clock: it steps the plant, hands each agent its
camera's observations and then its telemetry frame, and lets the loops run until they are idle
before it takes the commands they sent. No sockets, no wall clock, no sleeping.

The two runs differ in one thing only, the order of the exchange within a control tick. The
fast simulation hears every status, ticks the ground station, delivers the fused estimate and
the mission state, and then steers; the async loops steer on the frame as soon as it arrives
and publish the status after, so an agent steers on the fused estimate and the stage of the
previous tick (0.1 s older), and the ground station ticks on the first status of a tick with
the others one tick old (dead-reckoned). Tolerances, from that one-tick lag (measured on seed 1:
stage times 0.2 s apart, convergence times 0.4 s, RMS figures 0.07-0.24 m and 0.06-0.33 deg;
each tolerance is about three times that: room for the lag's noise, little for a drift between
the two drivers):

- stage times within 0.5 s (5 ticks), the convergence times (on the circle, spaced, in
  formation) within 1.0 s: a stage change waits on a threshold that the team's distance or
  spacing crosses at a rate set by the vehicles' speed and turn rate, and a 0.1 s lag in the
  loop moves each crossing by a few ticks;
- per part of the run, the RMS distance error within 0.5 m + 15 % and the RMS spacing error
  within 1 deg + 10 % of the fast simulation's: the lag perturbs a closed loop, which settles
  on its own, so the figures agree to their noise, not to the digit (the digits are the fast
  simulation's own determinism, ``test_mission_fastsim``, and ``bench_track``).

The run's ~112 s of mission time take ~15 s of CPU (the fast simulation ~4 s of it).
"""

from __future__ import annotations

import asyncio
import math
from contextlib import AsyncExitStack
from typing import Any

import numpy as np
import pytest

from app.adapters.bus import InProcessBroker, InProcessBus
from app.compose.mission_fastsim import MissionSimSetup, run_mission_sim
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import MissionPlan, build_plan, team_starts
from app.core.mission.team import TeamSample
from app.core.plant import FixedWingState
from app.report.summary import summarize
from app.runtime.agent import AgentRuntimeParams, VehicleAgent
from app.runtime.fastsim import fly_team
from app.runtime.ground import GroundRuntimeParams, GroundStation
from app.runtime.ports.vehicle import CourseSpeedCommand, TargetObservation, VehicleTelemetry
from tests.support.fake_link import QueueLink, frame

SEED = 1
STAGE_TIME_TOLERANCE_S = 0.5
CONVERGENCE_TOLERANCE_S = 1.0
DIST_RMS_TOLERANCE = (0.5, 0.15)  # m, share
SPACING_RMS_TOLERANCE = (1.0, 0.10)  # deg, share
IDLE_YIELDS = 40  # event-loop turns without progress after which the loops are idle


class CommandLink(QueueLink):
    """A queue-fed link that keeps the last command sent."""

    def __init__(self, vehicle_id: int) -> None:
        super().__init__()
        self.vehicle_id = vehicle_id
        self.command: CourseSpeedCommand | None = None

    async def send(self, command: CourseSpeedCommand) -> None:
        await super().send(command)
        self.command = command


class Stages:
    """An event sink that keeps the stage changes: (t, stage)."""

    def __init__(self) -> None:
        self.changes: list[tuple[float, str]] = []

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        if kind == "stage":
            self.changes.append((t_s, str(fields["detail"])))


def _telemetry(vehicle: int, t_s: float, v: FixedWingState) -> VehicleTelemetry:
    return frame(
        t_s,
        v.east_m,
        v.north_m,
        vehicle_id=vehicle + 1,
        course_rad=v.course_rad,
        ground_speed_m_s=v.speed_m_s,
        v_east_m_s=v.speed_m_s * math.sin(v.course_rad),
        v_north_m_s=v.speed_m_s * math.cos(v.course_rad),
    )


class Silent:
    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        pass


async def _idle() -> None:
    """Let every loop run until nothing more happens: a fixed number of event-loop turns (the
    in-process bus and the loops only ever wait on each other, each hop one turn or two)."""
    for _ in range(IDLE_YIELDS):
        await asyncio.sleep(0)


async def _async_run(
    plan: MissionPlan, setup: MissionSimSetup
) -> tuple[list[TeamSample], list[tuple[float, str]]]:
    """The async run on the test's clock: the ground station's samples and stage changes."""
    limits = plan.config.limits.build()
    dt = setup.physics_dt_s
    per_tick = round(setup.control_period_s / dt)
    per_camera = round(setup.camera_period_s / dt)
    assert per_camera == per_tick  # one observation per vehicle per tick: never a backlog
    ticks = math.floor(plan.end_t_s / (per_tick * dt) + 1e-9)
    sigma = math.sqrt(setup.camera_sigma2_m2)
    rngs = [np.random.default_rng([setup.seed, i]) for i in range(plan.count)]
    vehicles = team_starts(plan)
    links = [CommandLink(i + 1) for i in range(plan.count)]
    stages = Stages()
    # one status and one ground tick per telemetry frame, as the fast simulation has them
    runtime = AgentRuntimeParams(status_period_s=0.05, estimate_period_s=setup.estimate_period_s)
    broker = InProcessBroker()
    async with AsyncExitStack() as stack:
        ground_bus = await stack.enter_async_context(InProcessBus(broker, client_id="ground"))
        buses = [
            await stack.enter_async_context(InProcessBus(broker, client_id=f"agent-{i + 1}"))
            for i in range(plan.count)
        ]
        tg = await stack.enter_async_context(asyncio.TaskGroup())
        station = GroundStation(
            plan.ground,
            GroundRuntimeParams(plan.end_t_s, 0.05, setup.mission_period_s),
            ground_bus,
            stages,
            truth=plan.target,
        )
        ground = tg.create_task(station.run(), name="ground")
        agents = [
            tg.create_task(
                VehicleAgent(plan.agents[i], link, bus, Silent(), runtime).run(),
                name=f"agent-{i + 1}",
            )
            for i, (link, bus) in enumerate(zip(links, buses, strict=True))
        ]
        await _idle()
        held = [(v.course_rad, v.speed_m_s) for v in vehicles]
        for tick in range(ticks + 1):
            t = tick * per_tick * dt
            for i, (link, v) in enumerate(zip(links, vehicles, strict=True)):
                link.put(_telemetry(i, t, v))
            await _idle()
            held = [
                (c.course_rad, c.speed_m_s) if (c := link.command) is not None else held[i]
                for i, link in enumerate(links)
            ]
            if tick == ticks:
                break

            def cameras(index: int, _team: object, base: int = tick * per_tick) -> None:
                """The cameras of the fast simulation, at its step times."""
                if (base + index) % per_camera:
                    return
                ts = (base + index) * dt
                target = plan.target.state_at(ts)
                for i, link in enumerate(links):
                    draws = rngs[i].standard_normal(2)
                    east = target.east_m + sigma * float(draws[0])
                    north = target.north_m + sigma * float(draws[1])
                    link.seen.put_nowait(TargetObservation(i + 1, ts, 0, 0, 0, east, north, sigma))

            # one tick of the plant on the commands sent (the fast simulation's own loop)
            def sent(_t: float, _team: object, commands: list[tuple[float, float]] = held) -> Any:
                return commands

            vehicles = fly_team(vehicles, limits, dt, per_tick, 1, sent, stepped=cameras)
            await _idle()  # the tick's observations (one per vehicle: see the camera period)
        for task in (ground, *agents):  # the last tick is the fast simulation's last one
            task.cancel()
    return station.samples, stages.changes


def _team(summary: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {key: part["team"] for key, part in summary["parts"].items()}


def _close(fast: float, slow: float, tolerance: tuple[float, float]) -> bool:
    absolute, share = tolerance
    return abs(slow - fast) <= absolute + share * abs(fast)


@pytest.mark.slow
def test_the_fast_simulation_and_the_async_run_agree_on_one_seed() -> None:
    plan = build_plan(load_config("test-short", MissionConfig))
    setup = MissionSimSetup(plan, seed=SEED)
    fast = run_mission_sim(setup)
    samples, changes = asyncio.run(_async_run(plan, setup))
    fast_changes = [(t, detail) for t, kind, detail in fast.events if kind == "stage"]
    assert [s for _, s in changes] == [s for _, s in fast_changes] == ["gather", "adjust", "track"]
    for (t_async, stage), (t_fast, _) in zip(changes, fast_changes, strict=True):
        assert t_async == pytest.approx(t_fast, abs=STAGE_TIME_TOLERANCE_S), stage
    cfg, stages = plan.config, plan.ground.stages
    summary = summarize(
        samples,
        cfg.radius_m,
        cfg.tracking_command_s,
        stages.radius_tolerance_m,
        stages.spacing_tolerance_rad,
    )
    for key in ("time_to_circle_s", "time_to_spacing_s", "time_to_formation_s"):
        t_fast, t_async = fast.summary["convergence"][key], summary["convergence"][key]
        assert t_fast is not None
        assert t_async == pytest.approx(t_fast, abs=CONVERGENCE_TOLERANCE_S), key
    fast_parts, async_parts = _team(fast.summary), _team(summary)
    assert set(async_parts) == set(fast_parts)
    for key in ("adjust", "track:A-B"):
        f, a = fast_parts[key], async_parts[key]
        dist_f, dist_a = f["distance_error_m"]["rms"], a["distance_error_m"]["rms"]
        assert _close(dist_f, dist_a, DIST_RMS_TOLERANCE), (key, dist_f, dist_a)
        spacing_f, spacing_a = f["spacing_error_deg"]["rms"], a["spacing_error_deg"]["rms"]
        assert _close(spacing_f, spacing_a, SPACING_RMS_TOLERANCE), (key, spacing_f, spacing_a)
