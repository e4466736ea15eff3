"""Interacting multiple model filter over unscented Kalman filters (IMM-UKF, Appendix B).

State: r model-conditioned means and covariances plus the mode probabilities mu, as one frozen
value. ``imm_predict`` does Appendix B steps 1-2 (interaction, model prediction) to a time,
``imm_update`` steps 2-4 (model update, mode probabilities, output) with one position
observation. Both return a new state and leave their inputs alone.

Time steps vary (observations are asynchronous), so the mode-transition matrix is given for a
reference step ``transition_dt_s``; for a step dt the matrix used is M^k (I + (M - I) f) with
dt / transition_dt_s = k + f, which is M at the reference step, I at dt = 0 (several observations
at one instant do not switch modes) and always a stochastic matrix.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from app.core.estimation.linalg import ensure_spd, symmetrise
from app.core.estimation.models import STATE_DIM, MotionModel
from app.core.estimation.ukf import SigmaPoints, position_update, unscented_predict

FloatArray = NDArray[np.float64]

_MAX_TRANSITION_POWER = 10_000
_MU_FLOOR = 1e-12


@dataclass(frozen=True, slots=True, eq=False)
class IMMParams:
    """The models and the Markov chain that switches between them.

    Parameters
    ----------
    models
        r >= 1 motion models (eqs 16-21).
    transition
        Mode-transition matrix p_ij = P(model j next | model i now) over ``transition_dt_s``,
        shape (r, r), rows summing to 1.
    transition_dt_s
        The step the matrix is given for, s.
    sigma
        Sigma-point scheme of the model filters.
    """

    models: tuple[MotionModel, ...]
    transition: FloatArray
    transition_dt_s: float = 0.1
    sigma: SigmaPoints = field(default_factory=SigmaPoints)
    # memo of transition_for (a pure function of dt); not part of the value
    _cache: dict[float, FloatArray] = field(
        default_factory=dict, init=False, repr=False, compare=False, hash=False
    )

    def __post_init__(self) -> None:
        r = len(self.models)
        if r < 1:
            raise ValueError("an IMM needs at least one model")
        m = np.array(self.transition, dtype=np.float64)
        if m.shape != (r, r):
            raise ValueError(f"transition must have shape ({r}, {r}), got {m.shape}")
        if not np.all(np.isfinite(m)) or np.any(m < 0.0):
            raise ValueError("transition probabilities must be finite and >= 0")
        if not np.allclose(m.sum(axis=1), 1.0, atol=1e-9):
            raise ValueError(f"transition rows must sum to 1, got {m.sum(axis=1).tolist()}")
        if not (math.isfinite(self.transition_dt_s) and self.transition_dt_s > 0.0):
            raise ValueError(f"transition_dt_s must be > 0, got {self.transition_dt_s}")
        m = m / m.sum(axis=1, keepdims=True)
        m.setflags(write=False)
        object.__setattr__(self, "transition", m)
        object.__setattr__(self, "models", tuple(self.models))

    @property
    def n_models(self) -> int:
        return len(self.models)

    def transition_for(self, dt_s: float) -> FloatArray:
        """The mode-transition matrix over a step of ``dt_s`` seconds, shape (r, r), read-only."""
        cache: dict[float, FloatArray] = self._cache
        hit = cache.get(dt_s)
        if hit is None:
            if len(cache) > 256:
                cache.clear()
            hit = self._transition_for(dt_s)
            hit.setflags(write=False)
            cache[dt_s] = hit
        return hit

    def _transition_for(self, dt_s: float) -> FloatArray:
        steps = abs(dt_s) / self.transition_dt_s
        if steps == 1.0:
            return self.transition.copy()
        whole = min(int(steps), _MAX_TRANSITION_POWER)
        frac = steps - int(steps) if whole < _MAX_TRANSITION_POWER else 0.0
        r = self.n_models
        out = np.eye(r) + (self.transition - np.eye(r)) * frac
        if whole:
            out = np.linalg.matrix_power(self.transition, whole) @ out
        return out


@dataclass(frozen=True, slots=True)
class IMMState:
    """Model-conditioned estimates at ``t_s``.

    Attributes
    ----------
    t_s
        Time of the estimate, s.
    x
        Model-conditioned means, shape (r, 6), X = [x, vx, y, vy, ax, ay] (m, m/s, m/s^2).
    p
        Model-conditioned covariances, shape (r, 6, 6).
    mu
        Mode probabilities, shape (r,), a distribution.
    cov_scale
        The covariances are this multiple of the filter's own: 1 for a plain filter, beta^-1
        for a local filter that holds a federated share (Appendix A: P_i = beta_i^-1 P_g,
        Q_i = beta_i^-1 Q_g). Prediction scales Q and the mixing spread by it; the mode
        likelihoods undo it.
    """

    t_s: float
    x: FloatArray
    p: FloatArray
    mu: FloatArray
    cov_scale: float = 1.0

    def combined(self) -> tuple[FloatArray, FloatArray]:
        """The IMM output (Appendix B step 4): mean (6,) and covariance (6, 6).

        For a filter holding a federated share the model covariances are in share form and the
        spread of the means is not scaled: scaling it too (the exact share of the combined
        covariance) makes the Frobenius-norm shares beta_i swing with the model disagreement,
        which measured worse (docs/estimation.md)."""
        return combine(self.x, self.p, self.mu)


def combine(
    x: FloatArray, p: FloatArray, mu: FloatArray, spread_scale: float = 1.0
) -> tuple[FloatArray, FloatArray]:
    """Moment-matched mixture: X = sum mu_j X_j, P = sum mu_j (P_j + d_j d_j^T) (Appendix B (4)).

    ``x`` (r, 6), ``p`` (r, 6, 6), ``mu`` (r,); returns new arrays (6,) and (6, 6). The spread
    term is multiplied by ``spread_scale`` (a federated share's beta^-1).
    """
    mean = mu @ x
    d = x - mean
    r, n = x.shape
    spread = (d.T * mu) @ d
    if spread_scale != 1.0:
        spread = spread * spread_scale
    cov = (mu @ p.reshape(r, n * n)).reshape(n, n) + spread
    return mean, 0.5 * (cov + cov.T)


def imm_init(
    t_s: float, x0: FloatArray, p0: FloatArray, params: IMMParams, mu0: FloatArray | None = None
) -> IMMState:
    """Every model filter starts at ``x0`` (6,), ``p0`` (6, 6); mu uniform unless given."""
    r = params.n_models
    mu = np.full(r, 1.0 / r) if mu0 is None else np.asarray(mu0, dtype=np.float64) / np.sum(mu0)
    return IMMState(
        t_s=float(t_s),
        x=np.tile(np.asarray(x0, dtype=np.float64), (r, 1)),
        p=np.tile(symmetrise(np.asarray(p0, dtype=np.float64)), (r, 1, 1)),
        mu=mu,
    )


def imm_predict(state: IMMState, t_s: float, params: IMMParams) -> IMMState:
    """Appendix B steps 1-2 up to time ``t_s``: interaction (mixing) and model prediction.

    c_j = sum_i p_ij mu_i, mu_ij = p_ij mu_i / c_j, X_0j = sum_i mu_ij X_i,
    P_0j = sum_i mu_ij (P_i + (X_i - X_0j)(X_i - X_0j)^T); then each UKF predicts X_0j, P_0j
    with its model over dt = t_s - state.t_s. The returned mu is the predicted c_j.
    ``state.cov_scale`` multiplies every Q and the spread term (a federated share). dt = 0
    returns the state itself.
    """
    dt = float(t_s) - state.t_s
    if dt == 0.0:
        return state
    m = params.transition_for(dt)
    cbar = np.maximum(state.mu @ m, _MU_FLOOR)
    omega = m * state.mu[:, None] / cbar[None, :]  # mu_{i|j}, (r, r)
    x0 = omega.T @ state.x  # (r, 6)
    d = state.x[None, :, :] - x0[:, None, :]  # X_i - X_0j, (j, i, 6)
    spread = (d * omega.T[:, :, None]).swapaxes(1, 2) @ d  # sum_i mu_ij d d^T, (j, 6, 6)
    scale = state.cov_scale
    if scale != 1.0:
        spread = spread * scale
    r, n = state.x.shape
    p0 = (omega.T @ state.p.reshape(r, n * n)).reshape(r, n, n) + spread
    x_pred, p_pred = unscented_predict(x0, p0, params.models, dt, params.sigma, scale)
    return IMMState(float(t_s), x_pred, p_pred, cbar / cbar.sum(), scale)


@dataclass(frozen=True, slots=True)
class IMMUpdate:
    """What an update found: the new state and, per model, the innovation statistics."""

    state: IMMState
    nis: FloatArray
    log_likelihood: FloatArray


def imm_update(predicted: IMMState, z: FloatArray, r: FloatArray) -> IMMUpdate:
    """Appendix B steps 2-4 with one position observation ``z`` (2,), covariance ``r`` (2, 2).

    Each model filter updates; mu_j is proportional to Lambda_j c_j (computed in the log domain,
    so a far-off observation cannot underflow every likelihood to 0).
    """
    x, p, nis, loglik = position_update(predicted.x, predicted.p, z, r, predicted.cov_scale)
    p = ensure_spd(p)  # round-off after a very long prediction can break definiteness
    logw = loglik + np.log(np.maximum(predicted.mu, _MU_FLOOR))
    w = np.exp(logw - np.max(logw))
    mu = np.maximum(w / w.sum(), _MU_FLOOR)
    mu = mu / mu.sum()
    return IMMUpdate(IMMState(predicted.t_s, x, p, mu, predicted.cov_scale), nis, loglik)


def default_imm_params(
    q_cv: float = 1e-4,
    q_ca: float = 5e-4,
    q_turn: float = 0.3,
    turn_rate_rad_s: float = 0.02,
    transition: Sequence[Sequence[float]] | None = None,
    transition_dt_s: float = 0.1,
) -> IMMParams:
    """A three-model IMM (CV, CA, turn); the defaults are configs/estimator.toml's."""
    models = (
        MotionModel("cv", q_cv),
        MotionModel("ca", q_ca),
        MotionModel("turn", q_turn, turn_rate_rad_s),
    )
    m = (
        np.array(transition, dtype=np.float64)
        if transition is not None
        else np.array([[0.999, 0.0005, 0.0005], [0.002, 0.996, 0.002], [0.002, 0.002, 0.996]])
    )
    return IMMParams(models=models, transition=m, transition_dt_s=transition_dt_s)


__all__ = [
    "STATE_DIM",
    "IMMParams",
    "IMMState",
    "IMMUpdate",
    "combine",
    "default_imm_params",
    "imm_init",
    "imm_predict",
    "imm_update",
]
