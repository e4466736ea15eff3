"""The formation-time bounds of benchmarks/bench_gather_bound.py: shortest paths that really join
their poses, and the two ways of joining a team to the circle."""

import json
import math

import pytest

from app.config import load_config
from app.config.mission import MissionConfig
from app.core.guidance.dubins import dubins, seat_pose
from benchmarks.bench_gather_bound import gather_times, run_bounds, run_starts

R = 90.0


def test_a_seat_each_is_never_slower_than_one_joining_point():
    # three vehicles together 1 km west of the circle, flying east: with one joining point the
    # last joins two spacing gaps (2 x 188.5 m of arc at 18 m/s) after the first can get there
    centre, speed = (0.0, 0.0), 18.0
    start = (-1000.0, 0.0, 0.0)
    one, each = gather_times([start] * 3, centre, 90.0, 1, speed, R)
    first = min(
        dubins(start, seat_pose(centre, 90.0, math.radians(k), 1), R).length_m for k in range(360)
    )
    assert one == pytest.approx(first / speed + 2 * (2 * math.pi * 90.0 / 3) / speed)
    assert first / speed <= each < one
    # alone, there is nothing to space: both are the quickest way onto the circle
    alone = gather_times([start], centre, 90.0, 1, speed, R)
    assert alone[0] == pytest.approx(first / speed)
    assert alone[1] == pytest.approx(first / speed)
    # the seat on the far side of the circle is joined clockwise by a clockwise team
    cw_one, cw_each = gather_times([start] * 3, centre, 90.0, -1, speed, R)
    assert cw_one == pytest.approx(one, rel=0.02)
    assert cw_each == pytest.approx(each, rel=0.02)
    with pytest.raises(ValueError):
        gather_times([], centre, 90.0, 1, speed, R)


def test_the_team_at_the_tracking_command_is_read_from_a_run_folder(tmp_path):
    (tmp_path / "config.json").write_text(json.dumps({"mission": {"tracking_command_s": 10.0}}))
    (tmp_path / "summary.json").write_text(
        json.dumps({"convergence": {"time_to_formation_s": 71.5}})
    )
    rows = ["t_s,vehicle,east_m,north_m,course_rad,speed_m_s"]
    for t in (9.9, 10.0, 10.1):
        for v in (2, 1):
            rows.append(f"{t},{v},{-1000.0 + t + v},{5.0 * v},{0.5 * v},14.0")
    (tmp_path / "track.csv").write_text("\n".join(rows) + "\n")
    starts, command, formed = run_starts(tmp_path)
    assert command == 10.0
    assert formed == 71.5
    assert starts == [
        pytest.approx((-989.0, 5.0, math.pi / 2 - 0.5)),
        pytest.approx((-988.0, 10.0, math.pi / 2 - 1.0)),
    ]


def test_a_runs_bounds_are_taken_from_where_its_team_was_on_its_configs_circle(tmp_path):
    # bench_load prints these beside each run's formation time
    cfg = load_config("hil", MissionConfig)
    (tmp_path / "config.json").write_text(json.dumps({"mission": {"tracking_command_s": 10.0}}))
    (tmp_path / "summary.json").write_text(json.dumps({"convergence": {}}))
    rows = ["t_s,vehicle,east_m,north_m,course_rad,speed_m_s"]
    poses = {1: (-850.0, 98.0, 0.0), 2: (-950.0, 30.0, 1.0), 3: (-1050.0, -40.0, 2.0)}
    for v, (e, n, course) in poses.items():
        rows.append(f"10.0,{v},{e},{n},{course},14.0")
    (tmp_path / "track.csv").write_text("\n".join(rows) + "\n")
    one, each, formed = run_bounds(tmp_path, cfg)
    assert formed is None
    speed = cfg.limits.max_speed_m_s
    starts = [(e, n, math.pi / 2 - c) for e, n, c in poses.values()]
    turn = speed / cfg.limits.max_course_rate_rad_s
    assert (one, each) == pytest.approx(
        gather_times(starts, (0.0, 0.0), cfg.radius_m, 1, speed, turn)
    )
    # about 1 km from the circle at 18 m/s: about a minute, more with the turns
    assert 50.0 < each < one < 100.0
