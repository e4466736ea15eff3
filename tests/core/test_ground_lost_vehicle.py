"""A vehicle the ground no longer hears is shown where it was last known, not flown on."""

import math
from dataclasses import replace

import numpy as np

from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.core.estimation.messages import GlobalEstimate
from app.core.mission.ground import VehicleReport, initial_ground_state, team_sample


def test_a_silent_vehicle_is_dead_reckoned_no_further_than_the_lost_time() -> None:
    plan = build_plan(load_config("test-short", MissionConfig))
    lost_after = plan.ground.lost_after_s
    fused = GlobalEstimate(10.0, np.zeros(6), np.eye(6), (("0", 1.0),))
    # vehicle 0 heard at 10 s flying north at 14 m/s; vehicle 1 heard just now
    heard = VehicleReport(10.0, 90.0, 0.0, 0.0, 14.0)
    fresh = VehicleReport(200.0, -90.0, 0.0, 0.0, 14.0)
    state = replace(
        initial_ground_state(), fused=fused, reports=((0, heard), (1, fresh)), active=(1,)
    )
    soon = team_sample(state, 10.0 + 0.5 * lost_after, plan.ground)
    late = team_sample(state, 200.0, plan.ground)
    assert soon is not None
    assert late is not None
    # within the lost time the vehicle is carried along its course...
    assert math.isclose(soon.vehicles[0].north_m, 14.0 * 0.5 * lost_after)
    # ...and after it, held where it would have been when it was lost (not 190 s x 14 m/s on)
    assert math.isclose(late.vehicles[0].north_m, 14.0 * lost_after)
    assert not late.vehicles[0].active
