import math

import pytest

from app.core.mission.team import TeamSample, VehicleSample
from app.report.summary import summarize


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
    # vehicles keyed from 1, as users number them (the samples' index 0 is vehicle "1")
    assert set(adjust["vehicles"]) == {"1", "2", "3"}
    assert adjust["vehicles"]["1"]["distance_error_m"]["rms"] == pytest.approx(2.0)
    assert adjust["vehicles"]["2"]["distance_error_m"]["max_abs"] == pytest.approx(2.0)
    assert adjust["vehicles"]["3"]["speed_m_s"] == {"min": 16.0, "max": 16.0}
    assert adjust["team"]["spacing_error_deg"]["max_abs"] == pytest.approx(0.0, abs=1e-9)
    assert adjust["team"]["estimation_rmse"]["position_m"] == pytest.approx(1.0)
    assert adjust["team"]["estimation_rmse"]["velocity_m_s"] == pytest.approx(0.5)
    track = out["parts"]["track:B-C"]
    # gaps 110, 130, 120: vehicle 1's gap ahead is 10 degrees short, vehicle 2's 10 long
    assert track["vehicles"]["1"]["spacing_error_deg"]["rms"] == pytest.approx(10.0)
    assert track["vehicles"]["2"]["spacing_error_deg"]["rms"] == pytest.approx(10.0)
    assert track["vehicles"]["3"]["spacing_error_deg"]["rms"] == pytest.approx(0.0, abs=1e-9)
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


def test_a_track_segment_reports_its_transient_apart():
    """After a turn of the target the team is off the circle for a while: the segment's
    time_to_circle_s is when every vehicle is back within the tolerance for hold_s, and its
    settled figures are the errors from then on."""
    errors = [30.0 - 3.0 * t if t < 10 else 0.5 for t in range(40)]
    samples = [
        ring(float(t), 90.0, (0, 120, 240), (e, -e, 0.0), "track", "B-C")
        for t, e in enumerate(errors)
    ]
    team = summarize(samples, 90.0, 0.0, radius_tolerance_m=3.0, hold_s=5.0)["parts"]["track:B-C"][
        "team"
    ]
    assert team["time_to_circle_s"] == 9.0  # |30 - 3t| <= 3 from t = 9 on
    settled = team["settled"]["distance_error_m"]
    assert settled["max_abs"] == pytest.approx(3.0)  # t = 9 itself
    # two vehicles at +-3 m once, then +-0.5 m for 30 samples; the third on the circle
    assert settled["rms"] == pytest.approx(math.sqrt((2 * 9.0 + 60 * 0.25) / 93))
    assert team["distance_error_m"]["max_abs"] == pytest.approx(30.0)
    never = [ring(float(t), 90.0, (0, 120, 240), (9.0, 0, 0), "track", "C-D") for t in range(9)]
    part = summarize(never, 90.0, 0.0)["parts"]["track:C-D"]["team"]
    assert part["time_to_circle_s"] is None
    assert "settled" not in part
