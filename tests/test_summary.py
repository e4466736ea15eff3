import math

import pytest

from app.report.summary import TeamSample, VehicleSample, summarize


def ring(t, radius, offsets_deg, errors_m, stage, segment="wait", active=(True, True, True)):
    vehicles = []
    for i, (offset, err) in enumerate(zip(offsets_deg, errors_m, strict=True)):
        angle = 0.1 * t + math.radians(offset)
        r = radius + err
        vehicles.append(
            VehicleSample(i, active[i], r * math.cos(angle), r * math.sin(angle), 14.0 + i)
        )
    return TeamSample(t, stage, segment, 0.0, 0.0, 0.0, 0.0, (1.0, 0.0, 0.0, 0.5), tuple(vehicles))


def test_figures_per_part_and_vehicle():
    samples = [ring(t, 90.0, (0, 120, 240), (2.0, -2.0, 0.0), "adjust") for t in range(10)]
    samples += [
        ring(t, 90.0, (0, 110, 240), (4.0, 0.0, 0.0), "track", "B-C") for t in range(10, 20)
    ]
    out = summarize(samples, 90.0, tracking_command_t_s=0.0)
    adjust = out["parts"]["adjust"]
    assert adjust["vehicles"]["0"]["distance_error_m"]["rms"] == pytest.approx(2.0)
    assert adjust["vehicles"]["1"]["distance_error_m"]["max_abs"] == pytest.approx(2.0)
    assert adjust["vehicles"]["2"]["speed_m_s"] == {"min": 16.0, "max": 16.0}
    assert adjust["team"]["spacing_error_deg"]["max_abs"] == pytest.approx(0.0, abs=1e-9)
    assert adjust["team"]["estimation_rmse"]["position_m"] == pytest.approx(1.0)
    assert adjust["team"]["estimation_rmse"]["velocity_m_s"] == pytest.approx(0.5)
    track = out["parts"]["track:B-C"]
    # gaps 110, 130, 120: vehicle 0's gap ahead is 10 degrees short, vehicle 1's 10 long
    assert track["vehicles"]["0"]["spacing_error_deg"]["rms"] == pytest.approx(10.0)
    assert track["vehicles"]["1"]["spacing_error_deg"]["rms"] == pytest.approx(10.0)
    assert track["vehicles"]["2"]["spacing_error_deg"]["rms"] == pytest.approx(0.0, abs=1e-9)
    assert track["team"]["start_s"] == 10.0


def test_convergence_times_count_from_the_tracking_command():
    samples = [ring(t, 90.0, (0, 60, 240), (50.0 - 5 * t, 0.0, 0.0), "gather") for t in range(5)]
    samples += [ring(t, 90.0, (0, 120, 240), (1.0, 1.0, 1.0), "adjust") for t in range(5, 30)]
    samples += [
        ring(t, 90.0, (0, 120, 240), (1.0, 1.0, 1.0), "track", "A-B") for t in range(30, 40)
    ]
    out = summarize(samples, 90.0, tracking_command_t_s=2.0, hold_s=5.0)
    conv = out["convergence"]
    assert conv["time_to_circle_s"] == 3.0  # t = 5 is the first formed instant
    assert conv["time_to_spacing_s"] == 3.0
    assert conv["time_to_formation_s"] == 3.0


def test_an_inactive_vehicle_is_left_out_of_spacing():
    s = ring(0.0, 90.0, (0, 180, 90), (0.0, 0.0, 300.0), "track", "A-B", (True, True, False))
    assert s.spacing_errors() == pytest.approx({0: 0.0, 1: 0.0}, abs=1e-9)
    assert set(s.distance_errors(90.0)) == {0, 1}


def test_never_formed_gives_none():
    samples = [ring(t, 90.0, (0, 10, 20), (0.0, 0.0, 0.0), "adjust") for t in range(10)]
    assert summarize(samples, 90.0, 0.0)["convergence"]["time_to_formation_s"] is None
