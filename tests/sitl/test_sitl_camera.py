"""The simulated tracking camera (noise, dropouts, outliers, range) and determinism under a seed."""

import math
from dataclasses import replace

import numpy as np
import pytest

from sitl.camera import TrackingCamera
from sitl.config import CameraConfig, SimConfig, WindConfig, default_vehicles
from sitl.server import SimulatorServer
from sitl.target import TargetState

TARGET = TargetState(0.0, 100.0, -50.0, 0.0, 0.0, 0.0, 0.0)


def _errors(camera: TrackingCamera, n: int) -> np.ndarray:
    out = []
    for k in range(n):
        obs = camera.observe(0.1 * k, 0.0, 0.0, 100.0, TARGET)
        out.append(
            (math.nan, math.nan) if obs is None else (obs.east_m - 100.0, obs.north_m + 50.0)
        )
    return np.array(out)


def test_default_noise_is_10_m2_per_axis_and_unbiased():
    errors = _errors(TrackingCamera(CameraConfig(), np.random.default_rng(1)), 20_000)
    assert np.var(errors[:, 0]) == pytest.approx(10.0, rel=0.05)
    assert np.var(errors[:, 1]) == pytest.approx(10.0, rel=0.05)
    assert abs(np.mean(errors[:, 0])) < 0.1
    assert abs(np.corrcoef(errors.T)[0, 1]) < 0.03


def test_same_seed_same_noise_and_dropouts_do_not_shift_the_sequence():
    clean = _errors(TrackingCamera(CameraConfig(), np.random.default_rng(5)), 2_000)
    again = _errors(TrackingCamera(CameraConfig(), np.random.default_rng(5)), 2_000)
    other = _errors(TrackingCamera(CameraConfig(), np.random.default_rng(6)), 2_000)
    np.testing.assert_array_equal(clean, again)
    assert not np.allclose(clean, other)
    lossy = _errors(
        TrackingCamera(CameraConfig(dropout_probability=0.3), np.random.default_rng(5)), 2_000
    )
    dropped = np.isnan(lossy[:, 0])
    assert dropped.mean() == pytest.approx(0.3, abs=0.04)
    np.testing.assert_array_equal(lossy[~dropped], clean[~dropped])


def test_outliers_are_flagged_and_wide():
    camera = TrackingCamera(
        CameraConfig(outlier_probability=0.1, outlier_sigma_m=50.0), np.random.default_rng(2)
    )
    sightings = [camera.observe(0.0, 0.0, 0.0, 100.0, TARGET) for _ in range(5_000)]
    outliers = [s for s in sightings if s is not None and s.outlier]
    assert len(outliers) / len(sightings) == pytest.approx(0.1, abs=0.02)
    spread = np.std([s.east_m - s.true_east_m for s in outliers])
    assert spread == pytest.approx(math.sqrt(50.0**2 + 10.0), rel=0.1)


def test_range_dependent_noise_and_maximum_range():
    config = CameraConfig(sigma2_m2=10.0, range_sigma_per_m=0.02, max_range_m=1000.0)
    camera = TrackingCamera(config, np.random.default_rng(3))
    near = camera.observe(0.0, 100.0, -50.0, 100.0, TARGET)
    assert near is not None
    assert near.range_m == pytest.approx(100.0)
    assert near.sigma_m == pytest.approx(math.sqrt(10.0 + 4.0))
    assert camera.observe(0.0, 2000.0, 0.0, 100.0, TARGET) is None
    camera.enabled = False
    assert camera.observe(0.0, 100.0, -50.0, 100.0, TARGET) is None


def _run(seed: int) -> tuple[list, tuple]:
    config = SimConfig(
        vehicles=default_vehicles(3),
        seed=seed,
        wind=WindConfig(east_m_s=3.0, gust_sigma_m_s=1.0),
        camera=CameraConfig(dropout_probability=0.2, outlier_probability=0.05),
        takeoff="launch",
    )
    sim = SimulatorServer(config)
    for vehicle in sim.vehicles:  # launch them all (arm), no client needed
        vehicle.arm(0.0)
    truth = sim.run_offline(30.0)
    return [(sysid, o.t_s, o.east_m, o.north_m) for sysid, o in sim.observations], truth.vehicles


def test_the_simulation_is_deterministic_under_a_seed():
    obs_a, vehicles_a = _run(11)
    obs_b, vehicles_b = _run(11)
    obs_c, vehicles_c = _run(12)
    assert obs_a == obs_b
    assert [v.state for v in vehicles_a] == [v.state for v in vehicles_b]
    assert obs_a != obs_c
    assert [v.state for v in vehicles_a] != [v.state for v in vehicles_c]  # gusts differ
    # 3 cameras at 10 Hz for 30 s, 20 % dropped
    assert len(obs_a) == pytest.approx(0.8 * 900, rel=0.1)


def test_a_vehicle_camera_stream_does_not_depend_on_the_team_size():
    small = SimulatorServer(SimConfig(vehicles=default_vehicles(2), seed=3))
    large = SimulatorServer(
        replace(small.config, vehicles=default_vehicles(2) + default_vehicles(3))
    )
    draws_small = small.vehicles[1].camera.observe(0.0, 0.0, 0.0, 100.0, TARGET)
    draws_large = large.vehicles[1].camera.observe(0.0, 0.0, 0.0, 100.0, TARGET)
    assert draws_small == draws_large
