"""The live mission's logic in one deterministic loop: no MAVLink, no bus, no clock.

``run_mission_sim`` flies the team of a ``MissionPlan`` (``app.config.plan.build_plan``) on
the eq. (2) fixed-wing of ``sitl.fixedwing`` around the plan's scripted target, and drives, in
the order the live mission does, the same pure functions:

- every camera period, each vehicle's seeded noisy camera (sigma^2 per axis, as the built-in
  simulator's) -> ``mission_agent.observe`` (its local IMM-UKF);
- every ``estimate_period_s`` each agent's local estimate -> ``ground.hear_local`` (through the
  live mission's bus conversions, ``app.runtime.wire``, both ways);
- every control period: each vehicle's status -> ``ground.hear_status``; ``ground.tick`` (active
  team, fusion, stage); the fused estimate -> ``mission_agent.hear_fused``; the stage ->
  ``hear_mission``; teammates' fixes -> ``hear_teammate``; then ``mission_agent.control`` -> the
  (course, speed) command, applied to the vehicle after ``latency_ticks`` control periods
  (0: at once, as the live loop nearly does; 1: one tick late) and held between ticks.

Figures come from ``app.report.summary.summarize`` on the same ``TeamSample``s the ground
station records (errors against the true target), so they read like a live run's
``summary.json``.
"""

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from app.config.plan import MissionPlan, team_starts
from app.core import ground as ground_logic
from app.core import mission_agent as logic
from app.core.agent import AgentParams, OwnTelemetry
from app.core.estimation.messages import GlobalEstimate, LocalEstimate, Observation
from app.report.summary import TeamSample, VehicleSample, summarize
from app.runtime import wire
from sitl.fixedwing import FixedWingLimits, step


@dataclass(frozen=True, slots=True)
class MissionSimSetup:
    """A plan and the timing of the loop (s). ``seed`` seeds the cameras; ``camera_sigma2_m2``
    is the per-axis noise variance; ``end_t_s`` defaults to the plan's end. With
    ``truth_fed`` the agents steer on the true target (position and velocity, exact, every tick)
    instead of their estimates: what guidance and phase keeping do with perfect knowledge of
    the target (the estimators, the fusion and the stages still run as usual)."""

    plan: MissionPlan
    seed: int = 1
    physics_dt_s: float = 0.02
    control_period_s: float = 0.1
    camera_period_s: float = 0.1
    camera_sigma2_m2: float = 10.0
    estimate_period_s: float = 0.2
    mission_period_s: float = 0.5
    latency_ticks: int = 0
    end_t_s: float | None = None
    track_override: tuple[AgentParams, ...] | None = None
    vehicle_limits: FixedWingLimits | None = None
    truth_fed: bool = False

    def __post_init__(self) -> None:
        for name in (
            "physics_dt_s",
            "control_period_s",
            "camera_period_s",
            "estimate_period_s",
            "mission_period_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if self.control_period_s < self.physics_dt_s - 1e-12:
            raise ValueError("control_period_s must be at least physics_dt_s")
        if self.latency_ticks < 0:
            raise ValueError("latency_ticks must be >= 0")
        if not (math.isfinite(self.camera_sigma2_m2) and self.camera_sigma2_m2 >= 0.0):
            raise ValueError("camera_sigma2_m2 must be finite and >= 0")


@dataclass
class MissionSimResult:
    """The ground's samples (every control tick), every command sent (t, vehicle, course,
    speed, implied course rate k * wrap(course cmd - course) against the course the vehicle has
    when the command starts to act), and the run's summary."""

    samples: list[TeamSample]
    commands: np.ndarray
    summary: dict[str, Any]
    events: list[tuple[float, str, str]] = field(default_factory=list)

    def part(self, key: str) -> dict[str, Any] | None:
        value = self.summary["parts"].get(key)
        return None if value is None else value["team"]


def _wrap_pi(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _bus_local(estimate: LocalEstimate, vehicle: int) -> LocalEstimate:
    """What the ground station receives over the bus: the live mission's own conversion."""
    return wire.local_to_core(wire.local_to_bus(estimate, vehicle, f"agent-{vehicle}"))


def _bus_global(estimate: GlobalEstimate) -> GlobalEstimate:
    """What an agent receives over the bus: the live mission's own conversion."""
    return wire.global_to_core(wire.global_to_bus(estimate, "ground"))


def _truth_estimate(t_s: float, truth: Any) -> GlobalEstimate:
    """The true target as a fused estimate (no uncertainty to speak of): what ``truth_fed``
    agents steer on."""
    x = np.array(
        [truth.east_m, truth.v_east_m_s, truth.north_m, truth.v_north_m_s, 0.0, 0.0],
        dtype=np.float64,
    )
    return GlobalEstimate(t_s, x, np.eye(6) * 1e-6, ())


def run_mission_sim(setup: MissionSimSetup) -> MissionSimResult:
    """Fly the plan to its end (see the module docstring); deterministic for a given setup."""
    plan = setup.plan
    cfg = plan.config
    n = plan.count
    agents = list(plan.agents)
    if setup.track_override is not None:
        if len(setup.track_override) != n:
            raise ValueError("track_override needs one AgentParams per vehicle")
        agents = [replace(a, track=t) for a, t in zip(agents, setup.track_override, strict=True)]
    limits = setup.vehicle_limits or cfg.limits.build()
    k_gain = limits.course_gain_per_s
    end_t = plan.end_t_s if setup.end_t_s is None else setup.end_t_s
    dt = setup.physics_dt_s
    per_tick = max(1, round(setup.control_period_s / dt))
    per_camera = max(1, round(setup.camera_period_s / dt))
    ticks = math.floor(end_t / (per_tick * dt) + 1e-9)
    sigma = math.sqrt(setup.camera_sigma2_m2)
    rngs = [np.random.default_rng([setup.seed, i]) for i in range(n)]

    vehicles = team_starts(plan)
    states = [logic.initial_agent_state(a) for a in agents]
    gstate = ground_logic.GroundState()
    gparams = plan.ground
    next_estimate_t = [-math.inf] * n
    next_mission_t = -math.inf
    last_stage = ""
    pending: deque[tuple[float, list[tuple[float, float]]]] = deque()
    held = [(v.course_rad, v.speed_m_s) for v in vehicles]
    samples: list[TeamSample] = []
    commands: list[tuple[float, int, float, float, float]] = []
    events: list[tuple[float, str, str]] = []
    path = plan.target

    step_index = 0
    for tick in range(ticks + 1):
        t = tick * per_tick * dt
        # 1. statuses -> ground; ground tick; fused estimate and mission state -> agents
        for i, v in enumerate(vehicles):
            report = ground_logic.VehicleReport(t, v.east_m, v.north_m, v.course_rad, v.speed_m_s)
            gstate = ground_logic.hear_status(gstate, i, report)
        gstate, fused, gevents = ground_logic.tick(gstate, gparams)
        events.extend((e.t_s, e.kind, e.detail) for e in gevents)
        if fused is not None:
            wire = _bus_global(fused)
            states = [logic.hear_fused(s, wire, a) for s, a in zip(states, agents, strict=True)]
        stage = gstate.stage.stage.value
        if stage != last_stage or t >= next_mission_t:
            last_stage = stage
            next_mission_t = t + setup.mission_period_s
            states = [logic.hear_mission(s, stage, gstate.active) for s in states]
        # 2. teammates' fixes
        for i in range(n):
            for j, v in enumerate(vehicles):
                if j != i:
                    fix = logic.TeammateFix(t, v.east_m, v.north_m, v.course_rad, v.speed_m_s)
                    states[i] = logic.hear_teammate(states[i], j, fix)
        # 3. sample (before the commands of this tick act)
        truth = path.state_at(t)
        estimate = None
        if gstate.fused is not None:
            fx = gstate.fused
            f = plan.agents[0].prediction_model.transition(t - fx.t_s) @ fx.x
            estimate = (float(f[0]), float(f[2]), float(f[1]), float(f[3]))
        samples.append(
            TeamSample(
                t,
                stage,
                path.segment_at(t),
                truth.east_m,
                truth.north_m,
                truth.v_east_m_s,
                truth.v_north_m_s,
                estimate,
                tuple(
                    VehicleSample(
                        i, i in gstate.active, v.east_m, v.north_m, v.speed_m_s, v.course_rad
                    )
                    for i, v in enumerate(vehicles)
                ),
            )
        )
        # 4. control
        if setup.truth_fed:
            exact = _truth_estimate(t, truth)
            states = [replace(s, fused=exact) for s in states]
        out = []
        for i, v in enumerate(vehicles):
            own = OwnTelemetry(v.east_m, v.north_m, v.course_rad, v.speed_m_s)
            states[i], command, aevents = logic.control(states[i], t, own, agents[i])
            events.extend((e.t_s, e.kind, f"vehicle {i}: {e.detail}") for e in aevents)
            out.append((command.course_rad, command.speed_m_s))
        pending.append((t, out))
        if len(pending) > setup.latency_ticks:
            sent_t, held = pending.popleft()
            for i, ((course, speed), v) in enumerate(zip(held, vehicles, strict=True)):
                # the course rate it asks of the vehicle it now acts on
                rate = k_gain * _wrap_pi(course - v.course_rad)
                commands.append((sent_t, i, course, speed, rate))
        if tick == ticks:
            break
        # 5. fly to the next tick; cameras and local estimates on the way
        for _ in range(per_tick):
            vehicles = [step(v, c, s, limits, dt) for v, (c, s) in zip(vehicles, held, strict=True)]
            step_index += 1
            if step_index % per_camera:
                continue
            ts = step_index * dt
            target = path.state_at(ts)
            for i in range(n):
                draws = rngs[i].standard_normal(2)
                obs = Observation(
                    ts,
                    agents[i].sensor,
                    target.east_m + sigma * float(draws[0]),
                    target.north_m + sigma * float(draws[1]),
                    sigma if sigma > 0.0 else None,
                )
                states[i], step_report = logic.observe(states[i], obs, agents[i])
                if step_report.used and ts >= next_estimate_t[i]:
                    local = states[i].local.estimate()
                    if local is not None:
                        next_estimate_t[i] = ts + setup.estimate_period_s
                        gstate = ground_logic.hear_local(gstate, _bus_local(local, i))
    summary = summarize(
        samples,
        cfg.radius_m,
        cfg.tracking_command_s,
        gparams.stages.radius_tolerance_m,
        gparams.stages.spacing_tolerance_rad,
    )
    return MissionSimResult(samples, np.asarray(commands, dtype=np.float64), summary, events)


def track_figures(result: MissionSimResult, labels: Sequence[str]) -> dict[str, dict[str, float]]:
    """Per track segment: RMS and max |distance error| (m), RMS and max |spacing error| (deg),
    and when the team got back onto the circle (``settle_s`` from the segment's start) with the
    RMS distance error from then on (``settled_dist_rms_m``)."""
    out: dict[str, dict[str, float]] = {}
    for label in labels:
        team = result.part(f"track:{label}")
        if team is None or "distance_error_m" not in team:
            continue
        row = {
            "dist_rms_m": team["distance_error_m"]["rms"],
            "dist_max_m": team["distance_error_m"]["max_abs"],
        }
        if "spacing_error_deg" in team:
            row["spacing_rms_deg"] = team["spacing_error_deg"]["rms"]
            row["spacing_max_deg"] = team["spacing_error_deg"]["max_abs"]
        if team.get("time_to_circle_s") is not None:
            row["settle_s"] = team["time_to_circle_s"]
            row["settled_dist_rms_m"] = team["settled"]["distance_error_m"]["rms"]
        out[label] = row
    return out
