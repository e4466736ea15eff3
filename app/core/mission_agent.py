"""One vehicle agent's mission logic, pure: what it hears, what it estimates, what it commands.

The agent's loop (``app.runtime.agent``) only moves values between the vehicle link, the bus and
these functions:

- ``observe``: a target observation into the vehicle's local IMM-UKF (Appendix B).
- ``hear_fused``: the main filter's fused estimate, with the federated information feedback
  (Appendix A) applied to the local filter.
- ``hear_mission`` / ``hear_teammate``: the ground station's stage and active team, and the
  teammates' positions, for phase keeping.
- ``control``: one tick on the vehicle's own telemetry: the target as best known (the fused
  estimate, else the local one, predicted to the tick's time), the active team, and
  ``agent_step`` (guidance + phase keeping) -> a command.

Before the tracking command, or while no estimate of the target exists, the vehicle loiters
around its standby point with the same guidance field (a stationary "target" at the standby
point, no phase keeping). A vehicle that the ground station has left out of the formation keeps
orbiting the target without phase keeping, so it never steers on a stale spacing.
"""

import math
from dataclasses import dataclass, field, replace
from typing import Literal

from app.core.agent import (
    AgentEvent,
    AgentInputs,
    AgentParams,
    AgentState,
    Command,
    OwnTelemetry,
    TargetInfo,
    agent_step,
    predict_own,
)
from app.core.estimation.federated import MainParams, apply_feedback
from app.core.estimation.local import LocalParams, LocalState, StepReport, local_step
from app.core.estimation.messages import GlobalEstimate, Observation
from app.core.estimation.models import MotionModel

StageName = Literal["standby", "gather", "adjust", "track"]
STAGES: tuple[StageName, ...] = ("standby", "gather", "adjust", "track")


@dataclass(frozen=True, slots=True)
class TeammateFix:
    """Where a teammate was at ``t_s`` (m, rad clockwise from north, m/s)."""

    t_s: float
    east_m: float
    north_m: float
    course_rad: float
    speed_m_s: float

    def at(self, t_s: float, max_extrapolation_s: float) -> tuple[float, float]:
        """Position dead-reckoned to ``t_s`` along the last course (at most the given span)."""
        dt = min(max(t_s - self.t_s, 0.0), max_extrapolation_s)
        return (
            self.east_m + self.speed_m_s * math.sin(self.course_rad) * dt,
            self.north_m + self.speed_m_s * math.cos(self.course_rad) * dt,
        )


@dataclass(frozen=True, slots=True)
class MissionAgentParams:
    """One agent's fixed configuration.

    ``agent`` flies the mission (its ``index`` is replaced each tick by the vehicle's place in
    the active team); ``track``, when given, replaces it in the track stage (the mission turns
    the inverse-field switch off there: it serves the approach, and on the circle around a
    moving, estimated target its crossing prediction is dominated by noise), and in adjust as
    soon as the target the agent sees moves faster than ``moving_speed_m_s`` (the ground
    station's own rule for starting to track: an agent that has not heard "track", e.g. cut off
    from the bus, must not keep flying the stationary-target approach around a moving target);
    ``standby`` flies
    the loiter around (``standby_east_m``, ``standby_north_m``). ``main`` carries the federated
    feedback mode; ``None`` turns feedback
    off. Fixes and fused estimates older than ``max_age_s`` are not used; a fused estimate is
    predicted forward with ``prediction_model``; ``use_target_accel`` passes the estimated
    acceleration to the moving-target correction.

    Latency compensation (improvement): ``latency_s`` is the time from a telemetry frame until
    its command starts to act on the vehicle, ``hold_s`` how long a command then acts (the
    control period). The agent steers on where the vehicle and the target will be in the middle
    of that, ``latency_s + hold_s / 2`` after the frame (``agent.predict_own`` under the command
    it last sent), not on where they were (both 0: the paper's loop; a delay of one 0.1 s tick
    costs ~50 % more distance error around a moving target, ``benchmarks.bench_track
    --latency-ticks``).
    """

    vehicle: int
    agent: AgentParams
    standby: AgentParams
    standby_east_m: float
    standby_north_m: float
    local: LocalParams
    main: MainParams | None = None
    track: AgentParams | None = None
    max_age_s: float = 3.0
    prediction_model: MotionModel = field(default_factory=lambda: MotionModel("cv", 0.05))
    use_target_accel: bool = False
    latency_s: float = 0.0
    hold_s: float = 0.0
    moving_speed_m_s: float = 1.5

    def __post_init__(self) -> None:
        if not self.moving_speed_m_s >= 0.0:  # inf: only the track stage flies ``track``
            raise ValueError(f"moving_speed_m_s must be >= 0, got {self.moving_speed_m_s!r}")
        for name in ("latency_s", "hold_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise ValueError(f"{name} must be in [0, 1] s, got {value!r}")
        if not (math.isfinite(self.standby_east_m) and math.isfinite(self.standby_north_m)):
            raise ValueError("standby point must be finite")
        if not (math.isfinite(self.max_age_s) and self.max_age_s > 0.0):
            raise ValueError(f"max_age_s must be finite and > 0, got {self.max_age_s!r}")

    @property
    def sensor(self) -> str:
        """The vehicle's name as a sensor of the federated estimator."""
        return str(self.vehicle)


@dataclass(frozen=True, slots=True)
class MissionAgentState:
    """Everything one agent remembers."""

    local: LocalState
    guidance: AgentState = field(default_factory=AgentState)
    standby_guidance: AgentState = field(default_factory=AgentState)
    fused: GlobalEstimate | None = None
    stage: StageName = "standby"
    active: tuple[int, ...] = ()
    teammates: tuple[tuple[int, TeammateFix], ...] = ()
    holding: bool = False
    #: the (course rad, speed m/s) command of the last tick, for the latency compensation
    last_command: tuple[float, float] | None = None


def initial_agent_state(params: MissionAgentParams) -> MissionAgentState:
    return MissionAgentState(local=LocalState(sensor=params.sensor))


def observe(
    state: MissionAgentState, obs: Observation, params: MissionAgentParams
) -> tuple[MissionAgentState, StepReport]:
    """Feed one observation to the local filter; the report says whether it was used and why not."""
    local, report = local_step(state.local, obs, params.local)
    return replace(state, local=local), report


def hear_fused(
    state: MissionAgentState, fused: GlobalEstimate, params: MissionAgentParams
) -> MissionAgentState:
    """Keep the newest fused estimate and apply the main filter's information allocation."""
    if state.fused is not None and fused.t_s < state.fused.t_s:
        return state
    local = state.local
    if params.main is not None:
        local = apply_feedback(local, fused, params.local, params.main)
    return replace(state, fused=fused, local=local)


def hear_mission(
    state: MissionAgentState, stage: str, active: tuple[int, ...]
) -> MissionAgentState:
    """The ground station's stage and active team (sorted, unique vehicle ids)."""
    if stage not in STAGES:
        raise ValueError(f"unknown stage {stage!r}")
    return replace(state, stage=stage, active=tuple(sorted(set(active))))


def hear_teammate(state: MissionAgentState, vehicle: int, fix: TeammateFix) -> MissionAgentState:
    """A teammate's newest position (older fixes than the one held are ignored)."""
    held = dict(state.teammates)
    old = held.get(vehicle)
    if old is not None and fix.t_s < old.t_s:
        return state
    held[vehicle] = fix
    return replace(state, teammates=tuple(sorted(held.items())))


def set_holding(state: MissionAgentState, holding: bool) -> MissionAgentState:
    return replace(state, holding=holding)


def target_at(
    state: MissionAgentState, t_s: float, params: MissionAgentParams
) -> TargetInfo | None:
    """The target as best known at ``t_s``: the fused estimate if fresh, else the local one,
    predicted to ``t_s`` (at most ``max_age_s`` ahead); None when neither is fresh."""
    candidates = []
    if state.fused is not None:
        candidates.append((state.fused.t_s, state.fused.x))
    local = state.local.estimate()
    if local is not None:
        candidates.append((local.t_s, local.x))
    for t0, x in candidates:
        dt = t_s - t0
        if -params.max_age_s <= dt <= params.max_age_s:
            f = params.prediction_model.transition(dt)
            e, ve, n, vn, ae, an = (float(v) for v in f @ x)
            if not params.use_target_accel:
                ae = an = 0.0
            return TargetInfo(e, n, ve, vn, ae, an)
    return None


def control(
    state: MissionAgentState, t_s: float, own: OwnTelemetry, params: MissionAgentParams
) -> tuple[MissionAgentState, Command, tuple[AgentEvent, ...]]:
    """One tick: the command for the vehicle's telemetry ``own`` of time ``t_s``, steered for
    ``latency_s + hold_s / 2`` later (see ``MissionAgentParams``). Its implied course rate
    k * (command - course) is within the limit for the course the vehicle is predicted to have
    then, the middle of the hold; against the course at the start of the hold it may ask up to
    W (1 + k hold_s / 2), which keeps the vehicle turning at W through a hold in which a
    command at exactly W / k of lead would let the rate decay (the turn rate itself is the
    autopilot's to limit, and it does)."""
    if params.latency_s > 0.0 or params.hold_s > 0.0:
        lead_s = params.latency_s + 0.5 * params.hold_s
        course, speed = state.last_command or (own.course_rad, own.speed_m_s)
        ahead = predict_own(own, course, speed, params.agent.envelope, lead_s)
        state, command, events = _control(state, t_s + lead_s, ahead, params)
    else:
        state, command, events = _control(state, t_s, own, params)
    return replace(state, last_command=(command.course_rad, command.speed_m_s)), command, events


def _control(
    state: MissionAgentState, t_s: float, own: OwnTelemetry, params: MissionAgentParams
) -> tuple[MissionAgentState, Command, tuple[AgentEvent, ...]]:
    target = None if state.stage == "standby" else target_at(state, t_s, params)
    if target is None:
        standby = TargetInfo(params.standby_east_m, params.standby_north_m)
        inputs = AgentInputs(t_s=t_s, own=own, target=standby)
        g, command, events = agent_step(state.standby_guidance, inputs, params.standby)
        return replace(state, standby_guidance=g), command, events
    fixes = dict(state.teammates)
    team: list[tuple[float, float]] = []
    index = 0
    in_team = params.vehicle in state.active
    if in_team:
        for vehicle in state.active:
            if vehicle == params.vehicle:
                index = len(team)
                team.append((own.east_m, own.north_m))
                continue
            fix = fixes.get(vehicle)
            if fix is not None and abs(t_s - fix.t_s) <= params.max_age_s:
                team.append(fix.at(t_s, params.max_age_s))
    base = _flown(state, target, params)
    agent = base if base.index == index else replace(base, index=index)
    inputs = AgentInputs(t_s=t_s, own=own, target=target, team_positions=tuple(team))
    g, command, events = agent_step(state.guidance, inputs, agent)
    return replace(state, guidance=g), command, events


def _flown(state: MissionAgentState, target: TargetInfo, params: MissionAgentParams) -> AgentParams:
    """The guidance and phase keeping flown now: ``track`` in the track stage, and in adjust
    once the target is seen moving faster than ``moving_speed_m_s`` (where the ground station
    itself moves on to track); else ``agent``."""
    if params.track is None:
        return params.agent
    moving = math.hypot(target.v_east_m_s, target.v_north_m_s) > params.moving_speed_m_s
    tracking = state.stage == "track" or (state.stage == "adjust" and moving)
    return params.track if tracking else params.agent
