import itertools
import math

import numpy as np
import pytest

from sitl.target import Leg, Maneuver, TargetPath


def paper_path() -> TargetPath:
    return TargetPath.from_waypoints(
        0.0,
        0.0,
        [
            Leg(0.0, 300.0, 7.0, 1.0, label="A-B"),
            Leg(200.0, 300.0, 3.0, 1.0, label="B-C"),
            Leg(200.0, 0.0, None, 1.5, max_speed_m_s=12.0, stop=True, label="C-D"),
        ],
        wait_s=10.0,
    )


def test_waypoint_path_runs_through_its_legs_and_stops():
    path = paper_path()
    assert path.labels == ("wait", "A-B", "B-C", "C-D")
    assert path.state_at(5.0).speed_m_s == 0.0
    assert path.segment_at(5.0) == "wait"
    cruise = path.state_at(40.0)
    assert path.segment_at(40.0) == "A-B"
    assert cruise.speed_m_s == pytest.approx(7.0)
    assert cruise.v_north_m_s == pytest.approx(7.0)
    end = path.state_at(path.duration_s + 10.0)
    assert (end.east_m, end.north_m) == pytest.approx((200.0, 0.0), abs=1e-6)
    assert end.speed_m_s == 0.0


def test_speed_changes_respect_the_leg_acceleration():
    path = paper_path()
    times = np.arange(0.0, path.duration_s, 0.1)
    states = path.sample(times)
    speeds = np.hypot(states[:, 2], states[:, 3])
    assert np.all(np.abs(np.diff(speeds)) <= 3.0 * 0.1 + 1e-6)  # brake at most 3 m/s^2
    assert speeds.max() <= 12.0 + 1e-9


def test_positions_integrate_velocities():
    path = paper_path()
    times = np.arange(0.0, path.duration_s, 0.01)
    states = path.sample(times)
    moved = np.hypot(np.diff(states[:, 0]), np.diff(states[:, 1]))
    mean_speed = 0.5 * (
        np.hypot(states[:-1, 2], states[:-1, 3]) + np.hypot(states[1:, 2], states[1:, 3])
    )
    labels = [path.segment_at(t) for t in times]
    inside = np.array([a == b for a, b in itertools.pairwise(labels)])
    # within a segment the path moves as fast as it says; at the sharp corners it turns at once
    assert np.allclose(moved[inside], mean_speed[inside] * 0.01, atol=1e-3)


def test_maneuver_turn_has_centripetal_acceleration_and_turns_clockwise():
    quarter = math.pi / 2
    path = TargetPath.from_maneuvers(
        0.0,
        0.0,
        0.0,
        5.0,
        [
            Maneuver(10.0, label="straight"),
            Maneuver(50.0, turn_rate_rad_s=quarter / 50.0, label="turn"),
        ],
    )
    mid = path.state_at(35.0)
    assert math.hypot(mid.a_east_m_s2, mid.a_north_m_s2) == pytest.approx(
        5.0 * quarter / 50.0, rel=1e-6
    )
    end = path.state_at(60.0)
    assert end.v_east_m_s == pytest.approx(5.0, rel=1e-3)  # now heading east
    later = path.state_at(70.0)  # coasts on after the last manoeuvre
    assert later.east_m - end.east_m == pytest.approx(50.0, rel=1e-3)


def test_bad_paths_are_refused():
    with pytest.raises(ValueError, match="duration_s"):
        Maneuver(0.0)
    with pytest.raises(ValueError, match="speed_m_s"):
        Leg(1.0, 1.0, -3.0)
    with pytest.raises(ValueError, match="at least one"):
        TargetPath.from_waypoints(0.0, 0.0, [])
    with pytest.raises(ValueError, match="finite"):
        paper_path().state_at(math.nan)
