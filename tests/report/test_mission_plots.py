import math

import matplotlib.image as mpimg
import pytest

from app.core.mission.team import TeamSample, VehicleSample
from app.report.mission_plots import plot_mission


def sample(t, stage, segment):
    target_e = 3.0 * max(0.0, t - 60.0)
    vehicles = []
    for i in range(3):
        r = 90.0 + 200.0 * math.exp(-t / 10.0)
        a = 0.15 * t + i * (2.0 + 0.1 * math.exp(-t / 20.0))
        vehicles.append(VehicleSample(i, True, target_e + r * math.cos(a), r * math.sin(a), 14.0))
    return TeamSample(t, stage, segment, target_e, 0.0, 3.0, 0.0, None, tuple(vehicles))


@pytest.mark.slow
def test_mission_plots_are_written_as_images(tmp_path):
    samples = [sample(0.5 * k, "gather", "wait") for k in range(40)]
    samples += [sample(0.5 * k, "adjust", "wait") for k in range(40, 120)]
    samples += [sample(0.5 * k, "track", "B-C") for k in range(120, 200)]
    paths = plot_mission(samples, 90.0, tmp_path)
    assert [p.name for p in paths] == [
        "trajectories.png",
        "distance_error.png",
        "phase_difference.png",
    ]
    for path in paths:
        image = mpimg.imread(path)
        assert image.shape[0] > 200
        assert image.shape[1] > 600  # three panels side by side
        assert image.std() > 0.01  # not a blank canvas


def test_no_samples_no_plots(tmp_path):
    assert plot_mission([], 90.0, tmp_path) == []
