"""One vehicle agent's mission logic, pure: what it hears, what it estimates, what it commands.

The agent's loop (``app.runtime.agent``) only moves values between the vehicle link, the bus and
these functions:

- ``observe``: a target observation into the vehicle's local IMM-UKF (Appendix B).
- ``hear_fused``: the main filter's fused estimate, with the federated information feedback
  (Appendix A) applied to the local filter.
- ``hear_mission`` / ``hear_teammate(s)``: the ground station's stage and active team, and the
  teammates' positions, for phase keeping.
- ``control``: one tick on the vehicle's own telemetry: the target as best known (the fused
  estimate, else the local one, predicted to the tick's time), the active team, and
  ``agent_step`` (guidance + phase keeping) -> a command.

Before the tracking command, or while no estimate of the target exists, the vehicle loiters
around its standby point with the same guidance field (a stationary "target" at the standby
point, no phase keeping). A vehicle that the ground station has left out of the formation keeps
orbiting the target without phase keeping, so it never steers on a stale spacing.

With ``MissionAgentParams.course_id`` the agent also identifies its vehicle's course loop in
flight (``guidance.course_id``: gain k and delay of eq. 2 from every control tick's course and
command) and, once the estimate is ready, flies the course command with the identified k (the
lead field_rate / k and the clamp W / k) and steers on the state predicted for the identified
delay when it is longer than ``latency_s``; an event ``course_loop_identified`` says what was
learned, when it first is and whenever it changes materially.

``step`` is the one entry for every driver (the fast simulation, the async agent loop, live or
in-process): it takes one ``AgentInput`` and returns the new state and an ``AgentOutbox`` of
what is to be sent or recorded; when the local estimate and the status are due is part of the
state (``MissionAgentState.estimates``, ``.statuses``).
"""

import functools
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from app.core.agent import (
    AgentEvent,
    AgentInputs,
    AgentParams,
    AgentState,
    Command,
    OwnTelemetry,
    TargetInfo,
    agent_step,
    orbit_axes,
    predict_own,
)
from app.core.estimation.federated import MainParams, apply_feedback
from app.core.estimation.local import LocalParams, LocalState, StepReport, local_step
from app.core.estimation.messages import GlobalEstimate, LocalEstimate, Observation
from app.core.estimation.models import MotionModel
from app.core.frames import wrap_pi
from app.core.guidance import course_id as cid
from app.core.guidance import wind as wind_fit
from app.core.guidance.course import course_command
from app.core.guidance.dubins import (
    MAX_JOIN_TEAM,
    dubins,
    flight_time,
    join_plan,
    sample_path,
    seat_pose,
)
from app.core.mission.schedule import Every
from app.core.mission.separation import SeparationParams, Traffic, resolve
from app.core.mission.stage import Stage
from app.core.mission.team import dead_reckon
from app.core.phase import circle_ground_speed_in_wind
from app.core.values import replace

FloatArray = NDArray[np.float64]


#: how gather joins the team to the circle (``MissionAgentParams.gather_join``)
GatherJoin = Literal["point", "seat"]


@dataclass(frozen=True, slots=True)
class TeammateFix:
    """Where a teammate was at ``t_s`` (m, rad clockwise from north, m/s; ``up_m`` its height
    about the origin, ``climb_m_s`` its climb rate and ``level_up_m`` the height it climbs
    or descends to, None where its status has none)."""

    t_s: float
    east_m: float
    north_m: float
    course_rad: float
    speed_m_s: float
    up_m: float | None = None
    climb_m_s: float | None = None
    level_up_m: float | None = None

    def at(self, t_s: float, max_extrapolation_s: float) -> tuple[float, float]:
        """Position dead-reckoned to ``t_s`` along the last course (at most the given span)."""
        dt = min(max(t_s - self.t_s, 0.0), max_extrapolation_s)
        return dead_reckon(self.east_m, self.north_m, self.course_rad, self.speed_m_s, dt)

    def up_at(self, t_s: float, max_extrapolation_s: float) -> float | None:
        """Height dead-reckoned to ``t_s`` at the last climb rate, not past its level (at most
        the given span; without a climb rate, the height of the fix)."""
        if self.up_m is None or self.climb_m_s is None:
            return self.up_m
        dt = min(max(t_s - self.t_s, 0.0), max_extrapolation_s)
        up = self.up_m + self.climb_m_s * dt
        if self.level_up_m is not None:
            low, high = sorted((self.up_m, self.level_up_m))
            up = min(max(up, low), high)
        return up


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

    What it hears cannot push it (issue #14): a message stamped more than ``max_ahead_s`` ahead
    of the agent's own clock (its newest control tick, its vehicle's time) is refused, never
    used to move that clock; a fused estimate is checked against the agent's own local one
    (position NIS over the sum of both covariances above ``fused_gate_nis``, or a position
    covariance over 100 times the local one's: refused, the local estimate flown instead); the
    local filter restarts a lost track only on a fix consistent with the fused estimate. With
    the ground silent (no fused estimate or mission state taken) the agent keeps orbiting the
    last good estimate, held still once it is older than ``max_age_s``; after
    ``ground_silent_hold_s`` of silence it holds (``Hold``; an event ``ground_silent``) until
    a ``resume``.

    Latency compensation (improvement): ``latency_s`` is the time from a telemetry frame until
    its command starts to act on the vehicle, ``hold_s`` how long a command then acts (the
    control period). The agent steers on where the vehicle and the target will be in the middle
    of that, ``latency_s + hold_s / 2`` after the frame (``agent.predict_own`` under the command
    it last sent), not on where they were (both 0: the paper's loop; a delay of one 0.1 s tick
    costs ~50 % more distance error around a moving target, ``benchmarks.bench_track
    --latency-ticks``).

    Course-loop identification (improvement): with ``course_id`` the agent fits its vehicle's
    course loop on every tick it commands (``guidance.course_id``). Once the estimate is ready
    and ``fly_identified``, ``agent``, ``standby`` and ``track`` fly with the identified k as
    their envelope's ``course_gain_per_s`` and the latency compensation uses the identified
    delay where it exceeds ``latency_s``; the flown loop is rebuilt (and reported) only when k
    moves by more than ``course_id_change`` (a fraction) or the delay changes. Without
    ``fly_identified`` the loop is identified and reported only. None: off.

    Separation (issue #13): with ``separation`` every command is checked against the
    teammates' statuses (``mission.separation``) and turned away from, or held in height
    below or above, a teammate it would come too close to (events ``separation`` and
    ``separation_clear``). None: off.
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
    course_id: cid.CourseIdParams | None = None
    fly_identified: bool = True
    course_id_change: float = 0.05
    max_ahead_s: float = 5.0
    fused_gate_nis: float = 50.0
    ground_silent_hold_s: float = 60.0
    wind: wind_fit.WindParams | None = None
    separation: SeparationParams | None = None
    gather_join: GatherJoin = "point"
    join_handover_m: float = 20.0

    def __post_init__(self) -> None:
        if self.gather_join not in ("point", "seat"):
            raise ValueError(f"gather_join must be 'point' or 'seat', got {self.gather_join!r}")
        for name in ("max_ahead_s", "fused_gate_nis", "ground_silent_hold_s", "join_handover_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if not (math.isfinite(self.course_id_change) and 0.0 < self.course_id_change < 1.0):
            raise ValueError(f"course_id_change must be in (0, 1), got {self.course_id_change!r}")
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
class TunedLoop:
    """The course loop last reported (identified gain k 1/s, delay s) and what is flown on it:
    ``flown_gain_per_s`` (the assumed k while the identified one is within
    ``course_id_change`` of it), and ``flown``, the parameters rebuilt from ``base`` (kept to
    notice other parameters; ``base`` itself when nothing needed a change)."""

    gain_per_s: float
    delay_s: float
    flown_gain_per_s: float
    base: MissionAgentParams
    flown: MissionAgentParams


@dataclass(frozen=True, slots=True)
class JoinPath:
    """One member's path to its seat (``dubins.sample_path``: east, north, heading, curvature),
    its length (m), the mean ground speed the plan flies it at (m/s) and the index of the
    point the member was nearest when last looked at."""

    points: tuple[tuple[float, float, float, float], ...]
    length_m: float
    speed_m_s: float
    progress: int = 0

    @property
    def step_m(self) -> float:
        return self.length_m / max(len(self.points) - 1, 1)

    def nearest(self, east_m: float, north_m: float) -> tuple["JoinPath", float]:
        """The path with its progress moved to the point nearest (east, north), searched up
        to 200 m ahead of the last one, and the distance to it (m)."""
        pts = self.points
        ahead = pts[self.progress : min(len(pts) - 1, self.progress + 100) + 1]
        squares = [(p[0] - east_m) ** 2 + (p[1] - north_m) ** 2 for p in ahead]
        k = self.progress + squares.index(min(squares))  # the first of equals, as min's
        off = math.hypot(pts[k][0] - east_m, pts[k][1] - north_m)
        return (self if k == self.progress else replace(self, progress=k)), off

    def remaining_m(self) -> float:
        return (len(self.points) - 1 - self.progress) * self.step_m


@dataclass(frozen=True, slots=True)
class JoinTarget:
    """The team's joining in gather (``gather_join = "seat"``): every member's seat (polar
    angles about the target, rad, counter-clockwise from east) and path, in the order of the
    team the plan was made for, this vehicle's place in it, the members seen at their seats
    (they no longer hold the team's time), and the time the slowest reaches its seat (vehicle
    time, s)."""

    index: int
    seats_rad: tuple[float, ...]
    paths: tuple[JoinPath, ...]
    t_join_s: float
    seated: frozenset[int] = frozenset()

    @property
    def seat_angle_rad(self) -> float:
        return self.seats_rad[self.index]


@dataclass(frozen=True, slots=True)
class MissionAgentState:
    """Everything one agent remembers; ``estimates`` and ``statuses`` say when the local
    estimate and the vehicle's status are next due (``step``)."""

    local: LocalState
    guidance: AgentState = field(default_factory=AgentState)
    standby_guidance: AgentState = field(default_factory=AgentState)
    fused: GlobalEstimate | None = None
    stage: Stage = Stage.STANDBY
    active: tuple[int, ...] = ()
    teammates: tuple[tuple[int, TeammateFix], ...] = ()
    holding: bool = False
    #: the (course rad, speed m/s) command of the last tick, for the latency compensation
    last_command: tuple[float, float] | None = None
    estimates: Every = field(default_factory=lambda: Every(0.2))
    statuses: Every = field(default_factory=lambda: Every(0.1))
    #: the course-loop identifier (``MissionAgentParams.course_id``) and what it has tuned
    course_id: cid.CourseIdState = field(default_factory=cid.initial_state)
    tuned: TunedLoop | None = None
    #: the agent's own clock: its newest control tick (vehicle time)
    now_t_s: float = -math.inf
    #: own-clock time of the last fused estimate or mission state taken (None: never)
    ground_heard_t_s: float | None = None
    #: the wind fit (``MissionAgentParams.wind``) and whether it has been reported known
    wind: wind_fit.WindState = field(default_factory=wind_fit.WindState)
    wind_reported: bool = False
    #: the newest wind believed, when, and whose (held while none is, ``_fit_wind``)
    wind_believed: tuple[float, tuple[float, float], str] | None = None
    #: the low-passed along-track gust (m/s) and the time of its newest measurement
    gust_m_s: float = 0.0
    gust_t_s: float = -math.inf
    #: the planned orbit's semi-axes (m) last reported (``orbit_planned``; None: the circle)
    #: and when
    orbit_reported: tuple[float, float] | None = None
    orbit_reported_t_s: float = -math.inf
    #: the separation guard (``_separate``): the teammates acted on the tick before, the
    #: teammate turned away from and whether a height band is held in this episode, and
    #: when the guard last acted (an episode ends ``_SEPARATION_QUIET_S`` after)
    separation_near: frozenset[int] = frozenset()
    separation_threat: int | None = None
    separation_band: bool = False
    separation_acted_t_s: float = -math.inf
    #: what the team's joining is planned from (``gather_join = "seat"``): the ground's time
    #: of the mission state that started gather or changed its team (None: not heard with a
    #: time), and every member's first status at or after it (its own as published)
    join_since_t_s: float | None = None
    join_fixes: tuple[tuple[int, TeammateFix], ...] = ()
    #: every member's last few statuses, its own included (a status stamped after that mission
    #: state may come before it)
    recent_fixes: tuple[tuple[int, TeammateFix], ...] = ()
    #: the seat this vehicle flies to in gather (``gather_join = "seat"``), and whether this
    #: gather's joining leg is over (joined, or dropped)
    join: JoinTarget | None = None
    join_done: bool = False


def initial_agent_state(
    params: MissionAgentParams, estimate_period_s: float = 0.2, status_period_s: float = 0.1
) -> MissionAgentState:
    """A fresh agent that publishes its local estimate at most every ``estimate_period_s`` and
    its vehicle's status every ``status_period_s`` (vehicle time; 0: at every chance)."""
    return MissionAgentState(
        local=LocalState(sensor=params.sensor),
        estimates=Every(estimate_period_s),
        statuses=Every(status_period_s),
    )


def ahead_of_clock(state: MissionAgentState, t_s: float, params: MissionAgentParams) -> str:
    """Why a message stamped ``t_s`` is refused as not of now (empty string: it is not): a
    non-finite time, or more than ``max_ahead_s`` ahead of the agent's own clock (before its
    first control tick the agent has no clock and judges nothing by it)."""
    if not math.isfinite(t_s):
        return f"non-finite time {t_s!r}"
    now = state.now_t_s
    if math.isfinite(now) and t_s > now + params.max_ahead_s:
        return (
            f"stamped {t_s - now:.3g} s ahead of the agent's clock (limit {params.max_ahead_s:g} s)"
        )
    return ""


_POS = np.ix_((0, 2), (0, 2))


def _position_nis(x: FloatArray, p: FloatArray, z: FloatArray, r: FloatArray) -> float:
    """The normalised distance between the position of state (x, p) and position z of
    covariance r: d^T (P_pos + r)^-1 d; inf when that covariance is not positive definite."""
    d = np.array([z[0] - x[0], z[1] - x[2]])
    s = p[_POS] + r
    try:
        c = np.linalg.cholesky(0.5 * (s + s.T))
    except np.linalg.LinAlgError:
        return math.inf
    w = np.linalg.solve(c, d)
    return float(w @ w)


def _predicted(
    x: FloatArray, p: FloatArray, dt_s: float, params: MissionAgentParams
) -> tuple[FloatArray, FloatArray]:
    model = params.prediction_model
    f = model.transition(dt_s)
    return f @ x, f @ p @ f.T + model.process_noise(abs(dt_s))


def check_fused(state: MissionAgentState, fused: GlobalEstimate, params: MissionAgentParams) -> str:
    """Why the fused estimate ``fused`` is not believed (empty string: it is): non-finite or
    absurd values, per-model moments that are not this agent's models, or a position the
    agent's own local estimate (predicted to its time) says it cannot be at."""
    x, p = np.asarray(fused.x), np.asarray(fused.p)
    if x.shape != (6,) or p.shape != (6, 6):
        return f"state of shape {x.shape}, covariance {p.shape}"
    if not (np.isfinite(x).all() and np.isfinite(p).all()):
        return "non-finite state or covariance"
    if not np.abs(x).max() <= params.local.max_abs_position_m:
        return f"state beyond {params.local.max_abs_position_m:g}"
    moments = (fused.mu, fused.model_x, fused.model_p)
    if any(m is not None for m in moments):
        r = len(params.local.imm.models)
        shapes = [np.shape(m) if m is not None else None for m in moments]
        if shapes != [(r,), (r, 6), (r, 6, 6)] or not all(
            np.isfinite(m).all() for m in moments if m is not None
        ):
            return f"per-model moments that are not of this agent's {r} models"
    local = state.local.estimate()
    if local is None:
        return ""  # nothing of its own to judge by
    # judged however far apart in time: the prediction widens the covariance (a window here
    # let through a forged estimate stamped a few seconds off a lagging agent's filter)
    xl, pl = _predicted(local.x, local.p, fused.t_s - local.t_s, params)
    nis = _position_nis(xl, pl, x[[0, 2]], p[_POS])
    if not nis <= params.fused_gate_nis:
        return (
            f"{math.hypot(x[0] - xl[0], x[2] - xl[2]):.3g} m from the agent's own estimate "
            f"(NIS {nis:.3g} above {params.fused_gate_nis:g})"
        )
    if np.trace(p[_POS]) > 100.0 * np.trace(pl[_POS]):
        return "far less certain than the agent's own estimate"
    return ""


def observe(
    state: MissionAgentState, obs: Observation, params: MissionAgentParams
) -> tuple[MissionAgentState, StepReport]:
    """Feed one observation to the local filter; the report says whether it was used and why
    not. One stamped ahead of the agent's clock is refused (``invalid``); the filter restarts
    a lost track only on a fix the fused estimate, when fresh, finds consistent."""
    ahead = ahead_of_clock(state, obs.t_s, params)
    if ahead:
        counters = state.local.counters
        counters = replace(counters, invalid=counters.invalid + 1)
        local = replace(state.local, counters=counters)
        return replace(state, local=local), StepReport("invalid", ahead)
    fused = state.fused

    def consistent(fix: Observation) -> bool:
        if fused is None or abs(fix.t_s - fused.t_s) > params.max_age_s:
            return True
        x, p = _predicted(fused.x, fused.p, fix.t_s - fused.t_s, params)
        sigma = params.local.default_sigma_m if fix.sigma_m is None else fix.sigma_m
        z = np.array([fix.east_m, fix.north_m])
        return _position_nis(x, p, z, np.eye(2) * sigma * sigma) <= params.fused_gate_nis

    local, report = local_step(state.local, obs, params.local, may_restart=consistent)
    return replace(state, local=local), report


def _heard_ground(state: MissionAgentState) -> MissionAgentState:
    now = state.now_t_s
    return replace(state, ground_heard_t_s=now) if math.isfinite(now) else state


def hear_fused(
    state: MissionAgentState, fused: GlobalEstimate, params: MissionAgentParams
) -> MissionAgentState:
    """Keep the newest fused estimate and apply the main filter's information allocation
    (one the agent does not believe, ``ahead_of_clock`` or ``check_fused``, is ignored:
    ``step`` says why)."""
    return _hear_fused(state, fused, params)[0]


def _hear_fused(
    state: MissionAgentState, fused: GlobalEstimate, params: MissionAgentParams
) -> tuple[MissionAgentState, str]:
    refused = ahead_of_clock(state, fused.t_s, params) or check_fused(state, fused, params)
    if refused:
        return state, refused
    if state.fused is not None and fused.t_s < state.fused.t_s:
        return state, ""
    local = state.local
    if params.main is not None:
        local = apply_feedback(local, fused, params.local, params.main)
    return _heard_ground(replace(state, fused=fused, local=local)), ""


def hear_mission(
    state: MissionAgentState, stage: str, active: tuple[int, ...]
) -> MissionAgentState:
    """The ground station's stage and active team (sorted, unique vehicle ids)."""
    try:
        known = Stage(stage)
    except ValueError:
        raise ValueError(f"unknown stage {stage!r}") from None
    return _heard_ground(replace(state, stage=known, active=tuple(sorted(set(active)))))


def hear_teammate(state: MissionAgentState, vehicle: int, fix: TeammateFix) -> MissionAgentState:
    """A teammate's newest position (older fixes than the one held are ignored)."""
    return hear_teammates(state, ((vehicle, fix),))


def hear_teammates(
    state: MissionAgentState, fixes: Iterable[tuple[int, TeammateFix]]
) -> MissionAgentState:
    """Teammates' positions in the order heard, as ``hear_teammate`` one after another, in one
    update of the state: a team's statuses cost one step per control tick, not one each."""
    held = dict(state.teammates)
    changed = False
    for vehicle, fix in fixes:
        state = _join_fix(state, vehicle, fix)
        old = held.get(vehicle)
        if old is None or fix.t_s >= old.t_s:
            held[vehicle] = fix
            changed = True
    return replace(state, teammates=tuple(sorted(held.items()))) if changed else state


def _join_fix(state: MissionAgentState, vehicle: int, fix: TeammateFix) -> MissionAgentState:
    """Remember ``fix`` among the vehicle's last ``_RECENT_FIXES`` statuses, and keep it as the
    vehicle's pose to plan the joining from if it is its first at or after
    ``join_since_t_s``: every agent keeps the same statuses, its own included (teams of up to
    ``dubins.MAX_JOIN_TEAM``)."""
    if len(state.active) > MAX_JOIN_TEAM:
        return state
    mine = [f for v, f in state.recent_fixes if v == vehicle][-(_RECENT_FIXES - 1) :]
    others = [(v, f) for v, f in state.recent_fixes if v != vehicle]
    state = replace(state, recent_fixes=(*others, *((vehicle, f) for f in mine), (vehicle, fix)))
    since = state.join_since_t_s
    if since is None or fix.t_s < since or any(v == vehicle for v, _ in state.join_fixes):
        return state
    return replace(state, join_fixes=tuple(sorted((*state.join_fixes, (vehicle, fix)))))


#: how many of each member's statuses an agent keeps for the joining plan (0.5 s at 10 Hz)
_RECENT_FIXES = 5


def _join_started(state: MissionAgentState, t_s: float) -> MissionAgentState:
    """The team's joining is planned from each member's first status at or after ``t_s`` (the
    ground's time of the mission state that started gather or changed its team): those
    already heard, and those to come."""
    first: dict[int, TeammateFix] = {}
    for vehicle, fix in state.recent_fixes:
        if fix.t_s >= t_s and (vehicle not in first or fix.t_s < first[vehicle].t_s):
            first[vehicle] = fix
    return replace(state, join_since_t_s=t_s, join_fixes=tuple(sorted(first.items())))


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
    if candidates and state.ground_heard_t_s is not None:
        # the ground went silent and nothing fresh is known: orbit the last good estimate
        # where it was last known (its velocity is not flown on for ever), until the hold
        t0, x = max(candidates, key=lambda c: c[0])
        return TargetInfo(float(x[0]), float(x[2]))
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
    autopilot's to limit, and it does). With ``course_id`` k and the latency are the
    identified ones once ready; the tick (course, command sent) feeds the identifier."""
    flown = _flown_params(state, params)
    wind = known_wind = None
    if params.wind is not None:
        state, known_wind = _fit_wind(state, t_s, own, params.wind)
        if params.wind.air_frame and state.stage == "track":
            wind = known_wind
    steer = own if wind is None else _through_the_air(own, wind)
    if flown.latency_s > 0.0 or flown.hold_s > 0.0:
        lead_s = flown.latency_s + 0.5 * flown.hold_s
        course, speed = state.last_command or (steer.course_rad, steer.speed_m_s)
        ahead = predict_own(steer, course, speed, flown.agent.envelope, lead_s)
        state, command, events = _control(state, t_s + lead_s, ahead, flown, wind, known_wind)
    else:
        state, command, events = _control(state, t_s, steer, flown, wind, known_wind)
    state = replace(state, last_command=(command.course_rad, command.speed_m_s))
    if wind is not None:
        state, command, known = _over_the_ground(state, t_s, command, wind)
        events = (*events, *known)
    if wind is None and known_wind is not None and params.wind is not None:
        state, command, known = _in_the_wind(
            state, t_s, own, command, flown, known_wind, params.wind
        )
        events = (*events, *known)
    if params.separation is not None and own.up_m is not None:
        state, command, apart = _separate(state, t_s, own, command, params, params.separation)
        events = (*events, *apart)
    if params.course_id is not None:
        state, learned = _identify(state, t_s, own, command, params, params.course_id)
        events = (*events, *learned)
    return state, command, events


def _separate(
    state: MissionAgentState,
    t_s: float,
    own: OwnTelemetry,
    command: Command,
    params: MissionAgentParams,
    separation: SeparationParams,
) -> tuple[MissionAgentState, Command, tuple[AgentEvent, ...]]:
    """The command kept apart from the teammates (``mission.separation``): its course turned
    away from a threat, its height band set. Events: ``separation`` when an episode starts
    and when it turns away from another teammate or first holds a height in it,
    ``separation_clear`` once the guard has not acted for ``_SEPARATION_QUIET_S``."""
    traffic = []
    for vehicle, fix in state.teammates:
        if vehicle == params.vehicle or abs(t_s - fix.t_s) > separation.max_age_s:
            continue
        east, north = fix.at(t_s, separation.max_age_s)
        traffic.append(
            Traffic(
                vehicle,
                east,
                north,
                fix.up_at(t_s, separation.max_age_s),
                fix.course_rad,
                fix.speed_m_s,
                fix.climb_m_s,
                fix.level_up_m,
            )
        )
    assert own.up_m is not None
    r = resolve(
        own.east_m,
        own.north_m,
        own.up_m,
        own.course_rad,
        own.speed_m_s,
        command.course_rad,
        traffic,
        params.agent.envelope.max_course_rate_rad_s,
        separation,
        state.separation_near,
        own.climb_m_s,
        own.level_up_m,
    )
    events: list[AgentEvent] = []
    band = r.min_up_m is not None or r.max_up_m is not None
    if r.threat is not None:
        if r.threat != state.separation_threat:
            turn = math.degrees(wrap_pi(r.course_rad - own.course_rad))
            events.append(
                AgentEvent(
                    t_s,
                    "separation",
                    f"vehicle {r.threat + 1} predicted {r.closest_m:.0f} m away within "
                    f"{separation.look_ahead_s:g} s: turning to course "
                    f"{math.degrees(r.course_rad) % 360.0:.0f} deg ({turn:+.0f} deg from its own)",
                )
            )
        command = replace(
            command,
            course_rad=r.course_rad,
            field_course_rad=r.course_rad,
            course_rate_ff_rad_s=0.0,
        )
        if state.last_command is not None and params.wind is None:
            state = replace(state, last_command=(r.course_rad, command.speed_m_s))
    if band:
        if not state.separation_band:
            limits = []
            if r.max_up_m is not None:
                limits.append(f"at most {r.max_up_m:.0f} m")
            if r.min_up_m is not None:
                limits.append(f"at least {r.min_up_m:.0f} m")
            events.append(
                AgentEvent(
                    t_s,
                    "separation",
                    f"a teammate is near: height held {' and '.join(limits)} above the origin "
                    f"(now {own.up_m:.0f} m)",
                )
            )
        command = replace(command, min_up_m=r.min_up_m, max_up_m=r.max_up_m)
    if r.acted:
        state = replace(
            state,
            separation_near=r.near,
            separation_threat=r.threat if r.threat is not None else state.separation_threat,
            separation_band=state.separation_band or band,
            separation_acted_t_s=t_s,
        )
    elif state.separation_near:
        state = replace(state, separation_near=frozenset())
    episode = state.separation_threat is not None or state.separation_band
    if episode and not r.acted and t_s - state.separation_acted_t_s >= _SEPARATION_QUIET_S:
        events.append(
            AgentEvent(
                t_s,
                "separation_clear",
                f"no teammate near for {_SEPARATION_QUIET_S:g} s",
            )
        )
        state = replace(state, separation_threat=None, separation_band=False)
    return state, command, tuple(events)


_SEPARATION_QUIET_S = 5.0


def _through_the_air(own: OwnTelemetry, wind: tuple[float, float]) -> OwnTelemetry:
    """The vehicle as the air mass sees it: its position, and its velocity less the wind
    (heading and airspeed). Where that is too slow to have a direction, ``own`` itself."""
    a_east = own.speed_m_s * math.sin(own.course_rad) - wind[0]
    a_north = own.speed_m_s * math.cos(own.course_rad) - wind[1]
    speed = math.hypot(a_east, a_north)
    if speed < 1.0:
        return own
    return OwnTelemetry(
        own.east_m, own.north_m, math.atan2(a_east, a_north), speed, own.airspeed_m_s
    )


def _ground_velocity(
    heading_rad: float, airspeed_m_s: float, wind: tuple[float, float]
) -> tuple[float, float]:
    return airspeed_m_s * math.sin(heading_rad) + wind[0], airspeed_m_s * math.cos(
        heading_rad
    ) + wind[1]


def _over_the_ground(
    state: MissionAgentState, t_s: float, command: Command, wind: tuple[float, float]
) -> tuple[MissionAgentState, Command, tuple[AgentEvent, ...]]:
    """A command the guidance computed in the air mass (heading, airspeed; the target moving
    at its ground velocity less the wind) as the autopilot takes it: the ground course of that
    air velocity in the wind, with the airspeed itself (``airspeed_m_s``). The first time the
    wind is known, an event says so."""
    air = command.speed_m_s
    g_east, g_north = _ground_velocity(command.course_rad, air, wind)
    f_east, f_north = _ground_velocity(command.field_course_rad, air, wind)
    ground2 = f_east * f_east + f_north * f_north
    # the ground course turns at (a (a + w . h) / |g|^2) times the heading's rate
    along = wind[0] * math.sin(command.field_course_rad) + wind[1] * math.cos(
        command.field_course_rad
    )
    rate_scale = air * (air + along) / ground2 if ground2 > 1.0 else 1.0
    command = replace(
        command,
        course_rad=math.atan2(g_east, g_north),
        speed_m_s=math.hypot(g_east, g_north),
        field_course_rad=math.atan2(f_east, f_north),
        course_rate_ff_rad_s=command.course_rate_ff_rad_s * rate_scale,
        airspeed_m_s=air,
    )
    if state.wind_reported:
        return state, command, ()
    speed = math.hypot(*wind)
    toward = math.degrees(math.atan2(wind[0], wind[1])) % 360.0
    detail = (
        f"{speed:.1f} m/s toward {toward:.0f} deg ({_wind_source(state)}): guidance flies "
        "in the air mass (the target moving at its ground velocity less the wind)"
    )
    return replace(state, wind_reported=True), command, (AgentEvent(t_s, "wind_estimated", detail),)


def _fit_wind(
    state: MissionAgentState, t_s: float, own: OwnTelemetry, params: wind_fit.WindParams
) -> tuple[MissionAgentState, tuple[float, float] | None]:
    """The wind fit with this frame, and the wind believed: the autopilot's own estimate where
    the frame carries a usable one (finite, within ``max_wind_m_s``), else the fit's, or while
    the fit is not believed for a moment (a straight leg, a gusty spell) the last believed wind
    for up to ``hold_s``, so the guidance does not switch frames tick by tick."""
    v_east = own.speed_m_s * math.sin(own.course_rad)
    v_north = own.speed_m_s * math.cos(own.course_rad)
    fit = wind_fit.update(state.wind, t_s, v_east, v_north, own.airspeed_m_s, params)
    state = replace(state, wind=fit)
    reported = own.wind_m_s
    if reported is not None and math.hypot(*reported) <= params.max_wind_m_s:  # NaN: False
        return replace(state, wind_believed=(t_s, reported, _AUTOPILOT_WIND)), reported
    wind = fit.estimate(params)
    if wind is not None:
        return replace(state, wind_believed=(t_s, wind, _FITTED_WIND)), wind
    held = state.wind_believed
    if held is not None and 0.0 <= t_s - held[0] <= params.hold_s:
        return state, held[1]
    return state, None


_AUTOPILOT_WIND = "the autopilot's estimate"
_FITTED_WIND = "fitted to ground velocity and airspeed"


def _wind_source(state: MissionAgentState) -> str:
    return _FITTED_WIND if state.wind_believed is None else state.wind_believed[2]


def _in_the_wind(
    state: MissionAgentState,
    t_s: float,
    own: OwnTelemetry,
    command: Command,
    params: MissionAgentParams,
    wind: tuple[float, float],
    wind_params: wind_fit.WindParams,
) -> tuple[MissionAgentState, Command, tuple[AgentEvent, ...]]:
    """The command with the airspeed that flies its ground speed along its desired ground
    course in the estimated wind plus the along-track gust measured now, for the course one
    speed-loop time constant ahead (the autopilot's airspeed lags its command by about that);
    unchanged while the wind is unknown. The first time the wind is known, an event says so."""
    gust = wind_fit.along_track_gust(own.course_rad, own.speed_m_s, own.airspeed_m_s, wind)
    if gust is not None:
        filtered = wind_fit.filtered_gust(state.gust_m_s, state.gust_t_s, gust, t_s, wind_params)
        state = replace(state, gust_m_s=filtered, gust_t_s=t_s)
    envelope = params.agent.envelope
    lag_s = 1.0 / envelope.speed_gain_per_s
    # the gust was measured along the vehicle's own track: it blows that way
    blowing = (
        wind[0] + state.gust_m_s * math.sin(own.course_rad),
        wind[1] + state.gust_m_s * math.cos(own.course_rad),
    )
    air = wind_fit.airspeed_for(
        command.field_course_rad + command.course_rate_ff_rad_s * lag_s,
        command.speed_m_s,
        blowing,
        envelope.min_speed_m_s,
        envelope.max_speed_m_s,
    )
    command = replace(command, airspeed_m_s=air)
    if state.wind_reported:
        return state, command, ()
    speed = math.hypot(*wind)
    toward = math.degrees(math.atan2(wind[0], wind[1])) % 360.0
    detail = (
        f"{speed:.1f} m/s toward {toward:.0f} deg ({_wind_source(state)}): "
        "commands carry the airspeed that flies their ground speed in it"
    )
    return replace(state, wind_reported=True), command, (AgentEvent(t_s, "wind_estimated", detail),)


def _flown_params(state: MissionAgentState, params: MissionAgentParams) -> MissionAgentParams:
    """``params``, or the ones rebuilt with the identified course loop."""
    tuned = state.tuned
    if tuned is None or not params.fly_identified:
        return params
    if tuned.base is params:
        return tuned.flown
    return _retuned(params, tuned.flown_gain_per_s, tuned.delay_s)


def _retuned(params: MissionAgentParams, gain_per_s: float, delay_s: float) -> MissionAgentParams:
    """The agent's parameters flown with course gain ``gain_per_s`` (every envelope) and a
    latency of at least ``delay_s``; ``params`` itself when that changes nothing."""
    latency_s = max(params.latency_s, delay_s)
    if gain_per_s == params.agent.envelope.course_gain_per_s and latency_s == params.latency_s:
        return params

    def tuned(agent: AgentParams) -> AgentParams:
        return replace(agent, envelope=replace(agent.envelope, course_gain_per_s=gain_per_s))

    return replace(
        params,
        agent=tuned(params.agent),
        standby=tuned(params.standby),
        track=None if params.track is None else tuned(params.track),
        latency_s=latency_s,
    )


def _identify(
    state: MissionAgentState,
    t_s: float,
    own: OwnTelemetry,
    command: Command,
    params: MissionAgentParams,
    id_params: cid.CourseIdParams,
) -> tuple[MissionAgentState, tuple[AgentEvent, ...]]:
    """Feed the tick to the identifier; when a ready estimate is new, or its k has moved by more
    than ``course_id_change`` or its delay changed since last reported, report it and fly it
    (k only where it differs from the assumed one by as much)."""
    sent = None if state.holding else command.course_rad
    ident = cid.update(state.course_id, cid.CourseSample(t_s, own.course_rad, sent), id_params)
    state = replace(state, course_id=ident)
    est = cid.estimate(ident, id_params)
    if not est.ready:
        return state, ()
    change = params.course_id_change
    last = state.tuned
    if last is not None and last.base is params:
        moved = abs(est.gain_per_s - last.gain_per_s) > change * last.gain_per_s
        if not moved and est.delay_s == last.delay_s:
            return state, ()
    assumed = params.agent.envelope.course_gain_per_s
    gain = est.gain_per_s if abs(est.gain_per_s - assumed) > change * assumed else assumed
    flown = _retuned(params, gain, est.delay_s) if params.fly_identified else params
    state = replace(state, tuned=TunedLoop(est.gain_per_s, est.delay_s, gain, params, flown))
    if not params.fly_identified:
        use = "not flown"
    elif flown is params:
        use = "flown as assumed"
    else:
        use = f"flown with k = {gain:.3f} /s, latency {flown.latency_s:.2f} s"
    detail = (
        f"k = {est.gain_per_s:.3f} /s, delay = {est.delay_s:.2f} s "
        f"(assumed k = {assumed:.3f} /s, latency {params.latency_s:.2f} s; "
        f"{est.informative_count} informative samples, {est.informative_s:.0f} s, "
        f"rel. se {est.rel_se:.1%}): {use}"
    )
    return state, (AgentEvent(t_s, "course_loop_identified", detail),)


def identified_course_loop(state: MissionAgentState) -> tuple[float, float] | None:
    """The identified (gain 1/s, delay s) in use, None before the estimate is ready."""
    tuned = state.tuned
    return None if tuned is None else (tuned.gain_per_s, tuned.delay_s)


@dataclass(frozen=True, slots=True)
class CourseLoopReport:
    """Where a vehicle's course-loop identification stands (``course_loop_report``)."""

    identified: bool  # an estimate was ready: then ``gain_per_s``, ``delay_s`` in use
    gain_per_s: float | None
    delay_s: float | None
    fit_gain_per_s: float  # the identifier's fit now (the prior before 2 informative samples)
    fit_delay_s: float
    informative_s: float  # the informative seconds it remembers; ``min_s`` are needed
    min_s: float
    informative_samples: int
    rel_se: float | None  # k's relative standard error (None: not yet defined)
    max_rel_se: float
    saturated: int  # ticks left out: the loop may have been saturated
    quiet: int  # ticks left out: the course error too small for the noise
    gaps: int  # windows restarted (a gap, a tick with no command)


def course_loop_report(
    state: MissionAgentState, params: MissionAgentParams
) -> CourseLoopReport | None:
    """Where the course-loop identification stands, for the run's summary (None when it is
    off): whether an estimate was ready and which one is flown, the identifier's fit now,
    and what it counted, so that a vehicle never identified shows which test held it back
    (too few informative seconds, or a standard error still above the one needed)."""
    id_params = params.course_id
    if id_params is None:
        return None
    ident = state.course_id
    est = cid.estimate(ident, id_params)
    tuned = state.tuned
    return CourseLoopReport(
        identified=tuned is not None,
        gain_per_s=None if tuned is None else round(tuned.gain_per_s, 4),
        delay_s=None if tuned is None else tuned.delay_s,
        fit_gain_per_s=round(est.gain_per_s, 4),
        fit_delay_s=est.delay_s,
        informative_s=round(ident.informative_s, 2),
        min_s=id_params.min_informative_s,
        informative_samples=ident.informative_count,
        rel_se=round(est.rel_se, 4) if math.isfinite(est.rel_se) else None,
        max_rel_se=id_params.max_rel_se,
        saturated=ident.saturated,
        quiet=ident.quiet,
        gaps=ident.gaps,
    )


def _control(
    state: MissionAgentState,
    t_s: float,
    own: OwnTelemetry,
    params: MissionAgentParams,
    wind: tuple[float, float] | None = None,
    known_wind: tuple[float, float] | None = None,
) -> tuple[MissionAgentState, Command, tuple[AgentEvent, ...]]:
    """The guidance's command; with ``wind`` in the air mass (``own`` its heading and airspeed,
    the target and the standby point moving at their ground velocity less the wind). With
    ``known_wind`` (the wind the agent believes, in any stage) a lead speed is held to what
    the circle can be flown at in it (``_lead_in_wind``)."""
    target = None if state.stage == "standby" else target_at(state, t_s, params)
    w_east, w_north = (0.0, 0.0) if wind is None else wind
    if target is None:
        standby = TargetInfo(params.standby_east_m, params.standby_north_m, -w_east, -w_north)
        inputs = AgentInputs(t_s=t_s, own=own, target=standby)
        g, command, events = agent_step(state.standby_guidance, inputs, params.standby)
        return replace(state, standby_guidance=g), command, events
    fixes = dict(state.teammates)
    team: list[tuple[float, float]] = []
    motion: list[tuple[float, float]] = []
    index = 0
    in_team = params.vehicle in state.active
    if in_team:
        for vehicle in state.active:
            if vehicle == params.vehicle:
                index = len(team)
                team.append((own.east_m, own.north_m))
                motion.append((own.course_rad, own.speed_m_s))
                continue
            fix = fixes.get(vehicle)
            if fix is not None and abs(t_s - fix.t_s) <= params.max_age_s:
                team.append(fix.at(t_s, params.max_age_s))
                motion.append(_air_motion(fix.course_rad, fix.speed_m_s, wind))
    base = _flown(state, target, params)
    agent = base if base.index == index else replace(base, index=index)
    if agent.phase.lead_speed_m_s is not None and known_wind is not None:
        agent = _lead_in_wind(agent, known_wind)
    if wind is not None:
        target = replace(
            target, v_east_m_s=target.v_east_m_s - w_east, v_north_m_s=target.v_north_m_s - w_north
        )
    inputs = AgentInputs(
        t_s=t_s, own=own, target=target, team_positions=tuple(team), team_motion=tuple(motion)
    )
    g, command, events = agent_step(state.guidance, inputs, agent)
    state = replace(state, guidance=g)
    if params.gather_join == "seat":
        state, command, joining = _join_leg(
            state, t_s, own, target, team, motion, index, agent, command, params, known_wind, wind
        )
        events = (*events, *joining)
    if agent.guidance.orbit_plan == "ellipse":
        state, planned = _orbit_planned(state, t_s, target, agent, wind)
        events = (*events, *planned)
    return state, command, events


def _lead_in_wind(agent: AgentParams, wind: tuple[float, float]) -> AgentParams:
    """``agent`` with its lead speed (``PhaseParams.lead_speed_m_s``, gather and adjust) only
    where the circle can be flown all round at that ground speed in the known ``wind``
    (``phase.circle_ground_speed_in_wind``: 18 m/s in still air at 0.2 rad/s on 90 m, 14.2 m/s
    in 3 m/s); elsewhere the paper's law about cruise. A leader faster than that is blown off
    the circle downwind while it waits for the team: the default mission with an 18 m/s lead
    formed in 2 of 12 fast-sim runs in 3 m/s + 1 m/s gusts, and in 9 with the lead held to
    that speed (its law then closes the gaps only by slowing the vehicles ahead), against 11
    with no lead."""
    lead = agent.phase.lead_speed_m_s
    env = agent.envelope
    cap = circle_ground_speed_in_wind(
        math.hypot(wind[0], wind[1]), agent.guidance.radius_m, env.max_course_rate_rad_s
    )
    if lead is None or lead <= cap:
        return agent
    return replace(agent, phase=replace(agent.phase, lead_speed_m_s=None))


def _air_motion(
    course_rad: float, speed_m_s: float, wind: tuple[float, float] | None
) -> tuple[float, float]:
    """A teammate's (course, speed) over the ground, or through the air mass where the agent
    flies in it (``wind``: the air's motion east, north m/s), as its own telemetry then is."""
    if wind is None:
        return course_rad, speed_m_s
    ve = speed_m_s * math.sin(course_rad) - wind[0]
    vn = speed_m_s * math.cos(course_rad) - wind[1]
    return math.atan2(ve, vn), math.hypot(ve, vn)


def _orbit_planned(
    state: MissionAgentState,
    t_s: float,
    target: TargetInfo,
    agent: AgentParams,
    wind: tuple[float, float] | None,
) -> tuple[MissionAgentState, tuple[AgentEvent, ...]]:
    """An ``orbit_planned`` event the first time the circle is not flyable around the target
    (too fast over the ground, or through the air mass) and the nearest flyable orbit is flown;
    then, at most every ``_ORBIT_REPORT_S``, when it is flyable again or a semi-axis has moved
    by more than 8 m since last said (the target's speed is an estimate: the plan moves
    with it every tick, the log only with what matters)."""
    rd = agent.guidance.radius_m
    speed = math.hypot(target.v_east_m_s, target.v_north_m_s)
    along, across = orbit_axes(speed, agent, rd)
    circle = along == rd and across == rd
    last = state.orbit_reported
    moved = last is not None and max(abs(along - last[0]), abs(across - last[1])) > 8.0
    unchanged = circle if last is None else not circle and not moved
    first = last is None and state.orbit_reported_t_s == -math.inf
    if unchanged or (not first and t_s - state.orbit_reported_t_s < _ORBIT_REPORT_S):
        return state, ()
    if circle:
        detail = f"target {speed:.1f} m/s: the circle r_d = {rd:.0f} m is flyable again"
    else:
        frame = "over the ground" if wind is None else "through the air mass"
        detail = (
            f"target {speed:.1f} m/s {frame}: the circle r_d = {rd:.0f} m is not flyable at "
            f"this airframe's limits; flying the nearest flyable orbit, semi-axes "
            f"{along:.0f} m along its motion, {across:.0f} m across"
        )
    reported = None if circle else (along, across)
    state = replace(state, orbit_reported=reported, orbit_reported_t_s=t_s)
    return state, (AgentEvent(t_s, "orbit_planned", detail),)


_ORBIT_REPORT_S = 20.0


#: the joining paths turn on this many times the tightest turn at the top speed (the rest of
#: the course rate is the tracking's, against the course loop's lag)
_JOIN_TURN_MARGIN = 1.1
#: within this of the circle (m), flying along it (within ``_JOIN_ALONG``), a vehicle has
#: joined it: the field and phase keeping take it from there (20 m handed over on the last
#: turn's approach, 140 m before the seat, and the short mission of configs/test-short.toml
#: then formed only after the target had left; without it the default mission's vehicles
#: ended their paths 8 m off the circle and formed 15 s later)
_JOIN_CIRCLE_M = 5.0
_JOIN_ALONG = math.radians(30.0)
#: points of a joining path this far apart (m)
_JOIN_STEP_M = 2.0
#: further than this from its path (m), a vehicle plans its path to the seat again
_JOIN_REPLAN_M = 40.0
#: the point steered for is this far ahead along the path (s at the speed flown, at least 20 m)
_JOIN_LOOKAHEAD_S = 1.5


def _agreed_starts(
    state: MissionAgentState, max_age_s: float, air_wind: tuple[float, float] | None
) -> list[tuple[float, float, float]] | None:
    """Every active member's pose (east, north m, heading rad counter-clockwise from east) to
    plan the joining from: its first status since the team was set (``join_fixes``), each
    dead-reckoned to the newest of them, through the air mass where the agent flies in it;
    None while one is missing. Every agent holds the same statuses, so plans from the same
    poses (its own telemetry, a tick newer than its status, once made two agents choose
    placings 105 degrees apart that their views put 0.09 s apart)."""
    fixes = dict(state.join_fixes)
    if any(vehicle not in fixes for vehicle in state.active):
        return None
    chosen = [fixes[vehicle] for vehicle in state.active]
    t_ref = max(fix.t_s for fix in chosen)
    out = []
    for fix in chosen:
        east, north = fix.at(t_ref, max_age_s)
        course, _ = _air_motion(fix.course_rad, fix.speed_m_s, air_wind)
        out.append((east, north, 0.5 * math.pi - course))
    return out


def _join_path(
    start: tuple[float, float, float],
    goal: tuple[float, float, float],
    turn_radius_m: float,
    airspeed_m_s: float,
    wind: tuple[float, float],
) -> JoinPath:
    path = dubins(start, goal, turn_radius_m)
    time_s = flight_time(start, path, turn_radius_m, airspeed_m_s, wind)
    speed = path.length_m / time_s if math.isfinite(time_s) and time_s > 0.0 else airspeed_m_s
    points = sample_path(start, path, turn_radius_m, _JOIN_STEP_M)
    return JoinPath(points, path.length_m, speed)


def _join_leg(
    state: MissionAgentState,
    t_s: float,
    own: OwnTelemetry,
    target: TargetInfo,
    team: list[tuple[float, float]],
    motion: list[tuple[float, float]],
    index: int,
    agent: AgentParams,
    command: Command,
    params: MissionAgentParams,
    known_wind: tuple[float, float] | None = None,
    air_wind: tuple[float, float] | None = None,
) -> tuple[MissionAgentState, Command, tuple[AgentEvent, ...]]:
    """Gather with a seat each (``gather_join = "seat"``), in place of the field's ``command``
    until the vehicle is on its way round the circle.

    At the first gather tick at which it holds every active member's first status since the
    mission state that started gather or changed the team (``_agreed_starts``, its own as it
    published it; a team of 2 to ``dubins.MAX_JOIN_TEAM``), the agent plans the team's joining
    (``dubins.join_plan``: seats 2 pi / n apart, each vehicle's shortest path at the top speed,
    the slowest flight plus the earliest arrival as short as can be, timed in the wind the
    agent knows) and every member's path; every agent plans from the same statuses, so the
    plans agree (a ground without the mission state's time: from the poses it knows now). The
    paths turn on ``_JOIN_TURN_MARGIN`` times the tightest turn at the top speed over the
    ground (the airspeed plus the wind), which leaves course rate to follow them with. Each
    tick:

    - the team's time is taken again: when the slowest member not yet at its seat, going on
      along its path at the plan's speed from the point of it nearest its status, gets there
      (a member held up by the wind or a turn holds all back);
    - the vehicle steers for the point ``_JOIN_LOOKAHEAD_S`` ahead of the nearest one on its
      path, with the path's turn fed forward, at the speed that brings it to its seat at the
      team's time (within the envelope); further than ``_JOIN_REPLAN_M`` off its path it plans
      its path again.

    Within ``join_handover_m`` of its seat or of its path's end it has joined (event
    ``joined``) and the field and phase keeping fly on; the leg goes on into adjust (which the
    ground station starts once every vehicle is near the circle, some still on the last turn
    of their paths). A vehicle that joins the team or leaves it makes every agent plan again
    in gather (``join_dropped``, then ``join_planned``; in adjust the leg is dropped); the leg
    ends with the stage (a target seen moving takes the team to track: its estimated velocity alone
    is not trusted here, as it is noisy while the filters start, early in gather); a team that
    cannot be planned, or a vehicle whose phase actuator is not its
    speed (PX4 fixed-wing holds its own airspeed: the arrivals could not be timed), flies the
    field."""
    if state.stage not in (Stage.GATHER, Stage.ADJUST):
        if state.join is not None or state.join_done:
            state = replace(state, join=None, join_done=False)
        return state, command, ()
    if state.join_done or (state.join is None and state.stage != Stage.GATHER):
        return state, command, ()
    env = agent.envelope
    sign = agent.guidance.orbit_sign
    rd = agent.guidance.radius_m
    wind = (0.0, 0.0) if known_wind is None else known_wind
    # the tightest ground turn downwind: at the top airspeed plus the wind the agent knows
    turn_radius = (
        _JOIN_TURN_MARGIN * (env.max_speed_m_s + math.hypot(*wind)) / env.max_course_rate_rad_s
    )
    centre = (target.east_m, target.north_m)
    join = state.join
    events: tuple[AgentEvent, ...] = ()
    if join is not None and (len(team) != len(join.seats_rad) or index != join.index):
        # a vehicle joined the team or left it (every agent hears it alike): plan again, in
        # gather; in adjust the field spaces what there is
        state = replace(state, join=None, join_done=state.stage != Stage.GATHER)
        events = (AgentEvent(t_s, "join_dropped", "the team changed"),)
        if state.join_done:
            return state, command, events
        join = None
    starts = [
        (east, north, 0.5 * math.pi - course)
        for (east, north), (course, _) in zip(team, motion, strict=True)
    ]
    if join is None:
        n = len(team)
        if params.vehicle not in state.active or n != len(state.active) or n < 2:
            # a teammate not heard yet, or none in the team yet: try again next tick
            return state, command, events
        plan_from = starts
        if state.join_since_t_s is not None:
            agreed = _agreed_starts(state, params.max_age_s, air_wind)
            if agreed is None:  # a member's first status since the team was set not heard yet
                return state, command, events
            plan_from = agreed
        if n > MAX_JOIN_TEAM or agent.phase.actuator != "speed":
            # too large a team to plan, or an autopilot that holds its own airspeed (the
            # arrivals are timed by the speed): the field
            return replace(state, join_done=True), command, events
        # seats in the order the vehicles sit round the target (their polar angles), as the
        # paper's seat law has it: with the assignment free, every agent would pick the
        # slowest's seat alike but could break the ties of the others' differently (over
        # MAVLink two agents once took the same seat)
        order = sorted(
            range(n),
            key=lambda v: (
                math.atan2(plan_from[v][1] - centre[1], plan_from[v][0] - centre[0]),
                v,
            ),
        )
        try:
            plan = join_plan(
                plan_from,
                centre,
                rd,
                sign,
                env.max_speed_m_s,
                turn_radius,
                wind,
                order=order,
                min_speed_m_s=env.min_speed_m_s,
            )
        except ValueError as exc:  # a wind no seat can be reached against: the field
            state = replace(state, join_done=True)
            return state, command, (AgentEvent(t_s, "join_dropped", str(exc)),)
        paths = tuple(
            _join_path(
                start,
                seat_pose(centre, rd, seat, sign),
                turn_radius,
                env.max_speed_m_s,
                wind,
            )
            for start, seat in zip(plan_from, plan.seat_angles_rad, strict=True)
        )
        join = JoinTarget(index, plan.seat_angles_rad, paths, t_s + plan.time_s)
        detail = (
            f"seat at {math.degrees(join.seat_angle_rad):.0f} deg about the target, joining in "
            f"{plan.time_s:.1f} s (the team's slowest flight), {paths[index].length_m:.0f} m "
            "to fly"
        )
        events = (*events, AgentEvent(t_s, "join_planned", detail))
    # every member's progress, and the team's time
    paths_now = list(join.paths)
    seated = set(join.seated)
    slowest = 0.0
    own_off = 0.0
    for j, start in enumerate(starts):
        path, off = paths_now[j].nearest(start[0], start[1])
        if j == index and off > _JOIN_REPLAN_M:
            goal = seat_pose(centre, rd, join.seats_rad[j], sign)
            path = _join_path(start, goal, turn_radius, env.max_speed_m_s, wind)
            detail = f"{off:.0f} m off its path"
            events = (*events, AgentEvent(t_s, "join_replanned", detail))
            off = 0.0
        paths_now[j] = path
        if j == index:
            own_off = off
        if j in seated:
            continue
        if path.remaining_m() <= 2.0 * params.join_handover_m:
            seated.add(j)
            continue
        slowest = max(slowest, path.remaining_m() / path.speed_m_s)
    join = replace(join, paths=tuple(paths_now), seated=frozenset(seated), t_join_s=t_s + slowest)
    own_path = paths_now[index]
    goal = seat_pose(centre, rd, join.seat_angle_rad, sign)
    to_seat = math.hypot(own.east_m - goal[0], own.north_m - goal[1])
    x, y = own.east_m - centre[0], own.north_m - centre[1]
    along = wrap_pi(0.5 * math.pi - own.course_rad - math.atan2(y, x) - sign * 0.5 * math.pi)
    on_circle = abs(math.hypot(x, y) - rd) <= _JOIN_CIRCLE_M and abs(along) < _JOIN_ALONG
    if (
        on_circle
        or to_seat <= params.join_handover_m
        or own_path.remaining_m() <= params.join_handover_m
    ):
        state = replace(state, join=None, join_done=True)
        detail = (
            f"{to_seat:.0f} m from its seat, {own_off:.0f} m off its path, "
            f"{math.hypot(x, y) - rd:+.1f} m off the circle"
        )
        return state, command, (*events, AgentEvent(t_s, "joined", detail))
    pts, near, step = own_path.points, own_path.progress, own_path.step_m
    last = len(pts) - 1
    speed_now = max(own.speed_m_s, env.min_speed_m_s)
    ahead = max(_JOIN_LOOKAHEAD_S * speed_now, 20.0)
    k = near + round(ahead / step) if step > 0.0 else last
    if k <= last:
        px, py = pts[k][0], pts[k][1]
    else:  # past the end: on along the seat's direction
        beyond = (k - last) * step
        px, py = goal[0] + beyond * math.cos(goal[2]), goal[1] + beyond * math.sin(goal[2])
    wanted = math.atan2(px - own.east_m, py - own.north_m)
    rate = -pts[min(near + 1, last)][3] * speed_now
    left = join.t_join_s - t_s
    remaining = own_path.remaining_m()
    # flat out for the slowest (its own time is the team's), and as much slower for the others
    # as their time to spare asks (in the plan's wind: its mean ground speed for the top one)
    own_time = remaining / own_path.speed_m_s
    speed_wanted = env.max_speed_m_s * own_time / left if left > 0.0 else env.max_speed_m_s
    speed = min(max(speed_wanted, env.min_speed_m_s), env.max_speed_m_s)
    course = course_command(own.course_rad, wanted, rate, agent.course_loop)
    command = replace(
        command,
        course_rad=course,
        speed_m_s=speed,
        field_course_rad=wanted,
        course_rate_ff_rad_s=rate,
    )
    return replace(state, join=join), command, events


def _flown(state: MissionAgentState, target: TargetInfo, params: MissionAgentParams) -> AgentParams:
    """The guidance and phase keeping flown now: ``track`` in the track stage, and in adjust
    once the target is seen moving faster than ``moving_speed_m_s`` (where the ground station
    itself moves on to track); else ``agent``."""
    adjusting = state.stage == "adjust"
    if params.track is None:
        return _lead_held(params.agent) if adjusting else params.agent
    moving = math.hypot(target.v_east_m_s, target.v_north_m_s) > params.moving_speed_m_s
    if state.stage == "track" or (adjusting and moving):
        return params.track
    return _lead_held(params.agent) if adjusting else params.agent


@functools.lru_cache(maxsize=64)
def _lead_held(agent: AgentParams) -> AgentParams:
    """``agent`` with the lead speed held down at any distance outside the circle, and to its
    ``held_lead_turn_share`` of W r_d on it (``PhaseParams.lead_held_outside``): in adjust the
    team has gathered, and a vehicle blown out beyond the lead's 20 m band at 18 m/s (W r_d)
    would find no turn to come back with (twenty vehicles were carried 40-66 m out for 40 s at
    the lead speed), while at W r_d on the circle twenty were pushed 3-8 m out again and again."""
    if agent.phase.lead_speed_m_s is None:
        return agent
    return replace(agent, phase=replace(agent.phase, lead_held_outside=True))


# --- the step every driver pumps ------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class AgentStatus:
    """What the agent reports of its vehicle (m, rad clockwise from north, m/s; ``phase_rad``
    the polar angle about the target as best known, counter-clockwise from east, 0 when none)."""

    t_s: float
    east_m: float
    north_m: float
    course_rad: float
    speed_m_s: float
    phase_rad: float
    stage: Stage
    healthy: bool


@dataclass(frozen=True, slots=True)
class Observed:
    """A camera's (or the ground's) observation of the target."""

    observation: Observation


@dataclass(frozen=True, slots=True)
class Telemetry:
    """The vehicle's own telemetry of time ``t_s``: the status goes out when due."""

    t_s: float
    own: OwnTelemetry


@dataclass(frozen=True, slots=True)
class Control:
    """One control tick on the vehicle's telemetry of time ``t_s`` (``control``)."""

    t_s: float
    own: OwnTelemetry


@dataclass(frozen=True, slots=True)
class HeardFused:
    estimate: GlobalEstimate


@dataclass(frozen=True, slots=True)
class HeardMission:
    """The ground's stage and team; ``t_s`` its time (None: not judged by the agent's clock)."""

    stage: str
    active: tuple[int, ...]
    t_s: float | None = None


@dataclass(frozen=True, slots=True)
class HeardTeammates:
    """Teammates' statuses, (vehicle, fix) in the order heard: those that came since the last
    control tick."""

    fixes: tuple[tuple[int, TeammateFix], ...]


@dataclass(frozen=True, slots=True)
class Hold:
    """Stop (True) or resume (False) commanding the vehicle."""

    holding: bool


AgentInput = Observed | Telemetry | Control | HeardFused | HeardMission | HeardTeammates | Hold


@dataclass(frozen=True, slots=True)
class AgentOutbox:
    """What one step wants sent or recorded: the vehicle ``command`` (None while holding), the
    local ``estimate`` to publish, the vehicle's ``status``, the observation's ``report``
    (used, or why not), the ``stage`` when the step changed it, events, and ``refused``: why
    a message heard was not believed (empty: it was, or there was none); of teammates'
    statuses, ``refused_teammates`` says whose and why, one entry for each refused."""

    command: Command | None = None
    estimate: LocalEstimate | None = None
    status: AgentStatus | None = None
    report: StepReport | None = None
    stage: Stage | None = None
    events: tuple[AgentEvent, ...] = ()
    refused: str = ""
    refused_teammates: tuple[tuple[int, str], ...] = ()


_EMPTY = AgentOutbox()


def step(
    state: MissionAgentState, event: AgentInput, params: MissionAgentParams
) -> tuple[MissionAgentState, AgentOutbox]:
    """Deliver one input to the agent: the new state and what it wants sent or recorded.

    Raises ValueError for a non-finite telemetry frame (``Control``), which must never be
    steered on."""
    match event:
        case Observed(obs):
            state, report = observe(state, obs, params)
            estimate = None
            if report.used and state.estimates.due(obs.t_s):
                estimate = state.local.estimate()
                if estimate is not None:
                    state = replace(state, estimates=state.estimates.sent(obs.t_s))
            return state, AgentOutbox(estimate=estimate, report=report)
        case Telemetry(t, own):
            if not state.statuses.due(t):
                return state, _EMPTY
            status = _status(state, t, own, params)
            own_fix = TeammateFix(
                t, status.east_m, status.north_m, status.course_rad, status.speed_m_s
            )
            state = replace(state, statuses=state.statuses.sent(t))
            return _join_fix(state, params.vehicle, own_fix), AgentOutbox(status=status)
        case Control(t, own):
            if t > state.now_t_s:
                state = replace(state, now_t_s=t)
            state, silent = _ground_silence(state, t, params)
            state, command, events = control(state, t, own, params)
            return state, AgentOutbox(
                command=None if state.holding else command, events=(*silent, *events)
            )
        case HeardFused(estimate):
            state, refused = _hear_fused(state, estimate, params)
            return state, AgentOutbox(refused=refused) if refused else _EMPTY
        case HeardMission(stage, active, t):
            refused = ahead_of_clock(state, t, params) if t is not None else ""
            if refused:
                return state, AgentOutbox(refused=refused)
            before, team = state.stage, state.active
            state = hear_mission(state, stage, active)
            # every agent hears this message alike: the joining is planned from each member's
            # first status after the one that started gather or changed its team
            started = before != Stage.GATHER or state.active != team
            if t is not None and state.stage == Stage.GATHER and started:
                state = _join_started(state, t)
            return state, AgentOutbox(stage=state.stage) if state.stage != before else _EMPTY
        case HeardTeammates(fixes):
            believed: list[tuple[int, TeammateFix]] = []
            refusals: list[tuple[int, str]] = []
            for vehicle, fix in fixes:
                why = ahead_of_clock(state, fix.t_s, params)
                if why:
                    refusals.append((vehicle, why))
                else:
                    believed.append((vehicle, fix))
            state = hear_teammates(state, believed)
            if not refusals:
                return state, _EMPTY
            return state, AgentOutbox(refused=refusals[0][1], refused_teammates=tuple(refusals))
        case Hold(holding):
            return set_holding(state, holding), _EMPTY


def _ground_silence(
    state: MissionAgentState, t_s: float, params: MissionAgentParams
) -> tuple[MissionAgentState, tuple[AgentEvent, ...]]:
    """Hold once the ground station, heard before, has been silent (no fused estimate or
    mission state taken) for ``ground_silent_hold_s`` of the agent's clock."""
    heard = state.ground_heard_t_s
    if heard is None or state.holding or t_s - heard <= params.ground_silent_hold_s:
        return state, ()
    detail = (
        f"nothing believable from the ground station for {t_s - heard:.1f} s "
        f"(limit {params.ground_silent_hold_s:g} s): holding until 'resume'"
    )
    return replace(state, holding=True), (AgentEvent(t_s, "ground_silent", detail),)


def _status(
    state: MissionAgentState, t_s: float, own: OwnTelemetry, params: MissionAgentParams
) -> AgentStatus:
    target = target_at(state, t_s, params)
    phase = (
        0.0
        if target is None
        else math.atan2(own.north_m - target.north_m, own.east_m - target.east_m)
    )
    return AgentStatus(
        t_s,
        own.east_m,
        own.north_m,
        own.course_rad,
        max(own.speed_m_s, 0.0),
        phase,
        state.stage,
        not state.holding,
    )
