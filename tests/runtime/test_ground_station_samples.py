"""What the ground station records each tick (its ``TeamSample``s), without I/O."""

from dataclasses import replace

import numpy as np
import pytest

from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.core.estimation.messages import GlobalEstimate
from app.core.mission.ground import VehicleReport, initial_ground_state, team_sample


@pytest.mark.parametrize("with_truth", [True, False])
def test_a_sample_scores_the_estimate_only_against_a_truth(with_truth: bool) -> None:
    plan = build_plan(load_config("test-short", MissionConfig))
    fused = GlobalEstimate(
        10.0, np.array([5.0, 0.0, -3.0, 0.0, 0.0, 0.0]), np.eye(6), (("0", 1.0),)
    )
    report = VehicleReport(10.0, 90.0, 0.0, 0.0, 14.0)
    state = replace(initial_ground_state(), fused=fused, reports=((0, report),), active=(0,))
    sample = team_sample(state, 10.0, plan.ground, plan.target if with_truth else None)
    assert sample is not None
    if with_truth:
        truth = plan.target.state_at(10.0)
        assert (sample.target_east_m, sample.target_north_m) == (truth.east_m, truth.north_m)
        assert sample.estimate == pytest.approx((5.0, -3.0, 0.0, 0.0))
    else:
        # no truth (external vehicles, their own cameras): the orbit is scored about the
        # estimate, and there is no estimation error to report (it would read 0)
        assert sample.target_segment == "estimated"
        assert (sample.target_east_m, sample.target_north_m) == pytest.approx((5.0, -3.0))
        assert sample.estimate is None
