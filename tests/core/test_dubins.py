"""Shortest paths with a least turn radius and the team's joining plan
(``app.core.guidance.dubins``)."""

import itertools
import math

import numpy as np
import pytest

from app.core.guidance.dubins import (
    dubins,
    dubins_words,
    flight_time,
    follow,
    ground_speed,
    join_plan,
    sample_path,
    seat_pose,
)

R = 90.0


def _same_pose(a, b):
    heading = (a[2] - b[2] + math.pi) % (2 * math.pi) - math.pi
    return math.hypot(a[0] - b[0], a[1] - b[1]) < 1e-6 and abs(heading) < 1e-9


def test_every_word_found_flies_from_the_start_to_the_goal():
    rng = np.random.default_rng(7)
    words = set()
    for _ in range(300):
        start = (*rng.uniform(-300.0, 300.0, 2), rng.uniform(-4.0, 4.0))
        goal = (*rng.uniform(-300.0, 300.0, 2), rng.uniform(-4.0, 4.0))
        found = dubins_words(start, goal, R)
        assert found
        for path in found:
            words.add(path.word)
            assert _same_pose(follow(start, path, R), goal), path
            assert path.length_m >= math.hypot(goal[0] - start[0], goal[1] - start[1]) - 1e-9
        assert dubins(start, goal, R).length_m == min(p.length_m for p in found)
    assert words == {"LSL", "RSR", "LSR", "RSL", "RLR", "LRL"}


def test_the_shortest_paths_of_known_cases():
    # straight on
    path = dubins((0.0, 0.0, 0.0), (500.0, 0.0, 0.0), R)
    assert path.length_m == pytest.approx(500.0)
    # a U-turn onto the parallel line two radii to the left: half a circle
    assert dubins((0.0, 0.0, 0.0), (0.0, 2 * R, math.pi), R).length_m == pytest.approx(math.pi * R)
    # a quarter turn left onto a point a radius ahead and a radius to the left
    assert dubins((0.0, 0.0, 0.0), (R, R, math.pi / 2), R).length_m == pytest.approx(
        math.pi * R / 2
    )
    with pytest.raises(ValueError):
        dubins((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.0)


def test_a_sampled_path_runs_from_its_start_to_its_end_a_step_at_a_time():
    start, goal = (0.0, 0.0, 0.3), (300.0, 200.0, 2.0)
    path = dubins(start, goal, R)
    points = sample_path(start, path, R, 2.0)
    assert _same_pose(points[-1][:3], goal)
    steps = [math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(points)]
    assert max(steps) <= 2.0 + 1e-9
    assert sum(steps) == pytest.approx(path.length_m, rel=1e-4)  # chords of the arcs
    assert {p[3] for p in points[1:]} <= {1.0 / R, -1.0 / R, 0.0}
    with pytest.raises(ValueError):
        sample_path(start, path, R, 0.0)


def test_the_ground_speed_and_the_flight_time_in_a_wind():
    # along the wind, against it, across it (crabbing), and a cross wind stronger than the air
    assert ground_speed(15.0, 0.0, (3.0, 0.0)) == pytest.approx(18.0)
    assert ground_speed(15.0, math.pi, (3.0, 0.0)) == pytest.approx(12.0)
    assert ground_speed(15.0, math.pi / 2, (3.0, 0.0)) == pytest.approx(math.sqrt(15.0**2 - 9.0))
    assert ground_speed(2.0, math.pi / 2, (3.0, 0.0)) == 0.0
    straight = dubins((0.0, 0.0, math.pi), (-600.0, 0.0, math.pi), R)
    assert flight_time((0.0, 0.0, math.pi), straight, R, 15.0) == pytest.approx(40.0)
    assert flight_time((0.0, 0.0, math.pi), straight, R, 15.0, (3.0, 0.0)) == pytest.approx(50.0)
    # a full turn in a wind: slower downwind of nothing, the time of each piece at its speed
    loop = dubins((0.0, 0.0, 0.0), (0.0, 2 * R, math.pi), R)  # half a circle, left
    calm = flight_time((0.0, 0.0, 0.0), loop, R, 15.0)
    assert calm == pytest.approx(math.pi * R / 15.0)
    headwind = flight_time((0.0, 0.0, 0.0), loop, R, 15.0, (0.0, -3.0))  # against the climb
    assert headwind > calm
    assert math.isinf(flight_time((0.0, 0.0, math.pi), straight, R, 2.0, (3.0, 0.0)))


def test_the_joining_plan_puts_each_vehicle_on_its_own_seat_and_the_slowest_first():
    # three vehicles 1 km west, flying east, 150 m apart: seats 120 degrees apart, one each,
    # and no other placing of the seats gets the slowest there sooner
    starts = [(-1000.0, -150.0, 0.0), (-1000.0, 0.0, 0.0), (-1000.0, 150.0, 0.0)]
    plan = join_plan(starts, (0.0, 0.0), 90.0, 1, 18.0, R, band_s=0.0)
    gaps = sorted(round(math.degrees(a)) % 360 for a in plan.seat_angles_rad)
    assert np.diff(gaps).tolist() == [120, 120]
    times = [
        dubins(s, seat_pose((0.0, 0.0), 90.0, a, 1), R).length_m / 18.0
        for s, a in zip(starts, plan.seat_angles_rad, strict=True)
    ]
    assert plan.time_s == pytest.approx(max(times))
    for shift in range(0, 360, 7):
        for order in ((0, 1, 2), (2, 1, 0), (1, 0, 2)):
            seats = [math.radians(gaps[0] + shift + 120 * order[k]) for k in range(3)]
            other = max(
                dubins(s, seat_pose((0.0, 0.0), 90.0, a, 1), R).length_m / 18.0
                for s, a in zip(starts, seats, strict=True)
            )
            assert other >= plan.time_s - 1e-9
    # with a band of 0.5 s the middle of the near-quickest placings: at most 0.5 s slower
    banded = join_plan(starts, (0.0, 0.0), 90.0, 1, 18.0, R)
    assert plan.time_s <= banded.time_s <= plan.time_s + 0.5
    # agents whose views of the team differ by a few metres and degrees (statuses a tick old)
    # find seats within a few degrees of each other
    team = [(-900.0, 120.0, 2.6), (-930.0, 150.0, 2.2), (-960.0, 160.0, 1.9)]
    agreed = join_plan(team, (0.0, 0.0), 90.0, 1, 18.0, 99.0).seat_angles_rad
    rng = np.random.default_rng(2)
    for _ in range(6):
        view = [
            (x + rng.uniform(-2.0, 2.0), y + rng.uniform(-2.0, 2.0), h + rng.uniform(-0.03, 0.03))
            for x, y, h in team
        ]
        found = join_plan(view, (0.0, 0.0), 90.0, 1, 18.0, 99.0).seat_angles_rad
        for a, b in zip(found, agreed, strict=True):
            assert abs((math.degrees(a - b) + 180.0) % 360.0 - 180.0) <= 3.0
    # the same team in a head wind takes longer
    windy = join_plan(starts, (0.0, 0.0), 90.0, 1, 18.0, R, (-3.0, 0.0))
    assert windy.time_s > plan.time_s
    with pytest.raises(ValueError):
        join_plan(starts * 2, (0.0, 0.0), 90.0, 1, 18.0, R)  # six: too many to search
    with pytest.raises(ValueError):
        join_plan(starts, (0.0, 0.0), 90.0, 1, 2.0, R, (-3.0, 0.0))  # the wind wins


def test_with_the_least_speed_no_vehicle_is_planned_to_arrive_before_the_team():
    """Three vehicles side by side 60 m apart flying west 118 m north of the circle's centre
    (the ArduPlane personality's team at the tracking command): two placings are within 0.1 s
    for the slowest flight, and in the one taken on that alone a vehicle with 285 m to fly
    would reach its seat 6 s before the team even at the least speed. Counting that, the
    placing taken has every vehicle able to take the team's time."""
    radius, speed, least, turn = 90.0, 18.0, 10.0, 1.1 * 18.0 / 0.2
    centre = (0.6, 0.1)
    starts = [(-122.7 + 60.0 * j, 117.7, math.radians(181.0)) for j in range(3)]
    order = sorted(range(3), key=lambda v: math.atan2(starts[v][1], starts[v][0]))

    def longest(plan):
        return [
            dubins(s, seat_pose(centre, radius, a, 1), turn).length_m / least
            for s, a in zip(starts, plan.seat_angles_rad, strict=True)
        ]

    blind = join_plan(starts, centre, radius, 1, speed, turn, order=order)
    seeing = join_plan(starts, centre, radius, 1, speed, turn, order=order, min_speed_m_s=least)
    assert min(longest(blind)) < blind.time_s - 5.0
    assert min(longest(seeing)) >= seeing.time_s
    assert seeing.time_s < blind.time_s + 0.5  # for about the same slowest flight


def test_a_least_speed_above_the_top_speed_is_refused():
    with pytest.raises(ValueError, match="min_speed_m_s"):
        join_plan([(0.0, 0.0, 0.0)], (500.0, 0.0), 90.0, 1, 14.0, 77.0, min_speed_m_s=15.0)
