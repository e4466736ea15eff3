"""UKF and IMM steps: UKF == Kalman filter on linear models, equality with filterpy's IMM, mode
probabilities, covariance hygiene, and the local filter's handling of bad and asynchronous data."""

import math
from dataclasses import replace

import numpy as np
import pytest
from filterpy.kalman import IMMEstimator, MerweScaledSigmaPoints, UnscentedKalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from app.core.estimation.imm import (
    IMMParams,
    IMMState,
    combine,
    default_imm_params,
    imm_init,
    imm_predict,
    imm_update,
)
from app.core.estimation.linalg import is_spd, robust_cholesky
from app.core.estimation.local import LocalParams, LocalState, local_predict, local_step
from app.core.estimation.messages import Observation
from app.core.estimation.models import MotionModel
from app.core.estimation.ukf import SigmaPoints, position_update, unscented_predict

H = np.zeros((2, 6))
H[0, 0] = H[1, 2] = 1.0
R = np.eye(2) * 10.0


def _random_spd(seed: int, scale: float = 1.0) -> np.ndarray:
    a = np.random.default_rng(seed).normal(size=(6, 6))
    return scale * (a @ a.T + 0.5 * np.eye(6))


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    dt=st.floats(1e-4, 50.0),
    kind=st.sampled_from(["cv", "ca", "turn", "ct"]),
    alpha=st.floats(0.3, 1.5),
)
def test_ukf_equals_the_kalman_filter_on_linear_models(seed, dt, kind, alpha):
    model = MotionModel(kind, 0.5, 0.2)
    x = np.random.default_rng(seed).normal(size=6) * 10
    p = _random_spd(seed)
    sigma = SigmaPoints(6, alpha, 2.0, 0.0)
    xp, pp = unscented_predict(x[None], p[None], [model], dt, sigma)
    f, q = model.transition(dt), model.process_noise(dt)
    np.testing.assert_allclose(xp[0], f @ x, rtol=1e-9, atol=1e-9 * max(1, np.abs(f @ x).max()))
    kf_p = f @ p @ f.T + q
    np.testing.assert_allclose(pp[0], kf_p, rtol=1e-8, atol=1e-8 * np.abs(kf_p).max())
    z = np.array([1.0, -2.0])
    xu, pu, _, _ = position_update(xp, pp, z, R)
    s = H @ kf_p @ H.T + R
    k = kf_p @ H.T @ np.linalg.inv(s)
    np.testing.assert_allclose(xu[0], f @ x + k @ (z - H @ f @ x), rtol=1e-7, atol=1e-7)
    kf_post = (np.eye(6) - k @ H) @ kf_p
    np.testing.assert_allclose(pu[0], kf_post, rtol=1e-6, atol=1e-7 * np.abs(kf_post).max())


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    dt=st.floats(1e-4, 50.0),
    alpha=st.floats(0.3, 1.5),
    kappa=st.floats(0.0, 3.0),
)
def test_the_closed_form_prediction_is_the_unscented_transform_of_the_sigma_points(
    seed, dt, alpha, kappa
):
    """The prediction works out F X, F P F^T + Q; here the sigma points are moved one by one,
    as a UKF does, for the three models at once."""
    models = [MotionModel("cv", 0.5), MotionModel("ca", 0.3), MotionModel("turn", 0.2, 0.1)]
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(3, 6)) * 10
    p = np.stack([_random_spd(seed + k, 1.0 + k) for k in range(3)])
    sigma = SigmaPoints(6, alpha, 2.0, kappa)
    xp, pp = unscented_predict(x, p, models, dt, sigma)
    points = sigma.points(x, p)  # (3, 13, 6)
    for j, model in enumerate(models):
        moved = np.array([model.transition(dt) @ point for point in points[j]])
        mean = sigma.wm @ moved
        dev = moved - mean
        cov = (dev.T * sigma.wc) @ dev + model.process_noise(dt)
        np.testing.assert_allclose(xp[j], mean, rtol=1e-9, atol=1e-9 * max(1, np.abs(mean).max()))
        np.testing.assert_allclose(pp[j], cov, rtol=1e-7, atol=1e-8 * np.abs(cov).max())


def test_same_estimates_as_filterpy_imm_over_ukfs():
    """The issue's equality check: filterpy's IMMEstimator over UKFs, same models and params."""
    params = default_imm_params()
    rng = np.random.default_rng(3)
    times = 0.1 * np.arange(301)
    truth = np.stack([4 * times, 20 * np.sin(times / 10)], axis=1)
    zs = truth + rng.normal(0.0, math.sqrt(10.0), truth.shape)
    x0 = np.array([zs[0, 0], 0, zs[0, 1], 0, 0, 0.0])
    p0 = np.diag([10.0, 100, 10, 100, 1, 1])

    def make(model: MotionModel) -> UnscentedKalmanFilter:
        points = MerweScaledSigmaPoints(6, alpha=1.0, beta=2.0, kappa=0.0)
        f = UnscentedKalmanFilter(
            6,
            2,
            0.1,
            hx=lambda s: s[[0, 2]],
            fx=lambda s, dt: model.transition(dt) @ s,
            points=points,
        )
        f.x, f.P, f.R = x0.copy(), p0.copy(), R.copy()
        return f

    filters = [make(m) for m in params.models]
    reference = IMMEstimator(filters, np.ones(3) / 3, np.array(params.transition))
    state = imm_init(0.0, x0, p0, params)
    for k in range(1, len(times)):
        dt = times[k] - times[k - 1]
        for f, m in zip(filters, params.models, strict=True):
            f._dt = dt
            f.Q = np.array(m.process_noise(dt))
        reference.predict()
        reference.update(zs[k])
        state = imm_update(imm_predict(state, times[k], params), zs[k], R).state
        x, p = state.combined()
        np.testing.assert_allclose(x, reference.x, atol=1e-6)
        np.testing.assert_allclose(p, reference.P, atol=1e-6)
        np.testing.assert_allclose(state.mu, reference.mu, atol=1e-6)


@settings(max_examples=40, deadline=None)
@given(
    mu=arrays(np.float64, 3, elements=st.floats(1e-6, 1.0)),
    z=arrays(np.float64, 2, elements=st.floats(-1e4, 1e4)),
    dt=st.floats(0.0, 30.0),
)
def test_mode_probabilities_stay_a_distribution(mu, z, dt):
    params = default_imm_params()
    state = imm_init(0.0, np.zeros(6), np.eye(6), params, mu0=mu)
    predicted = imm_predict(state, dt, params)
    updated = imm_update(predicted, z, R).state
    for m in (predicted.mu, updated.mu):
        assert np.all(m >= 0.0)
        assert math.isclose(float(m.sum()), 1.0, abs_tol=1e-12)
        assert np.all(np.isfinite(m))


@pytest.mark.parametrize("dt", [1e-9, 1e-3, 0.1, 10.0, 1e4])
def test_covariances_stay_spd_under_long_runs_and_extreme_steps(dt):
    params = default_imm_params()
    rng = np.random.default_rng(7)
    state = imm_init(0.0, np.zeros(6), np.diag([10.0, 100, 10, 100, 1, 1]), params)
    t = 0.0
    for _ in range(400):
        t += dt
        z = rng.normal(0.0, 3.0, 2)
        state = imm_update(imm_predict(state, t, params), z, R).state
        x, p = state.combined()
        assert all(is_spd(pj) for pj in state.p)
        assert is_spd(p)
        assert np.all(np.isfinite(x))


def test_robust_cholesky_repairs_an_indefinite_matrix():
    p = np.diag([1.0, 1e-18, 2.0])
    p[0, 1] = p[1, 0] = 1e-6  # slightly indefinite
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky(p)
    lower = robust_cholesky(p)
    np.testing.assert_allclose(lower @ lower.T, p, atol=1e-6)
    stack = robust_cholesky(np.stack([p, np.eye(3)]))
    np.testing.assert_allclose(stack[1], np.eye(3))
    with pytest.raises(np.linalg.LinAlgError):
        robust_cholesky(np.full((2, 2), np.nan))


def test_imm_steps_do_not_mutate_their_inputs():
    params = default_imm_params()
    state = imm_init(0.0, np.ones(6), np.eye(6), params)
    before = (state.x.copy(), state.p.copy(), state.mu.copy())
    z = np.array([5.0, 5.0])
    imm_update(imm_predict(state, 1.0, params), z, R)
    for a, b in zip(before, (state.x, state.p, state.mu), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(z, [5.0, 5.0])


def test_imm_params_validate_the_transition_matrix():
    models = default_imm_params().models
    with pytest.raises(ValueError, match="sum to 1"):
        IMMParams(models, np.full((3, 3), 0.5))
    with pytest.raises(ValueError, match="shape"):
        IMMParams(models, np.eye(2))
    params = default_imm_params()
    np.testing.assert_allclose(params.transition_for(0.0), np.eye(3))
    np.testing.assert_allclose(params.transition_for(0.1), params.transition)
    long = params.transition_for(1e6)
    np.testing.assert_allclose(long.sum(axis=1), 1.0)


def test_combine_matches_appendix_b_output():
    x = np.array([[0.0] * 6, [2.0] + [0.0] * 5])
    p = np.stack([np.eye(6), np.eye(6)])
    mean, cov = combine(x, p, np.array([0.5, 0.5]))
    assert mean[0] == 1.0
    assert cov[0, 0] == pytest.approx(2.0)  # 1 + spread 1


# --- the local filter: asynchronous, bad and stale observations -------------------------------


@pytest.fixture
def params() -> LocalParams:
    return LocalParams(imm=default_imm_params())


def _obs(t: float, e: float = 0.0, n: float = 0.0, sigma: float | None = None) -> Observation:
    return Observation(t, "1", e, n, sigma)


def _imm(state: LocalState) -> IMMState:
    assert state.imm is not None
    return state.imm


def _running(params: LocalParams, n: int = 20) -> LocalState:
    state = LocalState("1")
    for k in range(n):
        state, _ = local_step(state, _obs(0.1 * k, 1.0 * 0.1 * k, 0.0), params)
    return state


@pytest.mark.parametrize(
    ("obs", "words"),
    [
        (Observation(math.nan, "1", 0.0, 0.0), "non-finite"),
        (Observation(3.0, "1", math.inf, 0.0), "non-finite"),
        (Observation(3.0, "1", 0.0, math.nan), "non-finite"),
        (Observation(3.0, "1", 5e6, 0.0), "beyond"),
        (Observation(3.0, "1", 0.0, 0.0, -1.0), "sigma"),
        (Observation(3.0, "1", 0.0, 0.0, math.nan), "sigma"),
        (Observation(3.0, "1", 0.0, 0.0, 1e9), "sigma"),
    ],
)
def test_invalid_observations_are_rejected_counted_and_leave_the_state(params, obs, words):
    state = _running(params)
    new, report = local_step(state, obs, params)
    assert report.outcome == "invalid"
    assert words in report.reason
    assert new.counters.invalid == state.counters.invalid + 1
    assert new.imm is state.imm


def test_a_first_invalid_observation_does_not_start_the_filter(params):
    new, report = local_step(LocalState("1"), _obs(math.nan), params)
    assert report.outcome == "invalid"
    assert new.imm is None


def test_stale_observations_are_dropped_and_counted(params):
    state = _running(params)
    new, report = local_step(state, _obs(_imm(state).t_s - 5.0), params)
    assert report.outcome == "stale"
    assert new.counters.stale_dropped == 1
    assert new.imm is state.imm


def test_late_observations_are_used_without_moving_the_filter_back(params):
    state = _running(params)
    t_now = _imm(state).t_s
    new, report = local_step(state, _obs(t_now - 0.25, 1.0 * (t_now - 0.25), 0.0), params)
    assert report.outcome == "late"
    assert new.counters.late_used == 1
    assert new.t_s == t_now
    _, p_before = _imm(state).combined()
    x_after, p_after = _imm(new).combined()
    assert is_spd(p_after)
    assert p_after[0, 0] < p_before[0, 0]  # it was information
    assert np.all(np.isfinite(x_after))


def test_outliers_are_gated_and_a_lost_track_restarts(params):
    state = _running(params)
    new, report = local_step(state, _obs(_imm(state).t_s + 0.1, 500.0, 500.0), params)
    assert report.outcome == "gated"
    assert "NIS" in report.reason
    assert new.counters.gated == 1
    x_pred, _ = _imm(new).combined()
    assert abs(x_pred[0] - 2.0) < 1.0  # the prediction, not the outlier
    for _ in range(params.max_consecutive_gated - 1):
        new, report = local_step(new, _obs(_imm(new).t_s + 0.1, 500.0, 500.0), params)
    assert report.outcome == "restarted"
    assert new.counters.restarts == 1
    assert _imm(new).combined()[0][0] == 500.0


@pytest.mark.parametrize(
    "ruin",
    [
        lambda imm: replace(imm, x=np.full_like(imm.x, np.nan)),
        lambda imm: replace(imm, x=imm.x + np.array([1e36, 0, 0, 0, 0, 0])),
        lambda imm: replace(imm, p=imm.p * 1e70),
    ],
    ids=["nan", "runaway", "unbounded-covariance"],
)
def test_a_diverged_track_restarts_on_the_next_observation_the_caller_allows(params, ruin):
    state = _running(params)
    ruined = replace(state, imm=ruin(_imm(state)))
    t = _imm(state).t_s + 0.1
    refused, report = local_step(ruined, _obs(t, 2.2, 0.0), params, may_restart=lambda _: False)
    assert report.outcome == "gated"
    assert "diverged" in report.reason
    assert refused.imm is ruined.imm
    if not np.all(np.isfinite(_imm(refused).x)):
        assert refused.estimate() is None  # nothing non-finite goes out meanwhile
    new, report = local_step(refused, _obs(t + 0.1, 2.4, 0.0), params)
    assert report.outcome == "restarted"
    assert "diverged" in report.reason
    assert new.counters.restarts == 1
    x, p = _imm(new).combined()
    assert x[0] == 2.4
    assert is_spd(p)


def test_a_filter_that_hears_nothing_keeps_predicting_with_growing_covariance(params):
    state = _running(params)
    traces = []
    for t in (2.0, 5.0, 20.0, 100.0):
        later = local_predict(state, t, params)
        traces.append(np.trace(_imm(later).combined()[1][:4, :4]))
        assert is_spd(_imm(later).combined()[1])
    assert traces == sorted(traces)
    assert local_predict(state, 0.0, params) is state  # never backwards


def test_observations_are_used_in_any_timestamp_order_without_corruption(params):
    rng = np.random.default_rng(1)
    times = np.sort(rng.uniform(0, 30, 300))
    order = times.copy()
    for i in range(0, 300, 7):  # swap neighbours: out-of-order arrivals
        if i + 1 < 300:
            order[i], order[i + 1] = order[i + 1], order[i]
    state = LocalState("1")
    outcomes = []
    for t in order:
        state, report = local_step(state, _obs(float(t), 2.0 * t, -1.0 * t), params)
        outcomes.append(report.outcome)
    x, p = _imm(state).combined()
    assert "late" in outcomes
    assert abs(x[1] - 2.0) < 0.5
    assert abs(x[3] + 1.0) < 0.5
    assert is_spd(p)


def test_ensure_spd_repairs_in_correlation_space_keeping_scales():
    from app.core.estimation.linalg import ensure_spd

    bad = np.array([[10.0, 3.2e9], [3.2e9, 1e18]])  # correlation 1.01: indefinite
    fixed = ensure_spd(bad[None])[0]
    assert is_spd(fixed)
    assert fixed[0, 0] == pytest.approx(10.0, rel=0.02)
    assert fixed[1, 1] == pytest.approx(1e18, rel=0.02)
    good = np.stack([np.eye(2)])
    assert ensure_spd(good) is good
