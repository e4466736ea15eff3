"""A local filter: an IMM-UKF that takes timestamped observations one at a time, defensively.

``local_step(state, observation, params)`` returns a new state and a report saying what became of
the observation. Observations are asynchronous: the filter predicts to each one's own time.

- invalid (non-finite time, position or sigma; sigma out of range; position beyond
  ``max_abs_position_m``): rejected, the reason in the report, counted; the state is untouched.
- late (older than the filter's time by at most ``max_lag_s``): used, as an observation of the
  current state: the position is carried forward by the estimated velocity over the lag and its
  covariance widened by the velocity uncertainty and the process noise over the lag; counted.
- stale (older than that): dropped, counted.
- outlier (every model's normalised innovation above the chi-square gate): dropped, counted; the
  filter keeps the prediction to the observation's time. After ``max_consecutive_gated`` gated
  observations in a row the filter restarts from the next one (a lost track), counted; the
  caller may refuse that restart on an observation it finds inconsistent (``may_restart``).
- a diverged track (a non-finite state, or a position or its standard deviation beyond
  ``max_abs_position_m``): restarted from the next observation the caller allows, counted.
  Seen once in a run of twenty vehicles: one agent's filter ran away over the target's stop
  at D (innovations 1e2 to 1e9 in 8 s), went to NaN and stayed there, and its vehicle was
  steered no more.

A filter that hears nothing can be moved to any later time with ``local_predict``; its
covariance grows with the process noise.
"""

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, cast

import numpy as np
from numpy.typing import NDArray

from app.core.estimation.imm import IMMParams, IMMState, imm_init, imm_predict, imm_update
from app.core.estimation.messages import LocalEstimate, Observation
from app.core.estimation.models import POS, STATE_DIM
from app.core.values import replace

FloatArray = NDArray[np.float64]

RECENT_KEPT = 20
"""How many used observations a local filter keeps for replay after a late allocation."""

_NOT_YET = object()  # LocalState's estimate, before it is first asked for

Outcome = Literal["initialised", "updated", "late", "stale", "invalid", "gated", "restarted"]


@dataclass(frozen=True, slots=True)
class LocalParams:
    """Everything a local filter needs besides its state.

    Parameters
    ----------
    imm
        Models, mode-transition matrix, sigma points.
    default_sigma_m
        Per-axis standard deviation of an observation that carries none, m.
    gate_nis
        Chi-square gate on the normalised innovation (2 dof); 18.42 is the 0.9999 quantile.
    max_consecutive_gated
        After this many gated observations in a row the filter restarts.
    max_lag_s
        Out-of-order observations up to this much older than the filter are used; older: dropped.
    max_abs_position_m
        Observations farther than this from the origin are absurd.
    min_sigma_m, max_sigma_m
        Accepted range of an observation's sigma, m.
    init_speed_sigma_m_s, init_accel_sigma_m_s2
        Prior standard deviations of velocity and acceleration at (re)start.
    """

    imm: IMMParams
    default_sigma_m: float = math.sqrt(10.0)
    gate_nis: float = 18.42
    max_consecutive_gated: int = 10
    max_lag_s: float = 1.0
    max_abs_position_m: float = 1.0e6
    min_sigma_m: float = 1.0e-3
    max_sigma_m: float = 1.0e3
    init_speed_sigma_m_s: float = 10.0
    init_accel_sigma_m_s2: float = 1.0

    def __post_init__(self) -> None:
        positive = {
            "default_sigma_m": self.default_sigma_m,
            "gate_nis": self.gate_nis,
            "max_abs_position_m": self.max_abs_position_m,
            "min_sigma_m": self.min_sigma_m,
            "max_sigma_m": self.max_sigma_m,
            "init_speed_sigma_m_s": self.init_speed_sigma_m_s,
            "init_accel_sigma_m_s2": self.init_accel_sigma_m_s2,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        if not (math.isfinite(self.max_lag_s) and self.max_lag_s >= 0.0):
            raise ValueError(f"max_lag_s must be finite and >= 0, got {self.max_lag_s}")
        if self.max_consecutive_gated < 1:
            raise ValueError("max_consecutive_gated must be >= 1")
        if self.min_sigma_m > self.max_sigma_m:
            raise ValueError("min_sigma_m must not exceed max_sigma_m")


@dataclass(frozen=True, slots=True)
class FilterCounters:
    """What became of the observations a filter was given, and of the feedback it received."""

    updated: int = 0
    late_used: int = 0
    stale_dropped: int = 0
    invalid: int = 0
    gated: int = 0
    restarts: int = 0
    feedback: int = 0

    def to_dict(self) -> dict[str, int]:
        return {name: getattr(self, name) for name in self.__slots__}


@dataclass(frozen=True, slots=True)
class LocalState:
    """A local filter between steps.

    Attributes
    ----------
    sensor
        Whose observations it filters (``"all"`` for a centralised filter).
    imm
        The IMM state, ``None`` before the first valid observation.
    counters
        Running counts of outcomes.
    consecutive_gated
        Gated observations since the last accepted one.
    recent
        The last few observations this filter used (at most ``RECENT_KEPT``), so that a
        federated allocation older than the filter can be applied and these replayed on top.
    alloc_t_s
        The time of the fused estimate whose allocation this filter last took (``None``
        before any); its estimates say so, so that the main filter fuses them only with
        copies of that allocation. A track restart keeps it (the restarted filter holds less
        than the allocation, never more).
    """

    sensor: str
    imm: IMMState | None = None
    counters: FilterCounters = field(default_factory=FilterCounters)
    consecutive_gated: int = 0
    recent: tuple[Observation, ...] = ()
    alloc_t_s: float | None = None
    # ``estimate()``, worked out on first use: the agent asks for it on every control tick
    # and status while the state changes only with an observation (not copied by replace)
    _estimate: object = field(default=_NOT_YET, init=False, repr=False, compare=False)

    @property
    def t_s(self) -> float | None:
        return None if self.imm is None else self.imm.t_s

    def estimate(self) -> LocalEstimate | None:
        """The message for the main filter (combined IMM output), or None before any data and
        while the track is non-finite (until ``local_step`` restarts it)."""
        known = self._estimate
        if known is _NOT_YET:
            known = self._combined()
            object.__setattr__(self, "_estimate", known)
        return cast(LocalEstimate | None, known)

    def _combined(self) -> LocalEstimate | None:
        if self.imm is None:
            return None
        imm = self.imm
        x, p = imm.combined()
        if not (np.isfinite(x).all() and np.isfinite(p).all()):
            return None
        return LocalEstimate(
            self.sensor,
            imm.t_s,
            x,
            p,
            imm.mu,
            imm.cov_scale,
            model_x=imm.x,
            model_p=imm.p,
            alloc_t_s=self.alloc_t_s,
        )


@dataclass(frozen=True, slots=True)
class StepReport:
    """What ``local_step`` did with one observation; ``reason`` explains every rejection."""

    outcome: Outcome
    reason: str = ""
    nis: float = math.nan

    @property
    def used(self) -> bool:
        return self.outcome in ("initialised", "updated", "late", "restarted")


def check_observation(obs: Observation, params: LocalParams) -> str:
    """Why ``obs`` cannot be used (empty string: it can)."""
    values = (obs.t_s, obs.east_m, obs.north_m)
    if not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
        return f"non-finite time or position (t={obs.t_s!r}, e={obs.east_m!r}, n={obs.north_m!r})"
    if math.hypot(obs.east_m, obs.north_m) > params.max_abs_position_m:
        return (
            f"position ({obs.east_m:.6g}, {obs.north_m:.6g}) m is beyond "
            f"{params.max_abs_position_m:g} m of the origin"
        )
    if obs.sigma_m is not None:
        s = obs.sigma_m
        if not (math.isfinite(s) and params.min_sigma_m <= s <= params.max_sigma_m):
            return f"sigma {s!r} m outside [{params.min_sigma_m:g}, {params.max_sigma_m:g}] m"
    return ""


def _noise(obs: Observation, params: LocalParams) -> FloatArray:
    sigma = params.default_sigma_m if obs.sigma_m is None else obs.sigma_m
    return np.diag([sigma * sigma, sigma * sigma])


def _start(obs: Observation, r: FloatArray, params: LocalParams) -> IMMState:
    x0 = np.array([obs.east_m, 0.0, obs.north_m, 0.0, 0.0, 0.0])
    v2, a2 = params.init_speed_sigma_m_s**2, params.init_accel_sigma_m_s2**2
    p0 = np.diag([r[0, 0], v2, r[1, 1], v2, a2, a2])
    return imm_init(obs.t_s, x0, p0, params.imm)


def local_predict(state: LocalState, t_s: float, params: LocalParams) -> LocalState:
    """The filter moved to a later time ``t_s`` with no observation (IMM prediction only).

    Earlier times return the state unchanged (a filter never runs backwards).
    """
    if state.imm is None or not t_s > state.imm.t_s:
        return state
    return replace(state, imm=imm_predict(state.imm, t_s, params.imm))


def local_step(
    state: LocalState,
    obs: Observation,
    params: LocalParams,
    *,
    may_restart: Callable[[Observation], bool] | None = None,
) -> tuple[LocalState, StepReport]:
    """Take one observation: validate, predict to its time, gate, update (Appendix B).

    Returns the new state and a report; the input state is never modified, and a rejected
    observation leaves the returned state equal to the input apart from the counters.
    ``may_restart``: whether a lost track may restart on this observation (the agent asks the
    team's fused estimate; a burst of forged fixes must not become the track); None: always.
    """
    counters = state.counters
    problem = check_observation(obs, params)
    if problem:
        counters = replace(counters, invalid=counters.invalid + 1)
        return replace(state, counters=counters), StepReport("invalid", problem)
    r = _noise(obs, params)
    z = np.array([obs.east_m, obs.north_m])
    if state.imm is None:
        new = replace(state, imm=_start(obs, r, params), consecutive_gated=0, recent=(obs,))
        return new, StepReport("initialised")
    diverged = _diverged(state.imm, params)
    if diverged:
        if may_restart is not None and not may_restart(obs):
            counters = replace(counters, gated=counters.gated + 1)
            return replace(state, counters=counters), StepReport("gated", diverged)
        counters = replace(counters, restarts=counters.restarts + 1)
        fresh = _start(obs, r, params)
        new = replace(state, imm=fresh, counters=counters, consecutive_gated=0, recent=(obs,))
        return new, StepReport("restarted", diverged)

    lag = state.imm.t_s - obs.t_s
    if lag > params.max_lag_s:
        counters = replace(counters, stale_dropped=counters.stale_dropped + 1)
        reason = f"{lag:.3f} s older than the filter (limit {params.max_lag_s:g} s)"
        return replace(state, counters=counters), StepReport("stale", reason)
    if lag > 0.0:
        predicted = state.imm
        z, r = _carry_forward(state.imm, z, r, lag, params)
    else:
        predicted = imm_predict(state.imm, obs.t_s, params.imm)

    result = imm_update(predicted, z, r)
    nis = float(np.min(result.nis))
    if not (nis <= params.gate_nis):
        if (
            lag <= 0.0
            and state.consecutive_gated + 1 >= params.max_consecutive_gated
            and (may_restart is None or may_restart(obs))
        ):
            counters = replace(counters, restarts=counters.restarts + 1)
            fresh = _start(obs, _noise(obs, params), params)
            new = replace(state, imm=fresh, counters=counters, consecutive_gated=0, recent=(obs,))
            return new, StepReport("restarted", "track lost: too many gated observations", nis)
        counters = replace(counters, gated=counters.gated + 1)
        reason = f"innovation NIS {nis:.3g} above the gate {params.gate_nis:g}"
        gated = state.consecutive_gated + 1
        new = replace(state, imm=predicted, counters=counters, consecutive_gated=gated)
        return new, StepReport("gated", reason, nis)

    if lag > 0.0:
        counters = replace(counters, late_used=counters.late_used + 1)
        outcome: Outcome = "late"
    else:
        counters = replace(counters, updated=counters.updated + 1)
        outcome = "updated"
    recent = (*state.recent[-(RECENT_KEPT - 1) :], obs)
    new = replace(state, imm=result.state, counters=counters, consecutive_gated=0, recent=recent)
    return new, StepReport(outcome, "", nis)


def _diverged(imm: IMMState, params: LocalParams) -> str:
    """Why the track is beyond use (empty string: it is not): non-finite, or a position or
    its standard deviation beyond ``max_abs_position_m``."""
    x, p, mu = imm.x, imm.p, imm.mu
    if not (np.isfinite(x).all() and np.isfinite(p).all() and np.isfinite(mu).all()):
        return "track diverged: non-finite state or covariance"
    limit = params.max_abs_position_m
    if not np.abs(x[:, POS]).max() <= limit:
        return f"track diverged: position beyond {limit:g} m"
    if not p[:, POS, POS].max() <= limit * limit:
        return f"track diverged: position uncertainty beyond {limit:g} m"
    return ""


def _carry_forward(
    imm: IMMState, z: FloatArray, r: FloatArray, lag_s: float, params: LocalParams
) -> tuple[FloatArray, FloatArray]:
    """An observation ``lag_s`` old as an observation of the current state (an approximation).

    z' = z + v_hat * lag, R' = R + lag^2 P_vv + the CV process noise over the lag, with v_hat and
    P_vv the combined velocity estimate and covariance.
    """
    x, p = imm.combined()
    vel = [1, 3]
    z_now = z + x[vel] * lag_s
    q = max(m.noise_intensity for m in params.imm.models)
    growth = q * lag_s**3 / 3.0
    r_now = r + lag_s * lag_s * p[np.ix_(vel, vel)] + growth * np.eye(2)
    return z_now, 0.5 * (r_now + r_now.T)


def initial_state(sensor: str) -> LocalState:
    """A local filter that has heard nothing yet."""
    return LocalState(sensor=sensor)


__all__ = [
    "STATE_DIM",
    "FilterCounters",
    "LocalParams",
    "LocalState",
    "Outcome",
    "StepReport",
    "check_observation",
    "initial_state",
    "local_predict",
    "local_step",
]
