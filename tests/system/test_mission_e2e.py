"""End-to-end missions: the built-in simulator over real UDP MAVLink, MAVSDK links, the in-process
bus, the ground station and three agents, with faults injected while they fly.

Every scenario flies ``configs/test-short.toml`` (the hil team and limits; the target waits 60 s,
drives 120 m north at 3 m/s and stops) at a 3x speed-up on free ports, with the simulator in
this event loop (given to the ``Mission``) so that the test's hooks can reach it; the hooks run
beside the mission, on its mission time, over its public parts. Each scenario runs once per
module and several tests read its results:

- the full mission, with garbage injected on the bus on the way: the run folder, the figures,
  and every setpoint the simulator received;
- two faults, one after the other, in one longer mission (the target drives on to its end):
  a vehicle's radio cut mid-track and restored (it leaves, the other two re-space to 180
  degrees, it rejoins), then, once the three have formed again, every camera stopped (the fused
  estimate is predicted on and the team orbits it);
- Ctrl-C (the mission task cancelled): every vehicle in hold, the logs closed, the summary marked.
"""

import asyncio
import functools
import itertools
import json
import math
import os
import random
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import pytest_asyncio
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from app.adapters.bus import InProcessBus, encode
from app.cli.fly import report as fly_report
from app.compose.mission import Mission
from app.compose.parts import MissionResult
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import MissionPlan, build_plan, sim_config
from app.config.schema import WaypointTargetConfig
from app.core.frames import TAU, wrap_pi
from app.core.mission.ground import team_view
from app.core.mission.stage import Stage, spacing_errors
from app.runtime.agent import VehicleAgent
from app.runtime.ground import GroundStation
from app.runtime.ports import topics
from app.runtime.ports.bus import Bus
from app.runtime.ports.messages import MissionState
from sitl.ports import find_free_udp_base_port
from sitl.server import SimTruth, SimulatorServer

pytestmark = [pytest.mark.slow, pytest.mark.asyncio(loop_scope="module")]

CONFIG = "test-short"
SPEEDUP = 3.0  # more than about 3x starves one process on a 2-core machine (offboard failsafe)
WALL_TIMEOUT_S = 180.0  # the full mission is about 40 s of wall time, the fault run 80 s
KILLED = 2  # its index; users (the events, the operator's 'resume N') number it KILLED + 1
# The radio is cut mid-track once the team has formed (between these mission times): how long
# gather and adjust take varies from run to run on a loaded machine.
FAULT_FROM_S = 64.0
FAULT_BY_S = 95.0
RESPACE_S = 52.0  # the phase law needs 25 to 45 s to re-space two (around a 3 m/s target)
# The cameras are stopped once the three have formed again after the rejoin (25-45 s), at the
# latest 30 s before the end (as in a run of its own, stopped by 95 s of 125).
BLIND_BY_S = 200.0
FAULT_RUN_END_S = 230.0
# the target waits 60 s and drives on at 3 m/s to the end (a stop would stir the spacing)
FAULT_RUN_LEG_NORTH_M = 3.0 * (FAULT_RUN_END_S - 60.0)
INTERRUPT_AT_S = 25.0
# Course setpoints are computed on a telemetry frame and reach the simulator later: allow the
# vehicle to have turned at its limit for this long (simulated time) in between.
SETPOINT_LATENCY_S = 0.5
TELEMETRY_SPEED_M_S = 0.02  # speed resolution of GLOBAL_POSITION_INT (1 cm/s per axis)


# --- flying a scenario ------------------------------------------------------------------------


def short_config(end_s: float | None = None, leg_north_m: float | None = None) -> MissionConfig:
    """The short mission at ``SPEEDUP``; optionally ended at ``end_s``, with its one leg north
    ending at ``leg_north_m``."""
    config = load_config(CONFIG, MissionConfig)
    sim = config.sim.model_copy(update={"speedup": SPEEDUP})
    update: dict[str, Any] = {"sim": sim}
    if end_s is not None:
        update["end_s"] = end_s
    if leg_north_m is not None:
        target = config.target
        assert isinstance(target, WaypointTargetConfig)
        leg = target.legs[0].model_copy(update={"to_north_m": leg_north_m})
        update["target"] = target.model_copy(update={"legs": [leg]})
    return config.model_copy(update=update)


@dataclass
class MissionContext:
    """What the hooks reach while a mission flies: its plan, the simulator and its parts."""

    plan: MissionPlan
    sim: SimulatorServer
    mission: Mission

    @property
    def ground(self) -> GroundStation:
        assert self.mission.ground is not None
        return self.mission.ground

    @property
    def agents(self) -> list[VehicleAgent]:
        return self.mission.agents

    @property
    def buses(self) -> list[Bus]:
        return self.mission.buses


Hook = Callable[[MissionContext], None]


async def run_hooks(hooks: Sequence[tuple[float, Hook]], ctx: MissionContext) -> None:
    """Each hook once mission time reaches its time (checked every 20 ms of wall time)."""
    pending = sorted(hooks, key=lambda h: h[0])
    while pending:
        if ctx.mission.ground is not None:
            t = ctx.ground.state.mission_t_s
            while pending and t >= pending[0][0]:
                _, hook = pending.pop(0)
                hook(ctx)
        await asyncio.sleep(0.02)


class OperatorLines:
    """What an operator types at ``standoff fly``, put by a hook."""

    def __init__(self) -> None:
        self._lines: asyncio.Queue[str] = asyncio.Queue()

    def put(self, line: str) -> None:
        self._lines.put_nowait(line)

    async def lines(self) -> AsyncIterator[str]:
        while True:
            yield await self._lines.get()


async def fly(
    out_dir: Path,
    hooks: Sequence[tuple[float, Hook]],
    config: MissionConfig,
    operator: OperatorLines | None = None,
) -> MissionResult:
    plan = build_plan(config)
    sim_config_ = sim_config(plan, find_free_udp_base_port(plan.count))
    async with asyncio.timeout(WALL_TIMEOUT_S), SimulatorServer(sim_config_) as sim:
        mission = Mission(
            plan,
            out_dir,
            simulator=sim,
            operator=operator.lines() if operator is not None else None,
        )
        async with asyncio.TaskGroup() as tg:
            schedule = tg.create_task(run_hooks(hooks, MissionContext(plan, sim, mission)))
            result = await mission.run()
            schedule.cancel()
        return result


@dataclass(frozen=True)
class Snapshot:
    """What the ground, the agents and the simulator held at one hook call."""

    t_s: float
    stage: str
    active: tuple[int, ...]
    agent_stages: tuple[str, ...]
    agent_actives: tuple[tuple[int, ...], ...]
    fused_t_s: float | None
    fused_x: np.ndarray | None
    fused_position_var_m2: float | None
    truth: SimTruth


@dataclass
class Probe:
    """Hooks that keep the simulator at hand and snapshot the mission every ``period_s``."""

    sim: SimulatorServer | None = None
    snapshots: list[Snapshot] = field(default_factory=list)

    def hooks(self, end_s: float, period_s: float = 1.0) -> list[tuple[float, Hook]]:
        return [(k * period_s, self.snap) for k in range(int(end_s / period_s) + 1)]

    def snap(self, ctx: MissionContext) -> None:
        assert ctx.sim is not None
        self.sim = ctx.sim
        g = ctx.ground.state
        fused = g.fused
        self.snapshots.append(
            Snapshot(
                g.mission_t_s,
                g.stage.stage.value,
                g.active,
                tuple(a.state.stage for a in ctx.agents),
                tuple(a.state.active for a in ctx.agents),
                None if fused is None else fused.t_s,
                None if fused is None else np.array(fused.x),
                None if fused is None else float(fused.p[0, 0] + fused.p[2, 2]),
                ctx.sim.truth(),
            )
        )

    def between(self, t0: float, t1: float) -> list[Snapshot]:
        return [s for s in self.snapshots if t0 <= s.t_s <= t1]


@dataclass(frozen=True)
class Received:
    """One SET_POSITION_TARGET_LOCAL_NED as the simulator received it, and the vehicle then."""

    vehicle: int
    t_s: float
    vx: float
    vy: float
    vz: float
    yaw: float
    type_mask: int
    course_rad: float


@dataclass
class SetpointRecorder:
    """Wraps each simulated vehicle's ``handle`` to keep every setpoint it receives."""

    received: list[Received] = field(default_factory=list)

    def install(self, ctx: MissionContext) -> None:
        assert ctx.sim is not None
        for vehicle in ctx.sim.vehicles:
            vehicle.handle = self._wrap(vehicle)  # type: ignore[method-assign]

    def _wrap(self, vehicle: Any) -> Callable[..., Any]:
        handle = vehicle.handle

        def recording(msg: mavlink.MAVLink_message, t_s: float, wall_s: float) -> Any:
            if msg.get_msgId() == mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED:
                self.received.append(
                    Received(
                        vehicle.index,
                        t_s,
                        msg.vx,
                        msg.vy,
                        msg.vz,
                        msg.yaw,
                        msg.type_mask,
                        vehicle.state.course_rad,
                    )
                )
            return handle(msg, t_s, wall_s)

        return recording


def garbage_payloads(rng: random.Random) -> list[bytes]:
    """Random bytes, a truncated message, a message with a non-finite number."""
    valid = encode(
        MissionState(sender="intruder", t_s=1.0, stage="track", active=(0,), spacing_rad=1.0)
    )
    assert b'"t_s":1.0' in valid
    return [rng.randbytes(48), valid[: len(valid) // 2], valid.replace(b'"t_s":1.0', b'"t_s":NaN')]


GARBLED_TOPICS = (topics.MISSION, topics.status(0), topics.GLOBAL_ESTIMATE)


@dataclass
class Garbler:
    """Injects garbage on the mission, status and estimate topics; notes what each client saw."""

    at_s: float
    rng: random.Random = field(default_factory=lambda: random.Random(5))
    buses: list[InProcessBus] = field(default_factory=list)
    malformed_seen: list[int] = field(default_factory=list)
    injected: int = 0

    def inject(self, ctx: MissionContext) -> None:
        self.buses = [b for b in ctx.buses if isinstance(b, InProcessBus)]
        assert len(self.buses) == len(ctx.buses) == 1 + len(ctx.agents)
        before = [b.stats.malformed for b in self.buses]
        for topic in GARBLED_TOPICS:
            for payload in garbage_payloads(self.rng):
                self.buses[0].inject_raw(topic.value, payload)
                self.injected += 1
        self.malformed_seen = [
            b.stats.malformed - n for b, n in zip(self.buses, before, strict=True)
        ]


@dataclass
class WhenFormed:
    """Runs ``action`` once, at the first check (every 0.5 s from ``from_s`` to ``by_s``, once
    ``armed``) that finds the ground in track with the whole team active, near the circle and
    roughly spaced (about the fused estimate)."""

    action: Callable[[MissionContext], None]
    from_s: float = FAULT_FROM_S
    by_s: float = FAULT_BY_S
    armed: Callable[[], bool] = lambda: True
    distance_tolerance_m: float = 10.0
    spacing_tolerance_deg: float = 15.0
    at_s: float | None = None
    snapshot: Snapshot | None = None

    def hooks(self, probe: Probe) -> list[tuple[float, Hook]]:
        n = round((self.by_s - self.from_s) / 0.5)
        return [(self.from_s + 0.5 * k, functools.partial(self.check, probe)) for k in range(n + 1)]

    def check(self, probe: Probe, ctx: MissionContext) -> None:
        g = ctx.ground.state
        if self.at_s is not None or not self.armed():
            return
        if g.stage.stage is not Stage.TRACK or g.active != (0, 1, 2):
            return
        view = team_view(g, ctx.plan.ground)
        if any(abs(e) > self.distance_tolerance_m for e in view.distance_errors_m):
            return
        spacing = [math.degrees(e) for e in spacing_errors(view.polar_angles_rad)]
        if any(abs(e) > self.spacing_tolerance_deg for e in spacing):
            return
        probe.snap(ctx)
        self.snapshot = probe.snapshots[-1]
        self.action(ctx)
        self.at_s = g.mission_t_s


def team_gap_deg(truth: SimTruth, a: int, b: int) -> float:
    """Counter-clockwise angle from vehicle ``a`` to vehicle ``b`` about the true target."""
    te, tn = truth.target.east_m, truth.target.north_m
    angles = [
        math.atan2(truth.vehicles[i].state.north_m - tn, truth.vehicles[i].state.east_m - te)
        for i in (a, b)
    ]
    return math.degrees((angles[1] - angles[0]) % TAU)


def events(out_dir: Path) -> list[dict[str, Any]]:
    lines = (out_dir / "events.jsonl").read_text(encoding="utf-8").splitlines()
    return [json.loads(line) for line in lines]


# --- the scenarios (one run each, shared by the tests below) ------------------------------------


@dataclass
class FullRun:
    result: MissionResult
    probe: Probe
    recorder: SetpointRecorder
    garbler: Garbler


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def full_run(tmp_path_factory: pytest.TempPathFactory) -> FullRun:
    config = short_config()
    probe, recorder, garbler = Probe(), SetpointRecorder(), Garbler(at_s=40.0)
    hooks: list[tuple[float, Hook]] = [(0.0, recorder.install), (garbler.at_s, garbler.inject)]
    hooks += probe.hooks(build_plan(config).end_t_s)
    result = await fly(tmp_path_factory.mktemp("full"), hooks, config)
    return FullRun(result, probe, recorder, garbler)


@dataclass
class FaultRun:
    """The radio of vehicle ``KILLED`` cut and restored, then every camera stopped."""

    result: MissionResult
    probe: Probe
    killed_at_s: float
    revived_at_s: float
    blinded_at_s: float
    at_cut: Snapshot  # when the cameras were stopped


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def fault_run(tmp_path_factory: pytest.TempPathFactory) -> FaultRun:
    probe = Probe()
    revived: list[float] = []
    resumed: list[float] = []
    operator = OperatorLines()

    def kill(ctx: MissionContext) -> None:
        assert ctx.sim is not None
        ctx.sim.set_link(KILLED, False)

    killer = WhenFormed(kill)

    def revive_when_due(ctx: MissionContext) -> None:
        t = ctx.ground.state.mission_t_s
        if killer.at_s is not None and not revived and t >= killer.at_s + RESPACE_S:
            assert ctx.sim is not None
            ctx.sim.set_link(KILLED, True)
            revived.append(t)

    def resume_when_left_alone(ctx: MissionContext) -> None:
        # back on the radio, it is in its failsafe's hold and its agent leaves it there: the
        # operator types 'resume 3' (vehicles numbered from 1)
        if revived and not resumed and ctx.agents[KILLED].pilot_has_control:
            operator.put(f"resume {KILLED + 1}\n")
            resumed.append(ctx.ground.state.mission_t_s)

    def blind(ctx: MissionContext) -> None:
        assert ctx.sim is not None
        for i in range(len(ctx.sim.vehicles)):
            ctx.sim.set_camera(i, False)

    # the team is whole again only once the revived vehicle is back on the circle, spaced
    blinder = WhenFormed(
        blind, from_s=FAULT_FROM_S + RESPACE_S, by_s=BLIND_BY_S, armed=lambda: bool(revived)
    )
    hooks = [*killer.hooks(probe), *blinder.hooks(probe), *probe.hooks(FAULT_RUN_END_S)]
    hooks += [(FAULT_FROM_S + RESPACE_S + 0.5 * k, revive_when_due) for k in range(80)]
    hooks += [(FAULT_FROM_S + RESPACE_S + 0.25 * k, resume_when_left_alone) for k in range(200)]
    config = short_config(FAULT_RUN_END_S, FAULT_RUN_LEG_NORTH_M)
    result = await fly(tmp_path_factory.mktemp("faults"), hooks, config, operator)
    assert killer.at_s is not None, "the team never formed in track: no vehicle was killed"
    assert revived, "the killed vehicle was never revived"
    assert blinder.at_s is not None, "the team never formed again: no camera was stopped"
    assert blinder.snapshot is not None
    return FaultRun(result, probe, killer.at_s, revived[0], blinder.at_s, blinder.snapshot)


# --- the full mission ---------------------------------------------------------------------------


async def test_full_mission_runs_to_its_end(full_run: FullRun) -> None:
    summary = full_run.result.summary
    assert not full_run.result.interrupted
    assert summary["interrupted"] is False
    assert summary["mission_t_s"] >= summary["end_t_s"]
    assert summary["vehicles"] == 3
    assert summary["events"]["mission_complete"] == 1
    assert summary["events"]["vehicle_joined"] == 3
    assert "vehicle_left" not in summary["events"]
    assert all(c["link_losses"] == 0 for c in summary["links"].values())
    # a vehicle that fell out of offboard (its failsafe, when a loaded machine stalls the loop
    # for more than a second of simulated time) was left in its failsafe's mode and reported:
    # the agent takes a vehicle back only on 'resume'
    log = events(full_run.result.out_dir)
    for left in (e for e in log if e["kind"] == "LeftOffboard"):
        assert any(
            e["kind"] == "pilot_took_over" and e["vehicle"] == left["vehicle"] for e in log
        ), left
    assert not any(e["kind"] == "resumed" for e in log)


async def test_full_mission_writes_every_file_of_the_run_folder(full_run: FullRun) -> None:
    out = full_run.result.out_dir
    on_disk = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert on_disk["convergence"] == full_run.result.summary["convergence"]
    for name in ("trajectories.png", "distance_error.png", "phase_difference.png"):
        head = (out / name).read_bytes()[:8]
        assert head == b"\x89PNG\r\n\x1a\n", name
    assert sorted(p.name for p in out.glob("*.tlog")) == [f"vehicle-{i}.tlog" for i in (1, 2, 3)]


async def test_summary_has_convergence_times_and_per_part_figures(full_run: FullRun) -> None:
    summary = full_run.result.summary
    conv = summary["convergence"]
    for key in ("time_to_circle_s", "time_to_spacing_s", "time_to_formation_s"):
        assert conv[key] is not None, key
    # within the 100 s, and not before the team can have flown 310 m to the circle
    assert 15.0 < conv["time_to_circle_s"] <= conv["time_to_formation_s"] <= 100.0
    parts = summary["parts"]
    assert {"gather", "adjust", "track:A-B"} <= set(parts)
    for key in ("gather", "adjust", "track:A-B"):
        team = parts[key]["team"]
        assert set(team) >= {"distance_error_m", "spacing_error_deg", "estimation_rmse"}, key
        assert set(parts[key]["vehicles"]) == {"1", "2", "3"}, key
        for figures in parts[key]["vehicles"].values():
            # measured speeds, as MAVLink carries them (velocities in cm/s)
            speed = figures["speed_m_s"]
            assert 10.0 - TELEMETRY_SPEED_M_S <= speed["min"] <= speed["max"]
            assert speed["max"] <= 18.0 + TELEMETRY_SPEED_M_S
    track = parts["track:A-B"]["team"]
    # a 3 m/s target: the issue asks 3 m and 4 degrees RMS of the full mission; allow for the
    # short run starting its track straight from adjust
    assert track["distance_error_m"]["rms"] <= 6.0
    assert track["spacing_error_deg"]["rms"] <= 6.0
    assert track["estimation_rmse"]["position_m"] <= 3.0
    # the ground's main filter: 3 agents x 5 local estimates a second for ~110 s, and in one
    # process few refused (late, or built on an allocation still on its way: 3.9 % in one
    # full-length mission)
    fusion = summary["fusion"]
    refused = fusion["out_of_order_dropped"] + fusion["stale_basis_dropped"]
    assert fusion["local_estimates_taken"] > 1000
    assert refused < 0.15 * fusion["local_estimates_taken"]


async def test_track_csv_has_a_stage_column_through_gather_adjust_track(full_run: FullRun) -> None:
    lines = (full_run.result.out_dir / "track.csv").read_text(encoding="utf-8").splitlines()
    header = lines[0].split(",")
    assert header[:8] == [
        "t_s",
        "vehicle",
        "east_m",
        "north_m",
        "course_rad",
        "speed_m_s",
        "target_east_m",
        "target_north_m",
    ]
    assert "stage" in header[8:]
    rows = [dict(zip(header, line.split(","), strict=True)) for line in lines[1:]]
    stages = [r["stage"] for r in rows]
    assert {"gather", "adjust", "track"} <= set(stages)
    order = list(dict.fromkeys(stages))
    assert order == [s for s in ("standby", "gather", "adjust", "track") if s in order]
    assert {r["vehicle"] for r in rows} == {"1", "2", "3"}
    assert len(rows) == sum(len(s.vehicles) for s in full_run.result.samples)


async def test_every_tick_sends_its_status_and_the_ground_ticks_on_each_over_mavlink(
    full_run: FullRun,
) -> None:
    # every agent sends a status on each of its control ticks (0.1 s of its vehicle's clock),
    # and the ground station ticks (fuses, samples) in every 0.1 s slot it heard a status in:
    # none skipped for a status a rounding error short of a period after the last (a quarter
    # of them once were, which weighted the manoeuvres' figures). A loaded machine may make an
    # agent skip frames, and then its statuses; it skips their ticks too.
    out = full_run.result.out_dir
    summary = full_run.result.summary
    records = [json.loads(line) for line in (out / "observations.jsonl").read_text().splitlines()]
    statuses = [r for r in records if r["kind"] == "status"]
    for key, agent in summary["agents"].items():
        sent = sum(1 for r in statuses if r["vehicle"] == int(key) - 1)
        assert sent >= 0.98 * agent["ticks"], (key, sent, agent["ticks"])
    flying = [s.t_s for s in full_run.result.samples if s.stage in ("adjust", "track")]
    t0, t1 = flying[0], flying[-1]
    slots = {round((r["t_s"] - t0) / 0.1) for r in statuses if t0 <= r["t_s"] <= t1}
    assert len(flying) >= 0.98 * len(slots), (len(flying), len(slots))
    assert min(b - a for a, b in itertools.pairwise(flying)) > 0.05  # never two in one slot


async def test_every_tlog_reads_in_pymavlink(full_run: FullRun) -> None:
    # the summary numbers vehicles from 1, as the tlogs' names and system ids
    frames = {int(n) - 1: c["frames"] for n, c in full_run.result.summary["links"].items()}
    for i in range(3):
        reader = mavutil.mavlink_connection(str(full_run.result.out_dir / f"vehicle-{i + 1}.tlog"))
        positions = []
        kinds = set()
        while (msg := reader.recv_match()) is not None:
            kinds.add(msg.get_type())
            # the vehicle's traffic and the app's (MAVSDK's system id 245) to it, as it flew
            assert msg.get_srcSystem() in (i + 1, 245)
            if msg.get_type() == "GLOBAL_POSITION_INT":
                positions.append(msg)
        assert {"HEARTBEAT", "GLOBAL_POSITION_INT"} <= kinds
        assert len(positions) >= 0.9 * frames[i]
        times = [p.time_boot_ms for p in positions]
        assert times == sorted(times)
        # the vehicles fly within a few km of the mission origin
        assert all(abs(p.lat / 1e7 - 47.397742) < 0.05 for p in positions)


async def test_event_log_is_json_lines_of_the_mission(full_run: FullRun) -> None:
    kinds = [e["kind"] for e in events(full_run.result.out_dir)]
    assert kinds[0] == "mission_start"
    assert kinds[-1] == "mission_complete"
    assert kinds.count("offboard") == 3
    stages = [e["detail"] for e in events(full_run.result.out_dir) if e["kind"] == "stage"]
    assert stages == ["gather", "adjust", "track"]
    assert "interrupted" not in kinds


async def test_no_setpoint_was_non_finite_or_outside_the_limits(full_run: FullRun) -> None:
    plan = build_plan(short_config())
    lim = plan.config.limits
    links = full_run.result.summary["links"]
    assert set(links) == {"1", "2", "3"}
    for counters in links.values():
        # a setpoint per frame from the hand-over on (the runway take-off and the climb to the
        # hand-over height before it are about a tenth of this short mission's frames)
        assert counters["setpoints"] > 0.8 * counters["frames"] > 0
        assert counters["setpoints_limited"] == 0, counters["limited_by"]
    received = full_run.recorder.received
    sent = sum(c["setpoints"] for c in links.values())
    # MAVSDK resends the newest setpoint too; the first few arrived before the recorder
    assert len(received) >= 0.95 * sent
    tolerance_rad = lim.max_course_rate_rad_s * SETPOINT_LATENCY_S
    for r in received:
        assert all(math.isfinite(v) for v in (r.vx, r.vy, r.vz, r.yaw)), r
        speed = math.hypot(r.vx, r.vy)
        assert lim.min_speed_m_s * (1 - 1e-5) <= speed <= lim.max_speed_m_s * (1 + 1e-5), r
        course = math.atan2(r.vy, r.vx)
        assert abs(wrap_pi(r.yaw - course)) < 1e-3, r
        # the implied course rate k (command - course) within the limit, as sent on a frame
        # up to SETPOINT_LATENCY_S old
        implied = lim.course_gain_per_s * abs(wrap_pi(course - r.course_rad))
        assert implied <= lim.max_course_rate_rad_s + tolerance_rad, r


async def test_garbled_bus_messages_are_counted_and_dropped(full_run: FullRun) -> None:
    garbler = full_run.garbler
    assert garbler.injected == 3 * len(GARBLED_TOPICS)
    # the ground hears statuses; each agent hears the mission, statuses and the fused estimate
    assert garbler.malformed_seen == [3, 9, 9, 9]
    # nothing else was malformed, and the mission went on to its end (test above)
    assert [b.stats.malformed for b in garbler.buses] == [3, 9, 9, 9]
    after = [s for s in full_run.probe.snapshots if s.t_s > garbler.at_s]
    assert after
    assert all(s.active == (0, 1, 2) for s in after)
    assert after[-1].stage == "track"


# --- a vehicle killed mid-track, and back -------------------------------------------------------


async def test_a_killed_vehicle_leaves_and_the_others_respace_to_180(fault_run: FaultRun) -> None:
    kill_at, revive_at = fault_run.killed_at_s, fault_run.revived_at_s
    log = events(fault_run.result.out_dir)
    left = [e for e in log if e["kind"] == "vehicle_left"]
    assert [e["detail"] for e in left] == [f"vehicle {KILLED + 1} left the formation"]
    lost_after_s = build_plan(short_config()).ground.lost_after_s
    assert kill_at < left[0]["t_s"] <= kill_at + lost_after_s + 1.0
    assert any(e["kind"] == "link_lost" and e["vehicle"] == KILLED + 1 for e in log)
    out = fault_run.probe.between(left[0]["t_s"] + 1.0, revive_at)
    assert out
    assert all(s.active == (0, 1) for s in out)
    # the agents heard it: the survivors steer on a team of two
    assert all(s.agent_actives[0] == s.agent_actives[1] == (0, 1) for s in out)
    assert all(s.truth.vehicles[KILLED].mode == "hold" for s in out)  # its own failsafe
    gaps = [(s.t_s, team_gap_deg(s.truth, 0, 1)) for s in out]
    assert abs(gaps[0][1] - 180.0) > 40.0  # they started 120 degrees apart
    settled = [(t, g) for t, g in gaps if t >= revive_at - 6.0]
    assert settled
    assert all(abs(g - 180.0) <= 5.0 for _, g in settled), settled

    # and they kept orbiting the target meanwhile (re-spacing at up to 18 m/s around a 3 m/s
    # target can take one wide of the circle for a while: never off to the standby loiter)
    def distance_m(s: Snapshot, i: int) -> float:
        v, target = s.truth.vehicles[i].state, s.truth.target
        return math.hypot(v.east_m - target.east_m, v.north_m - target.north_m) - 90.0

    assert all(abs(distance_m(s, i)) < 60.0 for s in out for i in (0, 1))
    assert all(abs(distance_m(s, i)) < 10.0 for s in out if s.t_s >= settled[0][0] for i in (0, 1))


async def test_a_killed_vehicle_rejoins_when_its_link_returns(fault_run: FaultRun) -> None:
    log = events(fault_run.result.out_dir)
    revive_at = fault_run.revived_at_s
    joined = [e for e in log if e["kind"] == "vehicle_joined" and e["t_s"] > fault_run.killed_at_s]
    assert [e["detail"] for e in joined] == [f"vehicle {KILLED + 1} is in the formation"]
    assert revive_at <= joined[0]["t_s"] <= revive_at + 5.0
    assert any(e["kind"] == "link_restored" and e["vehicle"] == KILLED + 1 for e in log)
    # it had fallen back to hold: its agent left it there, reported it, and took it back into
    # offboard only on the operator's 'resume'
    [took] = [e for e in log if e["kind"] == "pilot_took_over" and e["vehicle"] == KILLED + 1]
    [typed] = [e for e in log if e["kind"] == "operator_command"]
    [resumed] = [e for e in log if e["kind"] == "resumed" and e["vehicle"] == KILLED + 1]
    assert took["flight_mode"] not in ("OFFBOARD", "")
    assert typed["command"] == "resume"
    assert list(typed["vehicles"]) == [KILLED + 1]
    assert took["t_s"] <= resumed["t_s"] <= joined[0]["t_s"]
    # to just before the end-of-mission hold (the cameras stopped meanwhile)
    back = fault_run.probe.between(joined[0]["t_s"] + 3.0, FAULT_RUN_END_S - 0.5)
    assert back
    assert all(s.active == (0, 1, 2) for s in back)
    assert all(s.truth.vehicles[KILLED].mode == "offboard" for s in back)
    assert all(a == (0, 1, 2) for s in back for a in s.agent_actives)
    summary = fault_run.result.summary
    assert not summary["interrupted"]
    assert summary["events"]["mission_complete"] == 1


# --- observations stopped -----------------------------------------------------------------------


async def test_without_observations_the_estimate_is_predicted_on(fault_run: FaultRun) -> None:
    probe, at_cut, cut_s = fault_run.probe, fault_run.at_cut, fault_run.blinded_at_s
    blind = probe.between(cut_s + 2.0, math.inf)
    assert len(blind) >= 25
    assert all(not v.camera_enabled for s in blind for v in s.truth.vehicles)
    # no camera fix reached a vehicle's filter after the cut (10 Hz from about 2 s)
    links = fault_run.result.summary["links"].values()
    assert all(c["observations"] < 10 * (cut_s + 1.0) for c in links)
    assert at_cut.fused_x is not None
    assert at_cut.fused_position_var_m2 is not None
    v_cut = math.hypot(at_cut.fused_x[1], at_cut.fused_x[3])
    variances = []
    for s in blind:
        # a fresh fused estimate every tick, with a growing covariance
        assert s.fused_t_s is not None
        assert s.t_s - s.fused_t_s <= 0.5
        assert s.fused_x is not None
        assert s.fused_position_var_m2 is not None
        variances.append(s.fused_position_var_m2)
        # carried on at the speed it had (a ground target does not speed up without being seen)
        assert abs(math.hypot(s.fused_x[1], s.fused_x[3]) - v_cut) <= 1.0, s.t_s
    assert all(b >= a for a, b in itertools.pairwise(variances))
    assert variances[-1] > 10.0 * at_cut.fused_position_var_m2
    assert all(s.stage == "track" and s.active == (0, 1, 2) for s in blind)


async def test_without_observations_the_team_orbits_the_predicted_target(
    fault_run: FaultRun,
) -> None:
    cut_s = fault_run.blinded_at_s
    samples = [s for s in fault_run.result.samples if s.t_s >= cut_s + 5.0]
    assert len(samples) >= 200
    errors = []
    for s in samples:
        assert s.estimate is not None
        for v in s.vehicles:
            # around the predicted target, never off to the standby loiter 400 m away (nor
            # after a predicted target that runs away: 110 m off 13 s after the cut, before)
            r = math.hypot(v.east_m - s.estimate[0], v.north_m - s.estimate[1])
            assert abs(r - 90.0) <= 45.0, (s.t_s, v.vehicle, r)
            errors.append(r - 90.0)
    assert math.sqrt(sum(e * e for e in errors) / len(errors)) <= 15.0
    # until just before the end, when every vehicle is put in hold on purpose
    blind = fault_run.probe.between(cut_s + 2.0, FAULT_RUN_END_S - 0.5)
    assert all(stage == "track" for s in blind for stage in s.agent_stages)
    assert all(v.mode == "offboard" for s in blind for v in s.truth.vehicles)


# --- Ctrl-C -------------------------------------------------------------------------------------


def file_sizes(paths: set[str]) -> list[int]:
    return [os.path.getsize(p) for p in paths]


def open_paths() -> set[str]:
    fd_dir = Path("/proc/self/fd")
    out = set()
    for fd in fd_dir.iterdir():
        try:
            out.add(os.readlink(fd))
        except OSError:
            continue
    return out


async def test_ctrl_c_holds_every_vehicle_closes_the_logs_and_marks_the_summary(
    tmp_path: Path,
) -> None:
    """What asyncio.run does on KeyboardInterrupt: cancel the task running the mission."""
    probe = Probe()
    reached = asyncio.Event()

    def interrupt(ctx: MissionContext) -> None:
        probe.snap(ctx)
        reached.set()

    config = short_config()
    task = asyncio.create_task(fly(tmp_path, [(INTERRUPT_AT_S, interrupt)], config), name="mission")
    async with asyncio.timeout(WALL_TIMEOUT_S):
        await reached.wait()
    assert not task.done()
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        async with asyncio.timeout(30.0):
            await task
    sim = probe.sim
    assert sim is not None
    assert probe.snapshots[0].stage == "gather"
    assert all(v.mode == "offboard" for v in probe.snapshots[0].truth.vehicles)
    modes = [v.mode for v in sim.truth().vehicles]
    assert modes == ["hold", "hold", "hold"]
    log = events(tmp_path)
    assert log[-1]["kind"] == "interrupted"
    assert INTERRUPT_AT_S <= log[-1]["t_s"] < INTERRUPT_AT_S + 2.0
    written = {str(tmp_path / "events.jsonl")} | {
        str(tmp_path / f"vehicle-{i}.tlog") for i in (1, 2, 3)
    }
    assert all(size > 0 for size in file_sizes(written))
    assert not written & open_paths()
    summary = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    assert summary["interrupted"] is True
    assert INTERRUPT_AT_S <= summary["mission_t_s"] < summary["end_t_s"]
    assert summary["events"]["interrupted"] == 1
    assert "mission_complete" not in summary["events"]
    assert (tmp_path / "track.csv").exists()


async def test_the_summary_counts_the_cpu_each_agent_and_the_run_took(full_run: FullRun) -> None:
    summary = full_run.result.summary
    agents = summary["agents"]
    assert set(agents) == {"1", "2", "3"}
    for key, agent in agents.items():
        # every agent did work and ran about as long as the run
        assert agent["cpu_s"] > 0.0, key
        assert 0.5 * summary["wall_s"] < agent["wall_s"] <= summary["wall_s"], key
        share = agent["cpu_share_at_1x"]
        rate = summary["run"]["speedup"]
        assert share == pytest.approx(agent["cpu_s"] / (agent["wall_s"] * rate)), key
        assert 0.0 < share < 0.5, key
    cpu = summary["cpu"]
    assert cpu["agents_s"] == pytest.approx(sum(a["cpu_s"] for a in agents.values()))
    # the agents' steps are part of what this process spent; the children add to it
    assert cpu["process_s"] > cpu["agents_s"]
    assert cpu["children_s"] >= 0.0
    per = cpu["per_vehicle_at_1x"]
    assert 0.0 < per["agents"] < per["process"] <= per["with_children"]
    assert per["process"] == pytest.approx(
        cpu["process_s"] / (summary["wall_s"] * cpu["speedup"] * 3)
    )
    line = fly_report(summary)
    assert f"agents' own work {100.0 * per['agents']:.2f} %" in line
    # each agent's course-loop identification, in the summary and the report's line
    loops = {key: agent["course_loop"] for key, agent in agents.items()}
    for key, loop in loops.items():
        assert loop["informative_samples"] > 0, key
        if loop["identified"]:
            assert f"vehicle {key}: k {loop['gain_per_s']:.2f} /s" in line
        else:
            assert f"vehicle {key}: not identified ({loop['informative_s']:.0f} s inf" in line
