"""Federated filter (Appendix A) and the messages that carry it between processes."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.core.estimation.federated import (
    ALLOCATION_IGNORED_AFTER_S,
    MIN_SHARE_OF_EQUAL,
    MainParams,
    MainState,
    apply_feedback,
    fuse,
    information_shares,
    main_allocate,
    main_fuse,
    main_receive,
)
from app.core.estimation.imm import IMMParams, default_imm_params
from app.core.estimation.linalg import is_spd
from app.core.estimation.local import LocalParams, LocalState, local_step
from app.core.estimation.messages import GlobalEstimate, LocalEstimate, Observation
from app.core.estimation.models import MotionModel
from app.core.estimation.pipeline import (
    FederatedParams,
    FederatedState,
    federated_step,
    run_centralised,
    run_federated,
)
from app.errors import InputError


def _spd(seed: int) -> np.ndarray:
    a = np.random.default_rng(seed).normal(size=(6, 6))
    return a @ a.T + np.eye(6)


def _estimate(sensor: str, x: np.ndarray, p: np.ndarray, t: float = 1.0) -> LocalEstimate:
    return LocalEstimate(sensor, t, x, p, np.array([1.0]))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_fusing_two_identical_estimates_halves_the_covariance(seed):
    p = _spd(seed)
    x = np.random.default_rng(seed).normal(size=6)
    fused = fuse([_estimate("a", x, p), _estimate("b", x, p)], 1.0, MainParams(feedback="mixture"))
    assert fused is not None
    np.testing.assert_allclose(fused.p, p / 2, rtol=1e-8, atol=1e-10 * np.abs(p).max())
    np.testing.assert_allclose(fused.x, x, rtol=1e-8, atol=1e-8)
    assert dict(fused.beta) == pytest.approx({"a": 0.5, "b": 0.5})


@settings(max_examples=40, deadline=None)
@given(seeds=st.lists(st.integers(0, 10_000), min_size=1, max_size=5))
def test_information_shares_follow_the_frobenius_norms_and_sum_to_one(seeds):
    ps = np.stack([_spd(s) for s in seeds])
    beta = information_shares(ps)
    assert beta.sum() == pytest.approx(1.0)
    norms = np.linalg.norm(ps, axis=(1, 2))
    raw = (1 / norms) / np.sum(1 / norms)
    floor = MIN_SHARE_OF_EQUAL / len(seeds)
    if np.all(raw >= floor):
        np.testing.assert_allclose(beta, raw)
    else:
        assert np.all(beta >= 0.9 * floor)
        assert np.all(np.diff(beta[np.argsort(norms)]) <= 1e-12)  # the more certain, the more


def test_no_share_falls_below_a_tenth_of_an_equal_one():
    """The allocation hands a filter P_g / beta: the least certain gets the least share and so
    the largest covariance, and the loop ran one agent of twenty to a share of 4.3e-9 and its
    filter to NaN. A tenth of an equal share is its floor."""
    ps = np.stack([np.eye(6)] * 19 + [np.eye(6) * 1e9])
    beta = information_shares(ps)
    assert beta[-1] == pytest.approx(MIN_SHARE_OF_EQUAL / 20)
    assert beta.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(beta[:-1], (1.0 - MIN_SHARE_OF_EQUAL / 20) / 19)


def test_fusion_weights_the_more_certain_estimate():
    x_a, x_b = np.zeros(6), np.ones(6)
    fused = fuse(
        [_estimate("a", x_a, np.eye(6)), _estimate("b", x_b, 3 * np.eye(6))],
        1.0,
        MainParams(feedback="none"),
    )
    assert fused is not None
    np.testing.assert_allclose(fused.x, 0.25 * np.ones(6))
    np.testing.assert_allclose(fused.p, 0.75 * np.eye(6))


def test_old_estimates_are_left_out_and_older_messages_dropped():
    params = MainParams(feedback="none", max_age_s=2.0)
    old = _estimate("a", np.zeros(6), np.eye(6), t=0.0)
    assert fuse([old], 10.0, params) is None
    state = main_receive(MainState(), _estimate("a", np.zeros(6), np.eye(6), t=5.0))
    state = main_receive(state, old)
    assert state.out_of_order_dropped == 1
    held = state.estimate_of("a")
    assert held is not None
    assert held.t_s == 5.0


def _track(n: int = 450) -> list[Observation]:
    rng = np.random.default_rng(5)
    out = []
    for k in range(n):
        t = 0.1 * (k // 3) + (k % 3) / 30.0
        e, nn = 3.0 * t, 20.0 + 1.0 * t
        out.append(Observation(t, str(k % 3 + 1), e + rng.normal(0, 3), nn + rng.normal(0, 3)))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["modewise", "mixture", "reset"])
@pytest.mark.parametrize("period", [0.0, 0.1])
def test_with_one_linear_model_the_federated_filter_is_the_centralised_filter(mode, period):
    """Appendix A's information sharing makes the fused estimate optimal for a linear model
    (after the start, where every local filter's own prior is counted once more)."""
    model = MotionModel("ca", 0.01)
    local = LocalParams(
        imm=IMMParams((model,), np.eye(1)), init_speed_sigma_m_s=1e3, init_accel_sigma_m_s2=1e2
    )
    params = FederatedParams(local, MainParams(time_update=model, feedback=mode), period)
    obs = _track(900)
    central = run_centralised(obs, local).fused
    federated = run_federated(obs, params).fused
    np.testing.assert_allclose(federated.x[450:], central.x[450:], atol=1e-6)
    np.testing.assert_allclose(federated.p[450:], central.p[450:], atol=1e-6)


def test_feedback_keeps_local_filters_spd_and_sets_their_share():
    imm = default_imm_params()
    local = LocalParams(imm=imm)
    params = FederatedParams(local)
    run = run_federated(_track(), params)
    assert all(c.feedback > 0 for c in run.counters.values())
    for p in run.fused.p:
        assert is_spd(p)
    # a local filter given a share beta = 1/2 holds every model's beta^-1 P_gj
    state = LocalState("1")
    for o in _track(60)[::3]:
        state, _ = local_step(state, o, local)
    est = state.estimate()
    assert est is not None
    fused = fuse([est], est.t_s, params.main)
    assert fused is not None
    half = GlobalEstimate(
        fused.t_s, fused.x, fused.p, (("1", 0.5),), fused.mu, fused.model_x, fused.model_p
    )
    fed = apply_feedback(state, half, local, params.main)
    assert fed.imm is not None
    assert fused.model_p is not None
    np.testing.assert_allclose(fed.imm.p, 2 * np.asarray(fused.model_p), rtol=1e-12)
    np.testing.assert_array_equal(fed.imm.mu, fused.mu)
    assert fed.imm.cov_scale == 2.0
    assert apply_feedback(state, half, local, MainParams(feedback="none")) is state


def test_messages_round_trip_through_json():
    obs = Observation(1.5, "2", 10.0, -4.0, 3.0)
    assert Observation.from_dict(json.loads(json.dumps(obs.to_dict()))) == obs
    state = LocalState("1")
    local = LocalParams(imm=default_imm_params())
    for o in _track(30)[::3]:
        state, _ = local_step(state, o, local)
    est = state.estimate()
    assert est is not None
    back = LocalEstimate.from_dict(json.loads(json.dumps(est.to_dict())))
    np.testing.assert_array_equal(back.x, est.x)
    np.testing.assert_array_equal(back.p, est.p)
    assert back.model_x is not None
    np.testing.assert_array_equal(back.model_x, est.model_x)
    assert back.q_scale == est.q_scale
    fused = fuse([est], est.t_s, MainParams(imm=local.imm))
    assert fused is not None
    g = GlobalEstimate.from_dict(json.loads(json.dumps(fused.to_dict())))
    np.testing.assert_array_equal(g.p, fused.p)
    assert g.beta == fused.beta
    assert g.mu is not None


@pytest.mark.parametrize(
    ("raw", "words"),
    [
        ({"t_s": 1.0, "sensor": "1", "east_m": 0.0}, "north_m"),
        ({"t_s": "x", "sensor": "1", "east_m": 0.0, "north_m": 0.0}, "number"),
        ({"t_s": 1.0, "sensor": "", "east_m": 0.0, "north_m": 0.0}, "sensor"),
        ({"t_s": True, "sensor": "1", "east_m": 0.0, "north_m": 0.0}, "number"),
    ],
)
def test_malformed_observation_dicts_raise_input_error(raw, words):
    with pytest.raises(InputError, match=words):
        Observation.from_dict(raw)


def test_malformed_estimate_dicts_raise_input_error():
    good = _estimate("a", np.zeros(6), np.eye(6)).to_dict()
    with pytest.raises(InputError, match="shape"):
        LocalEstimate.from_dict({**good, "x": [0.0] * 5})
    with pytest.raises(InputError, match="non-finite"):
        LocalEstimate.from_dict({**good, "p": [[math.nan] * 6] * 6})
    with pytest.raises(InputError, match="beta"):
        GlobalEstimate.from_dict({"t_s": 1.0, "x": [0.0] * 6, "p": np.eye(6).tolist()})


@pytest.mark.parametrize("mode", ["modewise", "mixture", "reset"])
def test_an_allocation_older_than_the_local_filter_is_carried_forward(mode):
    imm = default_imm_params()
    local = LocalParams(imm=imm)
    main = MainParams(imm=imm, feedback=mode)
    state = LocalState("1")
    for o in _track(90)[::3]:
        state, _ = local_step(state, o, local)
    est = state.estimate()
    assert est is not None
    fused = fuse([est], est.t_s - 0.5, main)
    assert fused is not None
    fed = apply_feedback(state, fused, local, main)
    assert fed.imm is not None
    assert state.imm is not None
    assert fed.imm.t_s == state.imm.t_s
    assert all(is_spd(p) for p in fed.imm.p)
    assert fed.counters.feedback == 1


def test_a_late_allocation_replays_the_newer_observations():
    """An allocation of the filter's own state at an earlier time, arriving late, gives back
    the filter's current state: the observations since are replayed, not lost."""
    imm = default_imm_params()
    local = LocalParams(imm=imm)
    main = MainParams(imm=imm)
    obs = _track(150)[::3]
    state = LocalState("1")
    for o in obs[:40]:
        state, _ = local_step(state, o, local)
    earlier = state.estimate()
    assert earlier is not None
    for o in obs[40:45]:
        state, _ = local_step(state, o, local)
    fused = fuse([earlier], earlier.t_s, main)
    assert fused is not None
    fed = apply_feedback(state, fused, local, main)
    assert fed.imm is not None
    assert state.imm is not None
    assert fed.imm.t_s == state.imm.t_s
    np.testing.assert_allclose(fed.imm.x, state.imm.x, atol=1e-8)
    np.testing.assert_allclose(fed.imm.p, state.imm.p, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(fed.imm.mu, state.imm.mu, atol=1e-9)
    assert fed.counters == replace(state.counters, feedback=1)


def test_an_estimate_built_on_the_last_allocation_replaces_the_copy_and_one_built_before_not():
    """The main filter fused at t = 10 and holds its allocation copies at t = 10. An estimate
    built on that allocation replaces the copy (its sender's clock may be a little behind);
    one its sender made before it took the allocation is counted and dropped (its basis is
    in the allocation already), and so is one older than its sender's newest."""
    params = MainParams(feedback="mixture")
    state = main_receive(MainState(), _estimate("a", np.zeros(6), np.eye(6), t=9.8))
    state = main_receive(state, _estimate("b", np.zeros(6), np.eye(6), t=9.8))
    fused = main_fuse(state, 10.0, params)
    assert fused is not None
    assert dict(fused.included_t_s) == {"a": 9.8, "b": 9.8}
    state = main_allocate(state, fused, params)
    held = state.estimate_of("a")
    assert held is not None
    assert (held.t_s, held.alloc_t_s) == (10.0, 10.0)  # the copy
    moved = np.array([5.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    state = main_receive(state, replace(_estimate("a", moved, np.eye(6), t=9.9), alloc_t_s=9.0))
    assert state.stale_basis_dropped == 1
    assert state.estimate_of("a") == held
    built = replace(_estimate("a", moved, np.eye(6), t=9.95), alloc_t_s=10.0)
    state = main_receive(state, built)
    assert state.estimate_of("a") == built
    again = main_fuse(state, 10.1, params)
    assert again is not None
    assert again.x[0] > 1.0  # the estimate built on the allocation pulled the fused one east
    assert dict(again.included_t_s) == {"a": 9.95, "b": 9.8}
    state = main_receive(state, replace(built, t_s=9.85))
    assert state.out_of_order_dropped == 1
    assert state.stale_basis_dropped == 1


def test_a_sender_that_takes_no_allocation_is_fused_all_the_same():
    """An agent that refuses the allocations (as it refuses a fused estimate far less certain
    than its own, after a bus outage) keeps sending estimates on its old basis: dropped while
    the basis is recent, fused once it is ``ALLOCATION_IGNORED_AFTER_S`` old, or the main
    filter would starve and coast away from the target."""
    params = MainParams(feedback="mixture")
    state = main_receive(MainState(), _estimate("a", np.zeros(6), np.eye(6), t=9.8))
    fused = main_fuse(state, 10.0, params)
    assert fused is not None
    state = main_allocate(state, fused, params)
    moved = np.array([5.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    recent = replace(_estimate("a", moved, np.eye(6), t=10.5), alloc_t_s=9.0)
    state = main_receive(state, recent)
    assert (state.stale_basis_dropped, state.allocations_ignored) == (1, 0)
    late = replace(recent, t_s=9.0 + ALLOCATION_IGNORED_AFTER_S + 0.1)
    state = main_receive(state, late)
    assert (state.stale_basis_dropped, state.allocations_ignored) == (1, 1)
    assert state.estimate_of("a") == late


def test_an_estimate_built_on_the_allocation_before_is_not_counted_twice():
    """Over a bus, agent 1 makes an estimate before the last allocation reaches it: it holds
    that allocation's predecessor and its observation at 15.0, both in the last allocation
    already. Fused with the copies of the last allocation it would count them twice; the main
    filter drops it and fuses exactly what the centralised filter would of the observations
    it has (linear model), and once agent 1 takes the allocation and replays its observation,
    exactly the centralised estimate of them all."""
    model = MotionModel("ca", 0.01)
    local = LocalParams(
        imm=IMMParams((model,), np.eye(1)), init_speed_sigma_m_s=1e3, init_accel_sigma_m_s2=1e2
    )
    params = FederatedParams(local, MainParams(time_update=model, feedback="modewise"))
    obs = _track(456)
    fed = FederatedState()
    for o in obs[:450]:  # feedback after every observation: all built on one allocation
        fed, _, _ = federated_step(fed, o, params)
    filters = {s.sensor: s for s in fed.locals}
    main = fed.main

    def observe(o: Observation) -> LocalEstimate:
        filters[o.sensor], report = local_step(filters[o.sensor], o, local)
        assert report.used
        est = filters[o.sensor].estimate()
        assert est is not None
        return est

    for o in obs[450:453]:  # sensors 1, 2, 3 at 15.0, 15.033, 15.067
        main = main_receive(main, observe(o))
    alloc = main_fuse(main, obs[452].t_s, params.main)
    assert alloc is not None
    main = main_allocate(main, alloc, params.main)
    for s in ("2", "3"):  # the allocation reaches agents 2 and 3; agent 1's is on its way
        filters[s] = apply_feedback(filters[s], alloc, local, params.main)
    late_built = observe(obs[453])  # sensor 1 at 15.1, on the allocation before
    main = main_receive(main, late_built)
    assert main.stale_basis_dropped == 1
    for o in obs[454:456]:  # sensors 2, 3 at 15.133, 15.167
        main = main_receive(main, observe(o))
    t = obs[455].t_s
    fused = main_fuse(main, t, params.main)
    assert fused is not None
    central = run_centralised(obs[:453] + obs[454:456], local).fused
    np.testing.assert_allclose(fused.x, central.x[-1], atol=1e-6)
    np.testing.assert_allclose(fused.p, central.p[-1], atol=1e-6)

    filters["1"] = apply_feedback(filters["1"], alloc, local, params.main)
    rebuilt = filters["1"].estimate()
    assert rebuilt is not None
    assert rebuilt.alloc_t_s == alloc.t_s
    main = main_receive(main, rebuilt)
    fused = main_fuse(main, t, params.main)
    assert fused is not None
    central = run_centralised(obs[:456], local).fused
    np.testing.assert_allclose(fused.x, central.x[-1], atol=1e-6)
    np.testing.assert_allclose(fused.p, central.p[-1], atol=1e-6)


def test_an_allocation_replays_the_observations_its_fusion_lacks_even_older_ones():
    """A filter whose estimate at 1.0 was the last of its in the fusion at 1.05 replays its
    observation at 1.02 (late to the allocation) on top: it is not in the fusion."""
    imm = default_imm_params()
    local = LocalParams(imm=imm)
    main = MainParams(imm=imm)
    state = LocalState("1")
    for o in _track(90)[::3]:  # sensor 1, 0.0 .. 2.9 s every 0.1 s
        if o.t_s > 1.0:
            break
        state, _ = local_step(state, o, local)
    est = state.estimate()
    assert est is not None
    fused = fuse([est], 1.05, main)
    assert fused is not None
    fused = replace(fused, included_t_s=(("1", 1.0),))
    state, _ = local_step(state, Observation(1.02, "1", 3.1, 21.0), local)
    fed = apply_feedback(state, fused, local, main)
    assert [o.t_s for o in fed.recent] == [1.02]
    assert fed.alloc_t_s == 1.05
    # the same allocation with no word of what it holds replays only what is newer than it
    bare = apply_feedback(state, replace(fused, included_t_s=()), local, main)
    assert bare.recent == ()
    with_obs, without = fed.estimate(), bare.estimate()
    assert with_obs is not None
    assert without is not None
    assert np.trace(with_obs.p[:4:2, :4:2]) < np.trace(without.p[:4:2, :4:2])
