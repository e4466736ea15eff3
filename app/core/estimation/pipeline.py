"""The federated estimator as one pure step, and batch runs over an observation sequence.

``federated_step`` routes an observation to its sensor's local filter, passes the local estimate
to the main filter, fuses at the observation's time and, once every ``feedback_period_s``,
shares the information back (Appendix A). In a live mission the same pieces run in different
processes (``local_step`` on each vehicle, ``main_receive``/``main_fuse`` at the ground station,
``apply_feedback`` on receipt); here they run in one loop. ``run_centralised`` is the reference:
one IMM-UKF that sees every observation.
"""

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from app.core.estimation.federated import (
    MainParams,
    MainState,
    apply_feedback,
    main_allocate,
    main_fuse,
    main_receive,
)
from app.core.estimation.local import (
    FilterCounters,
    LocalParams,
    LocalState,
    StepReport,
    local_step,
)
from app.core.estimation.messages import GlobalEstimate, Observation
from app.core.values import replace

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class FederatedParams:
    """Local filters' and main filter's parameters, and how often information is shared back."""

    local: LocalParams
    main: MainParams = field(default_factory=MainParams)
    feedback_period_s: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.feedback_period_s) and self.feedback_period_s >= 0.0):
            raise ValueError(f"feedback_period_s must be >= 0, got {self.feedback_period_s}")
        if self.main.imm is None:
            object.__setattr__(self, "main", replace(self.main, imm=self.local.imm))


@dataclass(frozen=True, slots=True)
class FederatedState:
    """All local filters (in order of first appearance) and the main filter."""

    locals: tuple[LocalState, ...] = ()
    main: MainState = field(default_factory=MainState)
    last_feedback_t_s: float = -math.inf

    def local(self, sensor: str) -> LocalState | None:
        for s in self.locals:
            if s.sensor == sensor:
                return s
        return None


def federated_step(
    state: FederatedState, obs: Observation, params: FederatedParams
) -> tuple[FederatedState, StepReport, GlobalEstimate | None]:
    """One observation through the federated filter.

    Returns the new state, what the observation's local filter did with it, and the fused
    estimate at the observation's time (None when the time is not finite or nothing is fused).
    """
    local = state.local(obs.sensor) or LocalState(sensor=obs.sensor)
    local, report = local_step(local, obs, params.local)
    locals_ = _with(state.locals, local)
    main = state.main
    if report.used:
        estimate = local.estimate()
        if estimate is not None:
            main = main_receive(main, estimate)
    fused = main_fuse(main, obs.t_s, params.main) if math.isfinite(obs.t_s) else None
    last = state.last_feedback_t_s
    if (
        fused is not None
        and params.main.feedback != "none"
        and report.used
        and fused.t_s - last >= params.feedback_period_s - 1e-9
    ):
        locals_ = tuple(apply_feedback(s, fused, params.local, params.main) for s in locals_)
        main = main_allocate(main, fused, params.main)
        last = fused.t_s
    return FederatedState(locals_, main, last), report, fused


def _with(states: tuple[LocalState, ...], new: LocalState) -> tuple[LocalState, ...]:
    if any(s.sensor == new.sensor for s in states):
        return tuple(new if s.sensor == new.sensor else s for s in states)
    return (*states, new)


@dataclass(frozen=True, slots=True)
class EstimateTrack:
    """Estimates at a sequence of times: t (n,), x (n, 6), p (n, 6, 6)."""

    t_s: FloatArray
    x: FloatArray
    p: FloatArray

    @classmethod
    def from_lists(
        cls, times: list[float], xs: list[FloatArray], ps: list[FloatArray]
    ) -> "EstimateTrack":
        if not times:
            return cls(np.zeros(0), np.zeros((0, 6)), np.zeros((0, 6, 6)))
        return cls(np.array(times), np.stack(xs), np.stack(ps))


@dataclass(frozen=True, slots=True)
class RunResult:
    """A batch run: the output track, per-sensor local tracks, every report, final counters."""

    fused: EstimateTrack
    local_tracks: dict[str, EstimateTrack]
    reports: tuple[StepReport, ...]
    counters: dict[str, FilterCounters]


def run_federated(observations: Iterable[Observation], params: FederatedParams) -> RunResult:
    """Run the federated filter over observations in arrival order; an output at each one whose
    time is finite and fusable (the first ones, before any filter starts, may give none)."""
    state = FederatedState()
    times: list[float] = []
    xs: list[FloatArray] = []
    ps: list[FloatArray] = []
    local_rows: dict[str, tuple[list[float], list[FloatArray], list[FloatArray]]] = {}
    reports: list[StepReport] = []
    for obs in observations:
        state, report, fused = federated_step(state, obs, params)
        reports.append(report)
        if fused is not None:
            times.append(fused.t_s)
            xs.append(np.asarray(fused.x))
            ps.append(np.asarray(fused.p))
        if report.used:
            local = state.local(obs.sensor)
            est = local.estimate() if local is not None else None
            if est is not None:
                rows = local_rows.setdefault(obs.sensor, ([], [], []))
                rows[0].append(est.t_s)
                rows[1].append(np.asarray(est.x))
                rows[2].append(np.asarray(est.p))
    return RunResult(
        fused=EstimateTrack.from_lists(times, xs, ps),
        local_tracks={k: EstimateTrack.from_lists(*v) for k, v in local_rows.items()},
        reports=tuple(reports),
        counters={s.sensor: s.counters for s in state.locals},
    )


def run_centralised(
    observations: Iterable[Observation], params: LocalParams, sensor: str = "all"
) -> RunResult:
    """One IMM-UKF fed every observation (the reference the federated filter is measured by)."""
    state = LocalState(sensor=sensor)
    times: list[float] = []
    xs: list[FloatArray] = []
    ps: list[FloatArray] = []
    reports: list[StepReport] = []
    for obs in observations:
        state, report = local_step(state, replace(obs, sensor=sensor), params)
        reports.append(report)
        est = state.estimate()
        if est is not None and report.used:
            times.append(est.t_s)
            xs.append(np.asarray(est.x))
            ps.append(np.asarray(est.p))
    track = EstimateTrack.from_lists(times, xs, ps)
    return RunResult(track, {sensor: track}, tuple(reports), {sensor: state.counters})
