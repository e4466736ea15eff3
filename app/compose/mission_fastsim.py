"""The live mission's logic in one deterministic loop: no MAVLink, no bus, no clock.

``run_mission_sim`` flies the team of a ``MissionPlan`` (``app.config.plan.build_plan``) on
the eq. (2) fixed-wing of ``app.core.plant`` around the plan's scripted target, and pumps the
core's mission state machine (``app.core.mission.agent.step``, ``app.core.mission.ground.step``)
and carries each outbox to where the bus would, in an order a little kinder than the live
mission's: over MAVLink an agent steers on the fused estimate of the tick before, and a camera
fix's local estimate reaches the ground after the tick of its instant (in the live order the
same mission flies 1-4 % worse: docs/mission.md, "Every tick over MAVLink"):

- every camera period, each vehicle's seeded noisy camera (sigma^2 per axis, as the built-in
  simulator's) -> ``Observed`` (its local IMM-UKF); the local estimate when due -> the ground's
  ``HeardLocal`` (through the live mission's bus conversions, ``app.runtime.wire``, both ways);
- every control period: each vehicle's ``Telemetry`` -> its status -> the ground's
  ``HeardStatuses`` (one tick: active team, fusion, stage, the recorded sample); the fused
  estimate and the mission state when due -> every agent; the statuses -> teammates' fixes;
  then ``Control`` -> the (course, speed) command, applied to the vehicle after
  ``latency_ticks`` control periods plus ``latency_s`` (rounded to physics steps) late (0: at
  once, as the live loop nearly does; 1: one tick late) and held until the next one acts.

The plan's ``[sim.wind]`` blows as the built-in simulator blows it (steady plus first-order
Gauss-Markov gusts per axis, one field for the whole team, seeded by ``seed``); in it the
vehicles hold the commanded ground course as NPFG does (``fly_team``'s wind), telemetry is
ground course and speed plus airspeed, and a command's airspeed (the wind estimate's) is flown
where it carries one, else its speed as the airspeed (what the autopilots do).

Figures come from ``app.report.summary.summarize`` on the same ``TeamSample``s the ground
station records (errors against the true target), so they read like a live run's
``summary.json``. It puts together a plan (config), the core, the runtime's stepping loop
(``app.runtime.fastsim.fly_team``) and the report's summary, so it lives with the composition.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from app.config.plan import MissionPlan, team_starts
from app.core.agent import AgentParams, OwnTelemetry
from app.core.estimation.messages import GlobalEstimate, LocalEstimate, Observation
from app.core.frames import wrap_pi
from app.core.mission import agent as logic
from app.core.mission import ground as ground_logic
from app.core.mission.team import TeamSample
from app.core.plant import FixedWingState, VehicleEnvelope
from app.report.summary import summarize
from app.runtime import wire
from app.runtime.fastsim import Commands, fly_team
from app.runtime.ports import topics


@dataclass(frozen=True, slots=True)
class MissionSimSetup:
    """A plan and the timing of the loop (s). ``seed`` seeds the cameras; ``camera_sigma2_m2``
    is the per-axis noise variance; ``end_t_s`` defaults to the plan's end. With
    ``autopilot_wind`` the telemetry carries the wind blowing (as the built-in simulator's PX4
    and ArduPlane report it, WIND_COV / WIND), else the agents fit their own. With
    ``truth_fed`` the agents steer on the true target (position and velocity, exact, every tick)
    instead of their estimates: what guidance and phase keeping do with perfect knowledge of
    the target (the estimators, the fusion and the stages still run as usual). ``truth_of``
    ("position" or "velocity") gives them only that part true, the other their own estimate's;
    ``truth_lag_s`` gives them the true velocity of that many seconds before: what knowing
    each part costs, and how fresh the velocity has to be to be worth having."""

    plan: MissionPlan
    seed: int = 1
    physics_dt_s: float = 0.02
    control_period_s: float = 0.1
    camera_period_s: float = 0.1
    camera_sigma2_m2: float = 10.0
    estimate_period_s: float = 0.2
    mission_period_s: float = 0.5
    latency_ticks: int = 0
    latency_s: float = 0.0
    autopilot_wind: bool = True
    end_t_s: float | None = None
    track_override: tuple[AgentParams, ...] | None = None
    vehicle_limits: VehicleEnvelope | None = None
    truth_fed: bool = False
    truth_of: Literal["all", "position", "velocity"] = "all"
    truth_lag_s: float = 0.0

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
        if not (math.isfinite(self.latency_s) and self.latency_s >= 0.0):
            raise ValueError("latency_s must be finite and >= 0")
        if not (math.isfinite(self.camera_sigma2_m2) and self.camera_sigma2_m2 >= 0.0):
            raise ValueError("camera_sigma2_m2 must be finite and >= 0")
        if self.truth_of not in ("all", "position", "velocity"):
            raise ValueError(f"truth_of must be all, position or velocity, got {self.truth_of!r}")
        if not (math.isfinite(self.truth_lag_s) and self.truth_lag_s >= 0.0):
            raise ValueError("truth_lag_s must be finite and >= 0")


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


def _report(status: logic.AgentStatus) -> ground_logic.VehicleReport:
    """What the ground station keeps of an agent's status."""
    s = status
    return ground_logic.VehicleReport(
        s.t_s, s.east_m, s.north_m, s.course_rad, s.speed_m_s, healthy=s.healthy
    )


def _fix(status: logic.AgentStatus) -> logic.TeammateFix:
    """What a teammate keeps of an agent's status."""
    s = status
    return logic.TeammateFix(s.t_s, s.east_m, s.north_m, s.course_rad, s.speed_m_s)


def _bus_local(estimate: LocalEstimate, vehicle: int) -> LocalEstimate:
    """What the ground station receives over the bus: the live mission's own conversion."""
    return wire.local_to_core(wire.local_to_bus(estimate, vehicle, topics.agent(vehicle)))


def _bus_global(estimate: GlobalEstimate) -> GlobalEstimate:
    """What an agent receives over the bus: the live mission's own conversion."""
    return wire.global_to_core(wire.global_to_bus(estimate, "ground"))


def _truth_steered(
    setup: "MissionSimSetup",
    t_s: float,
    path: Any,
    state: logic.MissionAgentState,
    params: logic.MissionAgentParams,
) -> GlobalEstimate | None:
    """What a ``truth_fed`` agent steers on at ``t_s``, as a fused estimate with no uncertainty
    to speak of: the true target's position and velocity (the velocity of ``truth_lag_s``
    earlier), or with ``truth_of`` one of them true and the other the agent's own estimate
    (None while it has none: it steers as it would)."""
    now = path.state_at(t_s)
    then = path.state_at(max(0.0, t_s - setup.truth_lag_s)) if setup.truth_lag_s > 0.0 else now
    east, north, v_east, v_north = now.east_m, now.north_m, then.v_east_m_s, then.v_north_m_s
    if setup.truth_of != "all":
        known = logic.target_at(state, t_s, params)
        if known is None:
            return None
        if setup.truth_of == "velocity":
            east, north = known.east_m, known.north_m
        else:
            v_east, v_north = known.v_east_m_s, known.v_north_m_s
    x = np.array([east, v_east, north, v_north, 0.0, 0.0], dtype=np.float64)
    return GlobalEstimate(t_s, x, np.eye(6) * 1e-6, ())


class _Gusts:
    """The plan's wind, one physics step at a time (the built-in simulator's process)."""

    def __init__(self, plan: MissionPlan, seed: int, dt_s: float) -> None:
        model = plan.config.sim.wind
        toward = math.radians(model.toward_deg)
        self.steady = (model.speed_m_s * math.sin(toward), model.speed_m_s * math.cos(toward))
        self.blows = model.speed_m_s > 0.0 or model.gust_sigma_m_s > 0.0
        self._decay = math.exp(-dt_s / model.gust_tau_s)
        self._spread = model.gust_sigma_m_s * math.sqrt(1.0 - self._decay**2)
        self._rng = np.random.default_rng([seed, 1_000_003])
        self._gust = (0.0, 0.0)
        self.now = self.steady

    def __call__(self, step_index: int) -> tuple[float, float]:
        """The wind blowing during physics step ``step_index`` (called once per step, in order)."""
        if self._spread > 0.0:
            draws = self._rng.standard_normal(2)
            self._gust = (
                self._decay * self._gust[0] + self._spread * float(draws[0]),
                self._decay * self._gust[1] + self._spread * float(draws[1]),
            )
        self.now = (self.steady[0] + self._gust[0], self.steady[1] + self._gust[1])
        return self.now


def _own(v: FixedWingState, wind: tuple[float, float] | None, reported: bool) -> OwnTelemetry:
    """The vehicle's telemetry: its state in still air; in wind (``v`` air-relative) its ground
    course and speed, with the airspeed, and the wind itself where ``reported``."""
    if wind is None:
        return OwnTelemetry(v.east_m, v.north_m, v.course_rad, v.speed_m_s)
    g_e, g_n = v.v_east_m_s + wind[0], v.v_north_m_s + wind[1]
    course, speed = math.atan2(g_e, g_n), math.hypot(g_e, g_n)
    return OwnTelemetry(v.east_m, v.north_m, course, speed, v.speed_m_s, wind if reported else None)


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

    # statuses and the ground's tick at every control tick; estimates and the mission state on
    # the schedule the live mission keeps (both in the core's states)
    states = [logic.initial_agent_state(a, setup.estimate_period_s, 0.0) for a in agents]
    gstate = ground_logic.initial_ground_state(0.0, setup.mission_period_s)
    gparams = plan.ground
    samples: list[TeamSample] = []
    commands: list[tuple[float, int, float, float, float]] = []
    events: list[tuple[float, str, str]] = []
    path = plan.target
    gusts = _Gusts(plan, setup.seed, dt)
    blowing = gusts if gusts.blows else None
    truth = setup.truth_fed

    def control(t: float, vehicles: Sequence[FixedWingState]) -> Commands:
        """Statuses -> ground; its tick (fusion, stage, sample) -> agents; teammates' fixes;
        then each agent's command."""
        nonlocal gstate
        wind = gusts.now if blowing else None
        owns = [_own(v, wind, setup.autopilot_wind) for v in vehicles]
        statuses: list[tuple[int, logic.AgentStatus]] = []
        for i, own in enumerate(owns):
            states[i], out = logic.step(states[i], logic.Telemetry(t, own), agents[i])
            if out.status is not None:
                statuses.append((i, out.status))
        heard = ground_logic.HeardStatuses(tuple((i, _report(s)) for i, s in statuses))
        gstate, gout = ground_logic.step(gstate, heard, gparams, path)
        events.extend((e.t_s, e.kind, e.detail) for e in gout.events)
        if gout.sample is not None:
            samples.append(gout.sample)
        inputs: list[logic.AgentInput] = []
        if gout.fused is not None:
            inputs.append(logic.HeardFused(_bus_global(gout.fused)))
        if gout.mission is not None:
            inputs.append(logic.HeardMission(gout.mission.stage, gout.mission.active, t))
        for i in range(n):
            fixes = logic.HeardTeammates(tuple((j, _fix(s)) for j, s in statuses if j != i))
            for event in (*inputs, fixes):
                states[i], _ = logic.step(states[i], event, agents[i])
        out_commands = []
        for i, own in enumerate(owns):
            heard_fused = states[i].fused
            steered = _truth_steered(setup, t, path, states[i], agents[i]) if truth else None
            if steered is not None:
                states[i] = replace(states[i], fused=steered)
            states[i], out = logic.step(states[i], logic.Control(t, own), agents[i])
            if steered is not None:  # what the ground sent stays the agent's fused estimate
                states[i] = replace(states[i], fused=heard_fused)
            events.extend((e.t_s, e.kind, f"vehicle {i + 1}: {e.detail}") for e in out.events)
            command = out.command
            if command is None:  # a holding agent: the vehicle keeps its course and speed
                held_speed = own.speed_m_s if own.airspeed_m_s is None else own.airspeed_m_s
                out_commands.append((own.course_rad, held_speed))
            elif blowing is not None and command.airspeed_m_s is not None:
                out_commands.append((command.course_rad, command.airspeed_m_s))
            else:
                out_commands.append((command.course_rad, command.speed_m_s))
        return out_commands

    def applied(sent_t: float, held: Commands, vehicles: Sequence[FixedWingState]) -> None:
        for i, ((course, speed), v) in enumerate(zip(held, vehicles, strict=True)):
            # the course rate it asks of the vehicle it now acts on
            rate = k_gain * wrap_pi(course - v.course_rad)
            commands.append((sent_t, i, course, speed, rate))

    def stepped(step_index: int, vehicles: Sequence[FixedWingState]) -> None:
        """The cameras, every camera period; the local estimates when due -> ground."""
        nonlocal gstate
        if step_index % per_camera:
            return
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
            states[i], out = logic.step(states[i], logic.Observed(obs), agents[i])
            if out.estimate is not None:
                local = ground_logic.HeardLocal(_bus_local(out.estimate, i))
                gstate, _ = ground_logic.step(gstate, local, gparams)

    fly_team(
        team_starts(plan),
        limits,
        dt,
        per_tick,
        ticks,
        control,
        latency_ticks=setup.latency_ticks,
        latency_steps=round(setup.latency_s / dt),
        applied=applied,
        stepped=stepped,
        wind=blowing,
    )
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
