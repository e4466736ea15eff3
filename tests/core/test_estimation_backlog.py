"""merge_backlog: a queue of observations folded into one per window, without losing what
they say about a target moving at constant velocity."""

import math

import numpy as np
import pytest

from app.config.estimator import load_estimator
from app.core.estimation.backlog import merge_backlog
from app.core.estimation.local import LocalParams, initial_state, local_step
from app.core.estimation.messages import Observation


def cv(t: float) -> tuple[float, float]:
    return 5.0 + 7.0 * t, -3.0 + 2.0 * t


def test_one_or_none_pass_unchanged():
    obs = Observation(1.0, "0", 2.0, 3.0, 4.0)
    assert merge_backlog([], 0.3, 3.0) == []
    assert merge_backlog([obs], 0.3, 3.0) == [obs]


def test_a_run_becomes_the_position_at_its_mean_time_with_the_combined_sigma():
    times = [10.0, 10.1, 10.2]
    merged = merge_backlog([Observation(t, "0", *cv(t), 3.0) for t in times], 0.3, 9.0)
    assert len(merged) == 1
    m = merged[0]
    assert m.t_s == pytest.approx(10.1)
    assert (m.east_m, m.north_m) == pytest.approx(cv(10.1))
    assert m.sigma_m == pytest.approx(3.0 / math.sqrt(3))
    assert m.sensor == "0"


def test_weights_follow_each_sigma_and_a_missing_one_is_the_default():
    a = Observation(0.0, "0", 0.0, 0.0, 1.0)
    b = Observation(0.0, "0", 10.0, 0.0, None)  # default 3: weight 1/9 against 1
    (m,) = merge_backlog([b, a], 0.3, 3.0)
    assert m.east_m == pytest.approx(10.0 * (1 / 9) / (1 + 1 / 9))
    assert m.sigma_m == pytest.approx(1.0 / math.sqrt(1 + 1 / 9))


def test_windows_sensors_and_bad_values_split_the_runs():
    obs = [Observation(0.1 * k, "0", *cv(0.1 * k), 3.0) for k in range(10)]  # 0.0 .. 0.9 s
    other = Observation(0.15, "1", 0.0, 0.0, 3.0)
    bad = Observation(0.25, "0", math.nan, 0.0, 3.0)
    merged = merge_backlog([*obs, other, bad], 0.3, 3.0)
    assert bad in merged  # passed on for the filter to refuse and count
    assert other in merged
    zeros = [m for m in merged if m.sensor == "0" and math.isfinite(m.east_m)]
    # windows of at most 0.3 s from each run's first observation; every fix counted once
    assert sum(round((3.0 / (m.sigma_m or math.inf)) ** 2) for m in zeros) == 10
    assert len(zeros) < 10
    for m in zeros:
        assert (m.east_m, m.north_m) == pytest.approx(cv(m.t_s))


def test_a_filter_fed_the_merged_backlog_ends_where_the_one_fed_each_fix_does():
    config = load_estimator("estimator")
    params: LocalParams = config.local
    rng = np.random.default_rng(4)
    times = np.arange(0.0, 20.0, 0.1)
    noise = rng.normal(0.0, 3.0, (len(times), 2))
    fixes = [
        Observation(float(t), "0", cv(float(t))[0] + e, cv(float(t))[1] + n, 3.0)
        for t, (e, n) in zip(times, noise, strict=True)
    ]
    each = merged = initial_state("0")
    for obs in fixes[:50]:  # both start on the same 5 s
        each, _ = local_step(each, obs, params)
        merged, _ = local_step(merged, obs, params)
    for obs in fixes[50:]:
        each, _ = local_step(each, obs, params)
    for obs in merge_backlog(fixes[50:], 0.3, 3.0):  # 15 s that queued: 50 updates, not 150
        merged, _ = local_step(merged, obs, params)
    a, b = each.estimate(), merged.estimate()
    assert a is not None
    assert b is not None
    truth = np.array(cv(a.t_s))
    at_b = b.x[[0, 2]] + b.x[[1, 3]] * (a.t_s - b.t_s)  # carried to the same time
    assert np.linalg.norm(a.x[[0, 2]] - truth) < 1.5
    assert np.linalg.norm(at_b - truth) < 1.5
    assert np.linalg.norm(b.x[[1, 3]] - np.array([7.0, 2.0])) < 0.5
