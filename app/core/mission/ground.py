"""The ground station's mission logic, pure: who flies, the fused target estimate, the stage.

Mission time is the vehicles' own time, as their statuses carry it: the newest status time seen.
A vehicle whose newest status is more than ``lost_after_s`` of mission time behind (it stopped
answering), or that reports its link lost or itself unhealthy, leaves the active team; it rejoins
when it reports healthy again. No wall clock is read, so the logic is the same at any speed-up.

When the local estimates stop (no observations: every camera lost the target), the fused
estimate coasts: it is predicted forward at constant velocity with a growing covariance, so the
team keeps orbiting where the target should be.

``step`` is the one entry for every driver: statuses and local estimates in, a ``GroundOutbox``
out (the fused estimate, the ``MissionUpdate`` when due, the recorded ``TeamSample``, events).
When the station ticks and when it announces the mission state ("on change or every period")
is part of the state (``GroundState.ticks``, ``.announcements``).
"""

import math
from dataclasses import dataclass, field

import numpy as np

from app.core.estimation.federated import (
    MainParams,
    MainState,
    main_allocate,
    main_fuse,
    main_receive,
    time_update,
)
from app.core.estimation.messages import GlobalEstimate, LocalEstimate
from app.core.estimation.models import MotionModel
from app.core.frames import TAU
from app.core.mission.schedule import Every, following_slot, slot_due
from app.core.mission.stage import Stage, StageParams, StageState, TeamView, next_stage
from app.core.mission.team import TeamSample, VehicleSample, dead_reckon
from app.core.target import TargetMotion
from app.core.values import replace


@dataclass(frozen=True, slots=True)
class VehicleReport:
    """The newest status of one vehicle (m, rad clockwise from north, m/s; ``up_m`` its height
    about the origin, None where its status has none)."""

    t_s: float
    east_m: float
    north_m: float
    course_rad: float
    speed_m_s: float
    link_ok: bool = True
    healthy: bool = True
    up_m: float | None = None


@dataclass(frozen=True, slots=True)
class GroundParams:
    """``vehicles``: the team as launched (ids). ``tracking_command_t_s``: when the team is
    sent from standby to track (mission time). ``fuse_period_s``: how often the main filter
    fuses: at the first tick after new local estimates came, at most once a period (less the
    early allowance of ``schedule.slot_due``), so the fusion follows the estimates' rounds
    rather than a grid of its own that may fall a tick after them; with none new, a period and
    a half after the last (a round a tick late is still waited for). ``feedback_period_s``:
    how often at most a fused estimate goes out as an information allocation (the others go
    out with no shares, to steer by); longer than the
    round trip to the agents, since the main filter drops the estimates built on the
    allocation before the last (``main_receive``). ``lost_after_s``: mission-time silence
    after which a vehicle leaves the team.
    ``coast_after_s``: once no local estimate has arrived for this long, the fused estimate is
    predicted with ``coast_model`` instead of fused (constant velocity: the acceleration last
    estimated is not extrapolated, which would take the predicted target off at ever higher
    speed; the acceleration states are held). ``prediction_model``: how the fused estimate is
    predicted to a sample's time (the agents' own ``MissionAgentParams.prediction_model``).

    What the station hears cannot push it (issue #14): a status or local estimate stamped more
    than ``max_ahead_s`` ahead of the station's own mission clock (``clock_t_s`` of the input;
    without one, of the mission time so far, unless another vehicle claims about the same
    time: the team back from an outage), or more than ``max_behind_s`` behind it, is refused
    and counted, and mission time never passes that clock. A local estimate whose
    position the fused estimate (predicted to its time) finds further off than
    ``local_gate_nis`` (position NIS over the sum of both covariances) is refused as an
    outlier while the fusion is live (some estimate taken within ``coast_after_s``), as is one
    of the wrong shape (per-model moments that are not the main filter's models). So is a
    diverged filter's: a state beyond ``max_abs_state`` (m, m/s, m/s^2), or, while the fusion
    is live, a position covariance more than ``max_uncertainty_ratio`` times the fused one's.
    The outlier gate alone lets such an estimate through (its covariance swallows any
    distance), and one did: an agent whose track had run away to 1e36 m took the fused
    estimate with it, and then every other agent's estimate was refused as an outlier."""

    vehicles: tuple[int, ...]
    radius_m: float
    tracking_command_t_s: float
    main: MainParams = field(default_factory=MainParams)
    stages: StageParams = field(default_factory=StageParams)
    fuse_period_s: float = 0.2
    feedback_period_s: float = 1.0
    lost_after_s: float = 2.0
    coast_after_s: float = 1.0
    coast_model: MotionModel = field(default_factory=lambda: MotionModel("cv", 0.05))
    prediction_model: MotionModel = field(default_factory=lambda: MotionModel("cv", 0.05))
    max_ahead_s: float = 2.0
    max_behind_s: float = 30.0
    local_gate_nis: float = 50.0
    max_abs_state: float = 1.0e6
    max_uncertainty_ratio: float = 1.0e4

    def __post_init__(self) -> None:
        for name in (
            "max_ahead_s",
            "max_behind_s",
            "local_gate_nis",
            "max_abs_state",
            "max_uncertainty_ratio",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if not self.vehicles or len(set(self.vehicles)) != len(self.vehicles):
            raise ValueError(f"vehicles must be unique and non-empty, got {self.vehicles}")
        for name in (
            "radius_m",
            "fuse_period_s",
            "feedback_period_s",
            "lost_after_s",
            "coast_after_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if not math.isfinite(self.tracking_command_t_s):
            raise ValueError("tracking_command_t_s must be finite")


@dataclass(frozen=True, slots=True)
class GroundState:
    reports: tuple[tuple[int, VehicleReport], ...] = ()
    active: tuple[int, ...] = ()
    main: MainState = field(default_factory=MainState)
    fused: GlobalEstimate | None = None
    stage: StageState = field(default_factory=StageState)
    mission_t_s: float = -math.inf
    last_fuse_t_s: float = -math.inf  # when the main filter last fused (or coasted)
    fused_received: int = 0  # the local estimates the main filter had received then
    next_feedback_t_s: float = -math.inf
    last_local_t_s: float = -math.inf  # time of the newest local estimate received
    ticks: Every = field(default_factory=lambda: Every(0.1))
    announcements: Every = field(default_factory=lambda: Every(0.5))
    announced: Stage | None = None  # the stage last announced
    statuses_refused: int = 0  # stamped outside the window of the station's clock
    locals_refused: int = 0  # stamped outside it, of the wrong shape, or outliers
    last_taken_t_s: float = -math.inf  # time of the newest local estimate taken into the fusion
    ahead_claims: tuple[tuple[int, float], ...] = ()  # refused status times, by vehicle

    def report(self, vehicle: int) -> VehicleReport | None:
        return dict(self.reports).get(vehicle)


@dataclass(frozen=True, slots=True)
class GroundEvent:
    t_s: float
    kind: str
    detail: str = ""


def out_of_window(
    state: GroundState, t_s: float, params: GroundParams, clock_t_s: float | None
) -> str:
    """Why a message stamped ``t_s`` is refused as not of now (empty string: it is not):
    non-finite, or outside [clock - ``max_behind_s``, clock + ``max_ahead_s``] of the
    station's own clock (``clock_t_s``; None: the mission time so far, when there is one)."""
    if not math.isfinite(t_s):
        return f"non-finite time {t_s!r}"
    now = clock_t_s if clock_t_s is not None else state.mission_t_s
    if not math.isfinite(now):
        return ""
    if t_s > now + params.max_ahead_s:
        limit = params.max_ahead_s
        return f"stamped {t_s - now:.3g} s ahead of the station's clock (limit {limit:g} s)"
    if t_s < now - params.max_behind_s:
        limit = params.max_behind_s
        return f"stamped {now - t_s:.3g} s behind the station's clock (limit {limit:g} s)"
    return ""


def hear_status(
    state: GroundState,
    vehicle: int,
    report: VehicleReport,
    params: GroundParams | None = None,
    clock_t_s: float | None = None,
) -> GroundState:
    """Keep a vehicle's newest report and advance mission time (older reports are ignored);
    with ``params``, one outside the window of the station's clock is refused and counted, and
    mission time goes no further than ``clock_t_s``."""
    if (
        params is not None
        and out_of_window(state, report.t_s, params, clock_t_s)
        and (clock_t_s is not None or not _corroborated(state, vehicle, report.t_s, params))
    ):
        claims = dict(state.ahead_claims)
        claims[vehicle] = report.t_s
        return replace(
            state,
            statuses_refused=state.statuses_refused + 1,
            ahead_claims=tuple(sorted(claims.items())),
        )
    held = dict(state.reports)
    old = held.get(vehicle)
    if old is not None and report.t_s < old.t_s:
        return state
    held[vehicle] = report
    t = report.t_s if clock_t_s is None else min(report.t_s, clock_t_s)
    return replace(
        state, reports=tuple(sorted(held.items())), mission_t_s=max(state.mission_t_s, t)
    )


def _corroborated(state: GroundState, vehicle: int, t_s: float, params: GroundParams) -> bool:
    """Without a clock of its own the station takes a jump of mission time only when another
    vehicle claims about the same time (all of them coming back after an outage; one liar
    cannot push it), or when it flies a single vehicle (nothing to check it against)."""
    if len(params.vehicles) == 1 and math.isfinite(t_s):
        return True
    return any(v != vehicle and abs(t - t_s) <= params.max_ahead_s for v, t in state.ahead_claims)


def check_local(state: GroundState, estimate: LocalEstimate, params: GroundParams) -> str:
    """Why the station does not take local estimate ``estimate`` into the fusion (empty
    string: it does): the wrong shape, non-finite, or an outlier against the live fusion."""
    x, p = np.asarray(estimate.x), np.asarray(estimate.p)
    if x.shape != (6,) or p.shape != (6, 6) or not (np.isfinite(x).all() and np.isfinite(p).all()):
        return "state or covariance of the wrong shape or non-finite"
    if not np.all(np.abs(x) <= params.max_abs_state):
        return f"state beyond {params.max_abs_state:g}: a diverged track"
    moments = (estimate.mu, estimate.model_x, estimate.model_p)
    models = params.main.imm.models if params.main.imm is not None else None
    if any(m is not None and np.size(m) > 0 for m in moments):
        r = len(models) if models is not None else np.shape(estimate.mu)[0]
        shapes = [np.shape(m) if m is not None else None for m in moments]
        if shapes != [(r,), (r, 6), (r, 6, 6)]:
            return f"per-model moments {shapes} that are not the main filter's {r} models"
        if not all(np.isfinite(m).all() for m in moments if m is not None):
            return "non-finite per-model moments"
    fused = state.fused
    live = estimate.t_s - state.last_taken_t_s <= params.coast_after_s
    if fused is None or not live:
        return ""
    model = params.prediction_model
    dt = estimate.t_s - fused.t_s
    f = model.transition(dt)
    xf, pf = f @ fused.x, f @ fused.p @ f.T + model.process_noise(abs(dt))
    pos = np.ix_((0, 2), (0, 2))
    if not np.trace(p[pos]) <= params.max_uncertainty_ratio * np.trace(pf[pos]):
        return (
            f"position covariance over {params.max_uncertainty_ratio:g} times the fused "
            "estimate's: a lost track"
        )
    d = np.array([x[0] - xf[0], x[2] - xf[2]])
    s = pf[pos] + p[pos]
    try:
        c = np.linalg.cholesky(0.5 * (s + s.T))
    except np.linalg.LinAlgError:
        return "covariance not positive definite"
    w = np.linalg.solve(c, d)
    nis = float(w @ w)
    if not nis <= params.local_gate_nis:
        return (
            f"{math.hypot(d[0], d[1]):.3g} m from the fused estimate "
            f"(NIS {nis:.3g} above {params.local_gate_nis:g})"
        )
    return ""


def hear_local(
    state: GroundState,
    estimate: LocalEstimate,
    params: GroundParams | None = None,
    clock_t_s: float | None = None,
) -> GroundState:
    """Take a local estimate into the main filter; with ``params``, one outside the window of
    the station's clock, of the wrong shape or an outlier (``check_local``) is refused."""
    if params is not None:
        refused = out_of_window(state, estimate.t_s, params, clock_t_s) or check_local(
            state, estimate, params
        )
        if refused:
            return replace(state, locals_refused=state.locals_refused + 1)
    return replace(
        state,
        main=main_receive(state.main, estimate),
        last_local_t_s=max(state.last_local_t_s, estimate.t_s),
        last_taken_t_s=max(state.last_taken_t_s, estimate.t_s),
    )


def coast(fused: GlobalEstimate, t_s: float, model: MotionModel) -> GlobalEstimate:
    """The fused estimate predicted to ``t_s`` with no new information: F x, F P F^T + Q
    (per model too, when the fusion was model by model); the shares are kept."""
    dt = t_s - fused.t_s
    if dt <= 0.0:
        return fused
    x, p = time_update(fused.x, fused.p, dt, model)
    model_x, model_p = fused.model_x, fused.model_p
    if model_x is not None and model_p is not None:
        f, q = model.transition(dt), model.process_noise(dt)
        model_x = model_x @ f.T
        model_p = f @ model_p @ f.T + q
        model_p = 0.5 * (model_p + model_p.swapaxes(-1, -2))
    return replace(fused, t_s=float(t_s), x=x, p=p, model_x=model_x, model_p=model_p)


def _active(state: GroundState, params: GroundParams) -> tuple[int, ...]:
    now = state.mission_t_s
    reports = dict(state.reports)
    return tuple(
        v
        for v in params.vehicles
        if (r := reports.get(v)) is not None
        and r.link_ok
        and r.healthy
        and now - r.t_s <= params.lost_after_s
    )


def team_view(state: GroundState, params: GroundParams) -> TeamView:
    """Distances to the circle and polar angles of the active team about the fused estimate."""
    if state.fused is None:
        return TeamView((), (), 0.0)
    te, tn = state.fused.position_m
    ve, vn = state.fused.velocity_m_s
    reports = dict(state.reports)
    dist, angles = [], []
    for v in state.active:
        r = reports[v]
        e, n = dead_reckon(r.east_m, r.north_m, r.course_rad, r.speed_m_s, state.fused.t_s - r.t_s)
        dist.append(math.hypot(e - te, n - tn) - params.radius_m)
        angles.append(math.atan2(n - tn, e - te) % TAU)
    return TeamView(tuple(dist), tuple(angles), math.hypot(ve, vn))


def tick(
    state: GroundState, params: GroundParams
) -> tuple[GroundState, GlobalEstimate | None, tuple[GroundEvent, ...]]:
    """At the current mission time: update the active team, fuse when due, advance the stage.

    Returns the new state, the fused estimate to publish (None when not due or nothing to fuse;
    with no shares when it is not an allocation, see ``feedback_period_s``) and events
    (vehicles leaving or rejoining, stage changes).
    """
    t = state.mission_t_s
    events: list[GroundEvent] = []
    active = _active(state, params)
    for v in set(state.active) - set(active):
        events.append(GroundEvent(t, "vehicle_left", f"vehicle {v + 1} left the formation"))
    for v in set(active) - set(state.active):
        events.append(GroundEvent(t, "vehicle_joined", f"vehicle {v + 1} is in the formation"))
    state = replace(state, active=active)
    fused = published = None
    period = params.fuse_period_s
    since = t - state.last_fuse_t_s
    fresh = state.main.received > state.fused_received
    if slot_due(since, period, period) and (fresh or slot_due(since, 1.5 * period, period)):
        if state.fused is not None and t - state.last_local_t_s > params.coast_after_s:
            fused = coast(state.fused, t, params.coast_model)
        else:
            fused = main_fuse(state.main, t, params.main)
        main, next_feedback, published = state.main, state.next_feedback_t_s, fused
        if fused is not None:
            if slot_due(t, next_feedback, params.feedback_period_s):
                main = main_allocate(state.main, fused, params.main)
                next_feedback = following_slot(next_feedback, t, params.feedback_period_s)
            else:
                published = replace(fused, beta=(), included_t_s=())
        state = replace(
            state,
            main=main,
            fused=fused if fused is not None else state.fused,
            # an empty fusion (no estimate yet) sets no time: the first is the first round's
            last_fuse_t_s=t if fused is not None else state.last_fuse_t_s,
            fused_received=state.main.received,
            next_feedback_t_s=next_feedback,
        )
    commanded = t >= params.tracking_command_t_s
    new_stage = next_stage(state.stage, t, commanded, team_view(state, params), params.stages)
    if new_stage.stage is not state.stage.stage:
        events.append(GroundEvent(t, "stage", new_stage.stage.value))
    return replace(state, stage=new_stage), published, tuple(events)


def desired_spacing_rad(state: GroundState) -> float:
    return TAU / max(1, len(state.active))


# --- the step every driver pumps ------------------------------------------------------------


def initial_ground_state(tick_period_s: float = 0.1, mission_period_s: float = 0.5) -> GroundState:
    """A fresh station that ticks at most every ``tick_period_s`` of mission time (0: on every
    batch of statuses) and announces the mission state on a change of stage or every
    ``mission_period_s``."""
    return GroundState(ticks=Every(tick_period_s), announcements=Every(mission_period_s))


@dataclass(frozen=True, slots=True)
class HeardStatuses:
    """The newest statuses of one or more vehicles, heard at once; ``clock_t_s``: the
    station's own mission clock when they were heard (None: it has none, and judges them by
    the mission time so far)."""

    reports: tuple[tuple[int, VehicleReport], ...]
    clock_t_s: float | None = None


@dataclass(frozen=True, slots=True)
class HeardLocal:
    estimate: LocalEstimate
    clock_t_s: float | None = None


GroundInput = HeardStatuses | HeardLocal


@dataclass(frozen=True, slots=True)
class MissionUpdate:
    """The stage and the active team, and the phase spacing they are to keep (rad)."""

    t_s: float
    stage: Stage
    active: tuple[int, ...]
    spacing_rad: float


@dataclass(frozen=True, slots=True)
class GroundOutbox:
    """What one step wants sent or recorded. ``tick_t_s``: the mission time of the tick this
    step ran (None: no tick); then ``fused`` to publish (None when not due), ``mission`` when
    due, the ``sample`` recorded (None with neither truth nor estimate) and events."""

    tick_t_s: float | None = None
    fused: GlobalEstimate | None = None
    mission: MissionUpdate | None = None
    sample: TeamSample | None = None
    events: tuple[GroundEvent, ...] = ()
    refused: bool = False  # the input was refused (``GroundState.*_refused`` count it)


_EMPTY = GroundOutbox()
_REFUSED = GroundOutbox(refused=True)


def step(
    state: GroundState, event: GroundInput, params: GroundParams, truth: TargetMotion | None = None
) -> tuple[GroundState, GroundOutbox]:
    """Deliver one input to the station; statuses that take mission time to the next tick
    run it (``tick``). Samples are scored against ``truth`` when given, else the orbit is
    scored about the estimate."""
    match event:
        case HeardLocal(estimate, clock):
            refused = state.locals_refused
            state = hear_local(state, estimate, params, clock)
            return state, _REFUSED if state.locals_refused > refused else _EMPTY
        case HeardStatuses(reports, clock):
            refused = state.statuses_refused
            for vehicle, report in reports:
                state = hear_status(state, vehicle, report, params, clock)
            if state.statuses_refused > refused:
                return state, _REFUSED
    t = state.mission_t_s
    if not state.ticks.due(t):
        return state, _EMPTY
    state = replace(state, ticks=state.ticks.sent(t))
    state, fused, events = tick(state, params)
    mission = None
    stage = state.stage.stage
    if stage is not state.announced or state.announcements.due(t):
        state = replace(state, announced=stage, announcements=state.announcements.sent(t))
        mission = MissionUpdate(t, stage, state.active, desired_spacing_rad(state))
    sample = team_sample(state, t, params, truth)
    return state, GroundOutbox(t, fused, mission, sample, events)


def estimate_at(
    state: GroundState, t_s: float, params: GroundParams
) -> tuple[float, float, float, float] | None:
    """The fused estimate predicted to ``t_s`` as (east, north, v_east, v_north); None before
    the first."""
    fused = state.fused
    if fused is None:
        return None
    x = params.prediction_model.transition(t_s - fused.t_s) @ fused.x
    return float(x[0]), float(x[2]), float(x[1]), float(x[3])


def team_sample(
    state: GroundState, t_s: float, params: GroundParams, truth: TargetMotion | None = None
) -> TeamSample | None:
    """The team at ``t_s`` (each vehicle dead-reckoned from its newest report, at most
    ``lost_after_s`` past it: a vehicle silent for longer is shown where it was last known, not
    flown on for minutes) and the target: the true one when ``truth`` is given, else the
    estimate (None before there is one)."""
    estimate = estimate_at(state, t_s, params)
    if truth is not None:
        true = truth.state_at(t_s)
        segment = truth.segment_at(t_s)
        target = (true.east_m, true.north_m, true.v_east_m_s, true.v_north_m_s)
    elif estimate is not None:
        # no truth: the orbit is scored about the estimate, which has nothing to be scored
        # against itself (an estimation error here would read 0)
        segment, target, estimate = "estimated", estimate, None
    else:
        return None
    active = set(state.active)
    vehicles = tuple(
        VehicleSample(
            v,
            v in active,
            *dead_reckon(
                r.east_m,
                r.north_m,
                r.course_rad,
                r.speed_m_s,
                min(t_s - r.t_s, params.lost_after_s),
            ),
            r.speed_m_s,
            r.course_rad,
            r.up_m,
        )
        for v, r in state.reports
    )
    return TeamSample(t_s, state.stage.stage.value, segment, *target, estimate, vehicles)
