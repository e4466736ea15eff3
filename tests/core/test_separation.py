"""The separation guard (app.core.mission.separation): flown by point-mass vehicles that turn
at a course-rate limit, pairs that would collide keep the minimum distance; stacked vehicles
keep their freedom; a vehicle never climbs into a teammate it is near."""

import math
from dataclasses import replace

import numpy as np
import pytest

from app.core.frames import wrap_pi
from app.core.mission.separation import Resolution, SeparationParams, Traffic, resolve

RATE = 0.2  # rad/s
SPEED = 14.0
PARAMS = SeparationParams()


def _fly(
    starts: list[tuple[float, float, float]],
    goals: list[tuple[float, float]],
    guard: bool,
    seconds: float = 90.0,
    dt: float = 0.1,
) -> float:
    """Vehicles at (east, north, up) each steering for its goal point at SPEED, with or without
    the guard (each its own agent, hearing the others' positions of the tick); the least 3-D
    pair distance over the flight."""
    n = len(starts)
    pos = np.array([s[:2] for s in starts], dtype=float)
    up = [s[2] for s in starts]
    course = [math.atan2(g[0] - p[0], g[1] - p[1]) for p, g in zip(pos, goals, strict=True)]
    least = math.inf
    for _ in range(int(seconds / dt)):
        commands = []
        for i in range(n):
            wanted = math.atan2(goals[i][0] - pos[i, 0], goals[i][1] - pos[i, 1])
            if guard:
                traffic = [
                    Traffic(j, pos[j, 0], pos[j, 1], up[j], course[j], SPEED)
                    for j in range(n)
                    if j != i
                ]
                r = resolve(
                    pos[i, 0], pos[i, 1], up[i], course[i], SPEED, wanted, traffic, RATE, PARAMS
                )
                wanted = r.course_rad
            commands.append(wanted)
        for i in range(n):
            error = wrap_pi(commands[i] - course[i])
            course[i] = wrap_pi(course[i] + max(-RATE * dt, min(RATE * dt, error)))
            pos[i] += SPEED * dt * np.array([math.sin(course[i]), math.cos(course[i])])
        for i in range(n):
            for j in range(i + 1, n):
                d = math.dist((*pos[i], up[i]), (*pos[j], up[j]))
                least = min(least, d)
    return least


def test_a_head_on_pair_passes_at_the_minimum_distance_and_collides_without_the_guard() -> None:
    starts = [(0.0, 0.0, 100.0), (5.0, 800.0, 100.0)]
    goals = [(5.0, 1600.0), (0.0, -800.0)]
    assert _fly(starts, goals, guard=False) < 10.0
    assert _fly(starts, goals, guard=True) >= PARAMS.min_distance_m


@pytest.mark.parametrize("seed", range(4))
def test_three_vehicles_converging_on_one_point_stay_apart(seed: int) -> None:
    """Three vehicles 60 m apart heading for one rally point, at one altitude (the climb-out of
    a team that took off side by side), then on through it."""
    rng = np.random.default_rng(seed)
    starts = [(60.0 * i + rng.uniform(-10, 10), rng.uniform(-20, 20), 100.0) for i in range(3)]
    goals = [(60.0 + rng.uniform(-5, 5), 500.0 + rng.uniform(-5, 5)) for _ in range(3)]
    assert _fly(starts, goals, guard=False, seconds=60.0) < PARAMS.min_distance_m
    assert _fly(starts, goals, guard=True, seconds=60.0) >= PARAMS.min_distance_m


def test_a_stacked_teammate_overhead_is_left_alone_until_the_climb_comes_too_close() -> None:
    """35 m below a teammate on a crossing course (the altitude stack): separated, nothing
    changes. 31 m below, climbing toward it: no turn (vertically separated), but the climb is
    capped at min_distance + vertical margin below it."""
    stacked = Traffic(2, 0.0, 50.0, 135.0, math.pi / 2, SPEED)
    assert resolve(0.0, 0.0, 100.0, 0.0, SPEED, 0.0, [stacked], RATE, PARAMS) == Resolution(0.0)
    r = resolve(0.0, 0.0, 104.0, 0.0, SPEED, 0.0, [stacked], RATE, PARAMS)
    assert r.course_rad == 0.0
    assert r.threat is None
    assert r.max_up_m == pytest.approx(104.0)  # already closer than 32 m: held where it is
    assert r.min_up_m is None
    far_below = resolve(
        0.0, 0.0, 70.0, 0.0, SPEED, 0.0, [replace(stacked, up_m=110.0)], RATE, PARAMS
    )
    assert far_below == Resolution(0.0)


def test_a_vehicle_climbing_below_a_near_teammate_holds_its_height_and_turns() -> None:
    """10 m below a teammate ahead on the same course: neither height change toward it (held at
    its own) nor the wanted course (it turns away)."""
    other = Traffic(3, 0.0, 40.0, 136.0, 0.0, 12.0)
    r = resolve(0.0, 0.0, 126.0, 0.0, SPEED, 0.0, [other], RATE, PARAMS)
    assert r.max_up_m == pytest.approx(126.0)
    assert r.threat == 3
    assert r.course_rad != 0.0
    assert r.closest_m < PARAMS.guard_m


def test_the_vehicle_above_does_not_descend_onto_the_one_below() -> None:
    other = Traffic(1, 0.0, 40.0, 126.0, 0.0, 12.0)
    r = resolve(0.0, 0.0, 136.0, 0.0, SPEED, 0.0, [other], RATE, PARAMS)
    assert r.min_up_m == pytest.approx(136.0)
    assert r.max_up_m is None


def test_nothing_near_and_no_own_altitude_leave_the_wanted_course() -> None:
    far = Traffic(2, 2000.0, 0.0, 100.0, 0.0, SPEED)
    assert resolve(0.0, 0.0, 100.0, 0.0, SPEED, 0.3, [far], RATE, PARAMS) == Resolution(0.3)
    near = Traffic(2, 0.0, 30.0, 100.0, math.pi, SPEED)
    unknown = resolve(0.0, 0.0, None, 0.0, SPEED, 0.3, [near], RATE, PARAMS)
    assert unknown == Resolution(0.3)
    assert not unknown.acted


def test_a_teammate_of_unknown_height_is_taken_at_the_own() -> None:
    other = Traffic(2, 0.0, 200.0, None, math.pi, SPEED)
    r = resolve(0.0, 0.0, 100.0, 0.0, SPEED, 0.0, [other], RATE, PARAMS)
    assert r.threat == 2
    assert r.course_rad > 0.0  # head-on: to the right


@pytest.mark.parametrize(
    "field", ["min_distance_m", "look_ahead_s", "step_s", "course_step_rad", "max_age_s"]
)
def test_nonpositive_settings_are_refused(field: str) -> None:
    with pytest.raises(ValueError, match=field):
        SeparationParams(**{field: 0.0})
