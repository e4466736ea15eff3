"""The issue's accuracy figures, on shorter runs than the benchmark (see docs/estimation.md).

Fig. 12-like path, first 290 s (the first straight leg and the first turn), one seed, scored
after the first 10 s (the start-up from an unknown velocity weighs 2.4 times more in a 290 s run
than in the full 700 s one); the section 5.2 path in full. The benchmark
(``python -m benchmarks.bench_estimation``) scores the whole 700 s path from t = 0 over several
seeds and every feedback design.
"""

from dataclasses import dataclass

import numpy as np
import pytest

from app.config import load_config
from app.config.estimator import load_estimator
from app.config.scenario import EstimationScenarioConfig
from app.core.estimation.metrics import ErrorSeries, errors, nees_band
from app.core.estimation.pipeline import FederatedParams, run_centralised, run_federated
from sitl.fixes import ScenarioData, generate

pytestmark = pytest.mark.slow

WARM_UP_S = 10.0


def _data(name: str, seed: int, duration_s: float | None = None) -> ScenarioData:
    scenario = load_config(name, EstimationScenarioConfig)
    return generate(scenario.target.build(), scenario.sensors.build(), seed, duration_s)


@dataclass
class Runs:
    fused: ErrorSeries
    central: ErrorSeries
    locals_: list[ErrorSeries]


@pytest.fixture(scope="module")
def params() -> FederatedParams:
    return load_estimator()


@pytest.fixture(scope="module")
def fig12(params: FederatedParams) -> Runs:
    data = _data("est-fig12", seed=2, duration_s=290.0)

    def score(track) -> ErrorSeries:
        keep = track.t_s >= WARM_UP_S
        return errors(
            track.t_s[keep], track.x[keep], data.truth_t_s, data.truth, data.segments, track.p[keep]
        )

    fused = score(run_federated(data.observations, params).fused)
    central = score(run_centralised(data.observations, params.local).fused)
    locals_ = []
    for sensor in ("1", "2", "3"):
        own = [o for o in data.observations if o.sensor == sensor]
        locals_.append(score(run_centralised(own, params.local, sensor).fused))
    return Runs(fused, central, locals_)


def test_fused_position_and_velocity_rmse(fig12: Runs):
    pos, vel = fig12.fused.rmse()
    turn_pos, _ = fig12.fused.rmse(fig12.fused.mask_for("turn"))
    assert pos <= 0.65
    assert turn_pos <= 0.9
    assert vel <= 0.4


def test_federated_within_5_percent_of_centralised_and_better_than_each_local(fig12: Runs):
    fused, _ = fig12.fused.rmse()
    central, _ = fig12.central.rmse()
    assert fused <= 1.05 * central
    for local in fig12.locals_:
        assert fused < local.rmse()[0]


def test_mean_nees_on_straight_legs_is_inside_the_95_percent_band(fig12: Runs):
    lo, hi = nees_band(1)
    straight = fig12.fused.mask_for("straight")
    assert straight.sum() > 1000
    assert lo <= float(np.mean(fig12.fused.nees[straight])) <= hi


def test_section_5_2_path(params: FederatedParams):
    data = _data("est-hil", seed=2)
    track = run_federated(data.observations, params).fused
    series = errors(track.t_s, track.x, data.truth_t_s, data.truth, data.segments)
    assert set(series.segments) >= {"high speed", "low speed B-C", "accelerating"}
    assert series.rmse()[0] <= 0.75
