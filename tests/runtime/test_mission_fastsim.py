"""The mission fast-sim: the live mission's logic in one deterministic loop."""

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from app.compose.mission_fastsim import MissionSimSetup, run_mission_sim, track_figures
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan


@pytest.fixture(scope="module")
def plan():
    return build_plan(load_config("hil", MissionConfig))


def _short(plan, **kw):
    # the tracking command is at 10 s; 40 s covers standby and most of the gather
    return run_mission_sim(MissionSimSetup(plan, end_t_s=40.0, **kw))


@pytest.mark.slow
def test_it_is_deterministic_for_a_seed(plan):
    a, b = _short(plan, seed=3), _short(plan, seed=3)
    np.testing.assert_array_equal(a.commands, b.commands)
    assert a.summary == b.summary
    c = _short(plan, seed=4)
    assert not np.array_equal(a.commands, c.commands)


@pytest.mark.slow
@pytest.mark.parametrize("latency", [0, 1])
def test_commands_are_finite_and_within_the_limits(plan, latency):
    """The agents compensate the delay (latency_s) and the 0.1 s hold (hold_s); the implied
    course rate is measured against the course the vehicle has when the command starts to act,
    so there it asks at most W (1 + k (latency_s + hold_s / 2)), W at the hold's middle, up to
    the prediction's error (see tests/core/test_latency_and_speed_cap.py)."""
    agents = tuple(replace(a, latency_s=0.1 * latency, hold_s=0.1) for a in plan.agents)
    result = _short(replace(plan, agents=agents), latency_ticks=latency)
    lim = plan.config.limits
    cmd = result.commands
    assert cmd.shape == (3 * (401 - latency), 5)  # the last `latency` ticks never act
    assert np.isfinite(cmd).all()
    assert (cmd[:, 3] >= lim.min_speed_m_s).all()
    assert (cmd[:, 3] <= lim.max_speed_m_s).all()
    lead_s = 0.1 * latency + 0.05
    bound = lim.max_course_rate_rad_s * (1.0 + lim.course_gain_per_s * lead_s) * 1.005
    assert (np.abs(cmd[:, 4]) <= bound).all()
    stages = {s.stage for s in result.samples}
    assert stages == {"standby", "gather"}
    # the estimate is on the (still waiting) target to within a few metres
    est = result.samples[-1].estimate
    assert est is not None
    assert abs(est[0]) < 3.0
    assert abs(est[1]) < 3.0


def test_bad_setups_are_rejected(plan):
    with pytest.raises(ValueError):
        MissionSimSetup(plan, control_period_s=0.0)
    with pytest.raises(ValueError):
        MissionSimSetup(plan, latency_ticks=-1)
    with pytest.raises(ValueError):
        MissionSimSetup(plan, truth_fed=True, truth_of="speed")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        MissionSimSetup(plan, truth_fed=True, truth_lag_s=-1.0)
    with pytest.raises(ValueError):
        run_mission_sim(MissionSimSetup(plan, end_t_s=1.0, track_override=()))


def test_track_figures_read_the_summary_parts(plan):
    result = _short(plan)
    assert track_figures(result, plan.target.labels) == {}


@pytest.mark.slow
def test_truth_fed_agents_steer_on_the_true_target_not_their_estimates():
    # a camera so noisy (50 m per axis) that steering on the estimates is visibly worse
    plan = build_plan(load_config("test-short", MissionConfig))
    figures = {}
    for truth_fed in (False, True):
        setup = MissionSimSetup(
            plan, seed=1, camera_sigma2_m2=2500.0, end_t_s=85.0, truth_fed=truth_fed
        )
        result = run_mission_sim(setup)
        figures[truth_fed] = track_figures(result, plan.target.labels)["A-B"]["dist_rms_m"]
    assert figures[True] < 3.0
    assert figures[False] > 3.0 * figures[True]


@pytest.mark.slow
def test_truth_fed_in_part_or_late_steers_between_the_truth_and_the_estimates():
    # the noisy camera as above: the true position with the estimated velocity, the true
    # velocity with the estimated position, or the true target with a velocity 20 s old (the
    # target still parked then, for half the leg) each fly between the two
    plan = build_plan(load_config("test-short", MissionConfig))

    def flown(**truth: Any) -> float:
        setup = MissionSimSetup(plan, seed=1, camera_sigma2_m2=2500.0, end_t_s=85.0, **truth)
        result = run_mission_sim(setup)
        return float(track_figures(result, plan.target.labels)["A-B"]["dist_rms_m"])

    estimates = flown()
    exact = flown(truth_fed=True)
    partial = {
        "position": flown(truth_fed=True, truth_of="position"),
        "velocity": flown(truth_fed=True, truth_of="velocity"),
        "late velocity": flown(truth_fed=True, truth_lag_s=20.0),
    }
    assert exact < 1.0
    for what, figure in partial.items():
        assert 3.0 * exact < figure < estimates, (what, figure, exact, estimates)
