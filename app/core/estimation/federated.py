"""The federated filter's main filter (Appendix A): fuse local estimates, share information back.

Overall optimisation: P_g = (sum_i P_i^-1)^-1, X_g = P_g sum_i P_i^-1 X_i, after a time update of
every local estimate to the fusion time. Information allocation: beta_i = ||P_i||_F^-1 /
sum_j ||P_j||_F^-1 (the main filter keeps beta_m = 0), and each local filter is given
P_i = beta_i^-1 P_g, X_i = X_g, Q_i = beta_i^-1 Q_g.

How the allocation reaches an IMM is the design choice (``FeedbackMode``):

- ``"none"``: no feedback; the local filters stay independent and the main filter only fuses.
- ``"reset"``: Appendix A read literally: every model of the local IMM is set to (X_g,
  beta_i^-1 P_g). It wipes out the differences between the model-conditioned estimates that the
  IMM needs to tell the models apart, and measures worse than no feedback.
- ``"mixture"``: the local IMM's whole mixture is moved by the affine map that takes its
  combined moments (X_i, P_i) to (X_g, beta_i^-1 P_g): X_j <- X_g + T (X_j - X_i),
  P_j <- T P_j T^T with T = chol(beta_i^-1 P_g) chol(P_i)^-1. The combined estimate is exactly
  the allocated one; the mode probabilities and the models' relative offsets are kept.
- ``"modewise"`` (default): Appendix A applied to each model of the IMM. The main filter fuses
  the local filters model by model (P_gj = (sum_i P_ij^-1)^-1, X_gj = P_gj sum_i P_ij^-1 X_ij),
  fuses the mode probabilities by the product rule (mu_g ~ prod_i mu_i / c^(n-1), c the
  common predicted prior), and gives every local filter every model's share
  (X_gj, beta_i^-1 P_gj) and mu_g. Local filters holding a share scale Q and the mixing spread
  by beta_i^-1 and undo it in their mode likelihoods (``IMMState.cov_scale``), so that for
  linear models the federated IMM reproduces the centralised IMM.

In every mode with feedback the local filters run with Q_i = beta_i^-1 Q_g.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from app.core.estimation.imm import IMMParams, IMMState, combine, imm_predict
from app.core.estimation.linalg import robust_cholesky, symmetrise
from app.core.estimation.local import LocalParams, LocalState, local_step
from app.core.estimation.messages import GlobalEstimate, LocalEstimate
from app.core.estimation.models import MotionModel
from app.core.values import replace

FloatArray = NDArray[np.float64]

FeedbackMode = Literal["none", "reset", "mixture", "modewise"]
FEEDBACK_MODES: tuple[FeedbackMode, ...] = ("none", "reset", "mixture", "modewise")


@dataclass(frozen=True, slots=True)
class MainParams:
    """The main filter.

    Parameters
    ----------
    imm
        The local filters' IMM parameters (the ``"modewise"`` fusion predicts each local
        filter's models to the fusion time with them).
    time_update
        Model that carries each combined local estimate to the fusion time (eqs 18-19), in the
        other modes.
    max_age_s
        Local estimates older than this at the fusion time are left out.
    feedback
        How the information allocation is applied to the local IMMs (module docstring).
    scale_process_noise
        Apply Q_i = beta_i^-1 Q_g in the local filters while feedback is on.
    """

    imm: IMMParams | None = None
    time_update: MotionModel = field(default_factory=lambda: MotionModel("ca", 5e-4))
    max_age_s: float = 2.0
    feedback: FeedbackMode = "modewise"
    scale_process_noise: bool = True

    def __post_init__(self) -> None:
        if self.feedback not in FEEDBACK_MODES:
            raise ValueError(f"feedback must be one of {FEEDBACK_MODES}, got {self.feedback!r}")
        if not (math.isfinite(self.max_age_s) and self.max_age_s > 0.0):
            raise ValueError(f"max_age_s must be finite and > 0, got {self.max_age_s}")


ALLOCATION_IGNORED_AFTER_S = 3.0
"""A local estimate whose basis (the allocation its filter last took) is this much older than
the estimate, while a newer allocation was given to it, comes from a sender that does not take
the allocations: it is fused all the same (``main_receive``)."""


@dataclass(frozen=True, slots=True)
class MainState:
    """The newest estimate from every local filter, and what was refused."""

    latest: tuple[LocalEstimate, ...] = ()
    received: int = 0
    out_of_order_dropped: int = 0
    shared: GlobalEstimate | None = None
    """The last allocation sent back (its mu is the common prior of the modewise fusion)."""
    received_t: tuple[tuple[str, float], ...] = ()
    """The time of the newest estimate each sensor itself sent (``latest`` may hold the main
    filter's allocation copy instead, at the fusion's time)."""
    allocated_t: tuple[tuple[str, float], ...] = ()
    """The time of the allocation last given to each sensor (the basis its estimates must
    declare to be fused)."""
    stale_basis_dropped: int = 0
    """Estimates refused because they were built on an older allocation than the last one."""
    allocations_ignored: int = 0
    """Estimates fused although built on an older allocation, their sender having taken none
    for ``ALLOCATION_IGNORED_AFTER_S``."""

    def estimate_of(self, sensor: str) -> LocalEstimate | None:
        for est in self.latest:
            if est.sensor == sensor:
                return est
        return None


def main_receive(state: MainState, estimate: LocalEstimate) -> MainState:
    """Keep ``estimate`` as its sender's newest; one older than the newest its sender already
    sent is counted and dropped.

    The order is the sender's own: after a fusion the main filter holds its allocation copy of
    every local filter at the fusion's time (``main_allocate``), but an estimate its sender
    made a little earlier and the bus delivered after that fusion is still new information (its
    measurements are not in the fused estimate); it replaces the copy and is carried to the next
    fusion's time there. Refusing it, as a comparison with the copy's time would, leaves the
    main filter fusing its own copies, coasting on the old velocity while the target turns,
    whenever the estimates arrive later than the fusion runs (the multi-process mission, where
    each agent stamps its estimates with its own vehicle's time).

    An estimate built on an older allocation than the last one given to its sender
    (``alloc_t_s`` older) is counted and dropped: the newer allocation
    already holds that allocation's information and the sender's observations up to its
    estimate then, and the main filter's copies of the other filters are shares of it, so
    fusing it with them would count both twice. Nothing is lost: the sender replays its
    observations after ``GlobalEstimate.included_t_s`` when the allocation reaches it. An
    estimate with no basis (``alloc_t_s`` None: its filter never took an allocation) is taken
    as before; only the first allocation's round trip can then count observations twice."""
    sent = dict(state.received_t)
    last = sent.get(estimate.sensor)
    if last is not None and estimate.t_s < last:
        return replace(state, out_of_order_dropped=state.out_of_order_dropped + 1)
    basis = dict(state.allocated_t).get(estimate.sensor)
    ignored = state.allocations_ignored
    if basis is not None and estimate.alloc_t_s is not None and estimate.alloc_t_s < basis:
        if estimate.t_s - estimate.alloc_t_s <= ALLOCATION_IGNORED_AFTER_S:
            return replace(state, stale_basis_dropped=state.stale_basis_dropped + 1)
        # its sender has not taken an allocation for that long (it refused them: an agent
        # does not believe a fused estimate far less certain than its own, as the main
        # filter's is after a bus outage): its estimates are fused as they are, or the main
        # filter would starve, coast and drift away from the target for good
        ignored += 1
    sent[estimate.sensor] = estimate.t_s
    others = tuple(e for e in state.latest if e.sensor != estimate.sensor)
    return replace(
        state,
        latest=(*others, estimate),
        received=state.received + 1,
        received_t=tuple(sorted(sent.items())),
        allocations_ignored=ignored,
    )


#: no share below this fraction of an equal one (1 / k): see ``information_shares``
MIN_SHARE_OF_EQUAL = 0.1


def information_shares(covariances: FloatArray) -> FloatArray:
    """beta_i = ||P_i||_F^-1 / sum_j ||P_j||_F^-1 (Appendix A), for a stack (k, 6, 6); sums to 1.

    A share below ``MIN_SHARE_OF_EQUAL`` / k is raised to it (the others scaled to make room). The
    allocation hands a filter P_g / beta_i: the least certain filter gets the smallest share,
    so the largest covariance, so the smallest share next time, and nothing stops that loop.
    In a run of twenty one agent's share fell to 4.3e-9, its allocated position variance to
    8e7 m^2 (its process noise scaled by 1 / beta as well), and its filter ran away to NaN.
    """
    norms = np.sqrt(np.sum(covariances * covariances, axis=(1, 2)))
    inv_norms: FloatArray = 1.0 / norms
    shares: FloatArray = inv_norms / np.sum(inv_norms)
    floor = MIN_SHARE_OF_EQUAL / len(shares)
    low = shares < floor
    if np.any(low) and not np.all(low):
        rest = shares[~low]
        shares = shares.copy()
        shares[low] = floor
        shares[~low] = rest * (1.0 - floor * np.count_nonzero(low)) / np.sum(rest)
    return shares


def time_update(
    x: FloatArray, p: FloatArray, dt_s: float, model: MotionModel, q_scale: float = 1.0
) -> tuple[FloatArray, FloatArray]:
    """Carry one estimate (6,), (6, 6) over ``dt_s`` with ``model``: F x, F P F^T + s Q(|dt|)."""
    if dt_s == 0.0:
        return x, p
    f = model.transition(dt_s)
    p_new = f @ p @ f.T + q_scale * model.process_noise(dt_s)
    return f @ x, 0.5 * (p_new + p_new.T)


def fuse(
    estimates: Sequence[LocalEstimate],
    t_s: float,
    params: MainParams,
    shared: GlobalEstimate | None = None,
) -> GlobalEstimate | None:
    """Overall optimisation (Appendix A (3)) of the estimates no older than ``max_age_s``.

    Each estimate is first carried to ``t_s`` (with the main filter's time-update model, or
    model by model with the IMM in the ``"modewise"`` design). Returns None when no estimate
    is fresh enough. ``shared`` is the last allocation (the common prior of the mode
    probabilities).
    """
    fresh = [e for e in estimates if abs(t_s - e.t_s) <= params.max_age_s]
    if not fresh:
        return None
    if params.feedback == "modewise":
        if params.imm is None:
            raise ValueError("the modewise fusion needs the local filters' IMM parameters (imm)")
        if all(e.model_x is not None for e in fresh):
            return _fuse_modewise(fresh, t_s, params.imm, shared)
    k = len(fresh)
    xs = np.empty((k, 6))
    ps = np.empty((k, 6, 6))
    for i, e in enumerate(fresh):
        xs[i], ps[i] = time_update(e.x, e.p, t_s - e.t_s, params.time_update, e.q_scale)
    x_g, p_g = _information_sum(xs, ps)
    beta = information_shares(ps)
    return GlobalEstimate(
        t_s=float(t_s),
        x=x_g,
        p=p_g,
        beta=tuple((e.sensor, float(b)) for e, b in zip(fresh, beta, strict=True)),
    )


def _information_sum(xs: FloatArray, ps: FloatArray) -> tuple[FloatArray, FloatArray]:
    """P_g = (sum P_i^-1)^-1, X_g = P_g sum P_i^-1 X_i over the first axis of (k, 6), (k, 6, 6)."""
    infos = np.linalg.inv(ps)
    info = infos.sum(axis=0)
    p_g = np.linalg.inv(0.5 * (info + info.T))
    p_g = 0.5 * (p_g + p_g.T)
    x_g = p_g @ (infos @ xs[:, :, None]).sum(axis=0)[:, 0]
    return x_g, p_g


def _fuse_modewise(
    fresh: Sequence[LocalEstimate],
    t_s: float,
    imm: IMMParams,
    shared: GlobalEstimate | None,
) -> GlobalEstimate:
    k, r = len(fresh), imm.n_models
    xs = np.empty((k, r, 6))
    ps = np.empty((k, r, 6, 6))
    mus = np.empty((k, r))
    # shares of one allocation (same arrays, same time) differ only by the scale of their
    # covariances, and every model is linear, so one prediction serves them all
    done: dict[tuple[float, int, int], tuple[IMMState, float]] = {}
    for i, e in enumerate(fresh):
        if e.model_x is None or e.model_p is None:
            raise ValueError(f"local estimate from {e.sensor!r} has no model-conditioned states")
        key = (e.t_s, id(e.model_x), id(e.mu))
        hit = done.get(key)
        if hit is not None:
            base, base_scale = hit
            xs[i], ps[i], mus[i] = base.x, base.p * (e.q_scale / base_scale), base.mu
            continue
        state = IMMState(e.t_s, np.asarray(e.model_x), np.asarray(e.model_p), e.mu, e.q_scale)
        if e.t_s < t_s:
            state = imm_predict(state, t_s, imm)
        done[key] = (state, e.q_scale)
        xs[i], ps[i], mus[i] = state.x, state.p, state.mu
    # per model: P_gj = (sum_i P_ij^-1)^-1, X_gj = P_gj sum_i P_ij^-1 X_ij
    infos = np.linalg.inv(ps)  # (k, r, 6, 6)
    info = infos.sum(axis=0)
    model_p = np.linalg.inv(0.5 * (info + info.swapaxes(1, 2)))
    model_p = 0.5 * (model_p + model_p.swapaxes(1, 2))
    model_x = (model_p @ (infos @ xs[..., None]).sum(axis=0))[..., 0]
    # product rule: each local mu_i ~ c * L_i from a common prior c
    log_mu = np.sum(np.log(np.maximum(mus, 1e-300)), axis=0)
    if shared is not None and shared.mu is not None and k > 1:
        prior = shared.mu @ imm.transition_for(t_s - shared.t_s)
        log_mu -= (k - 1) * np.log(np.maximum(prior, 1e-300))
    mu = np.exp(log_mu - np.max(log_mu))
    mu = np.maximum(mu / mu.sum(), 1e-12)
    mu /= mu.sum()
    x_g, p_g = combine(model_x, model_p, mu)
    beta = information_shares(np.stack([e.p for e in fresh]))
    return GlobalEstimate(
        t_s=float(t_s),
        x=x_g,
        p=p_g,
        beta=tuple((e.sensor, float(b)) for e, b in zip(fresh, beta, strict=True)),
        mu=mu,
        model_x=model_x,
        model_p=model_p,
    )


def main_fuse(state: MainState, t_s: float, params: MainParams) -> GlobalEstimate | None:
    """Fuse the main filter's newest local estimates at ``t_s``; the result says up to when
    each fused sensor's own estimates are in it (``included_t_s``)."""
    fused = fuse(state.latest, t_s, params, state.shared)
    if fused is None:
        return None
    sent = dict(state.received_t)
    included = tuple((s, sent[s]) for s, _ in fused.beta if s in sent)
    return replace(fused, included_t_s=included)


def main_allocate(state: MainState, fused: GlobalEstimate, params: MainParams) -> MainState:
    """The main filter's copy of each local filter after the information allocation it sent:
    (X_g, beta_i^-1 P_g) at the fused time, so that the next fusion counts the shared
    information once; from now on it takes only estimates built on this allocation from the
    filters given a share. With feedback ``"none"`` the state is returned as is.

    An estimate newer than the fused time is replaced too: it is in the fusion, and its
    sender replays its observations after ``included_t_s`` on top of the allocation."""
    if params.feedback == "none":
        return state
    shares = dict(fused.beta)
    allocated = dict(state.allocated_t)
    latest = []
    for est in state.latest:
        beta = shares.get(est.sensor)
        if beta is None or beta <= 0.0:
            latest.append(est)
            continue
        allocated[est.sensor] = fused.t_s
        scale = 1.0 / beta if params.scale_process_noise else 1.0
        if fused.model_x is not None and fused.model_p is not None and fused.mu is not None:
            copy = LocalEstimate(
                est.sensor,
                fused.t_s,
                fused.x,
                fused.p / beta,
                fused.mu,
                scale,
                model_x=fused.model_x,
                model_p=fused.model_p / beta,
                alloc_t_s=fused.t_s,
            )
        else:
            copy = LocalEstimate(
                est.sensor, fused.t_s, fused.x, fused.p / beta, est.mu, scale, alloc_t_s=fused.t_s
            )
        latest.append(copy)
    return replace(
        state, latest=tuple(latest), shared=fused, allocated_t=tuple(sorted(allocated.items()))
    )


def apply_feedback(
    local: LocalState,
    fused: GlobalEstimate,
    local_params: LocalParams,
    main_params: MainParams,
) -> LocalState:
    """Information allocation (Appendix A (1)) to one local filter, per ``main_params.feedback``.

    ``"modewise"``: the local filter takes the fused models' shares and mode probabilities; the
    observations it has used that the fusion lacks (newer than its newest estimate in the
    fusion, ``fused.included_for``) are replayed on top, and its estimates from now on declare
    this allocation as their basis (``alloc_t_s``). ``"reset"`` and
    ``"mixture"``: the local filter is first brought to the fused time (an IMM prediction), or
    the fused estimate is carried forward with the time-update model if the filter is past it.
    A filter that was not part of the fusion (no share), or mode ``"none"``, is returned as is.
    """
    beta = fused.beta_for(local.sensor)
    if main_params.feedback == "none" or beta is None or local.imm is None or beta <= 0.0:
        return local
    imm = local.imm
    scale = 1.0 / beta if main_params.scale_process_noise else 1.0
    r = imm.mu.shape[0]
    if (
        main_params.feedback == "modewise"
        and fused.model_x is not None
        and fused.model_p is not None
        and fused.mu is not None
    ):
        new_imm = IMMState(
            fused.t_s, np.array(fused.model_x), np.asarray(fused.model_p) / beta, fused.mu, scale
        )
        since = fused.included_for(local.sensor)
        newer = tuple(o for o in local.recent if o.t_s > since)
        if newer:
            # the allocation lacks observations this filter has used: take the allocation and
            # replay them on top (counted once); those older than the allocation are late
            # observations to it (local_step's carry-forward)
            replayed = LocalState(local.sensor, new_imm)
            for obs in sorted(newer, key=lambda o: o.t_s):
                replayed, _ = local_step(replayed, obs, local_params)
            assert replayed.imm is not None
            new_imm = replayed.imm
        if new_imm.t_s < imm.t_s:
            new_imm = imm_predict(new_imm, imm.t_s, local_params.imm)
        counters = replace(local.counters, feedback=local.counters.feedback + 1)
        return replace(local, imm=new_imm, counters=counters, recent=newer, alloc_t_s=fused.t_s)
    x_g, p_g = np.asarray(fused.x), np.asarray(fused.p)
    if imm.t_s < fused.t_s:
        imm = imm_predict(imm, fused.t_s, local_params.imm)
    elif imm.t_s > fused.t_s:
        x_g, p_g = time_update(
            x_g, p_g, imm.t_s - fused.t_s, main_params.time_update, imm.cov_scale
        )
    target_p = p_g / beta
    if main_params.feedback == "reset":
        xs = np.tile(x_g, (r, 1))
        ps = np.tile(target_p, (r, 1, 1))
    else:
        x_i, p_i = imm.combined()
        l_target = robust_cholesky(target_p)
        l_local = robust_cholesky(p_i)
        t = np.linalg.solve(l_local.T, l_target.T).T  # T = L_t L_i^-1
        xs = x_g + (imm.x - x_i) @ t.T
        ps = symmetrise(t @ imm.p @ t.T)
    new_imm = IMMState(imm.t_s, xs, ps, imm.mu, scale)
    counters = replace(local.counters, feedback=local.counters.feedback + 1)
    return replace(local, imm=new_imm, counters=counters, alloc_t_s=fused.t_s)
