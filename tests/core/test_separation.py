"""The separation guard (app.core.mission.separation): flown by point-mass vehicles that turn
at a course-rate limit, pairs that would collide keep the minimum distance; stacked vehicles
keep their freedom; a vehicle never climbs into a teammate it is near."""

import math
from dataclasses import replace

import numpy as np
import pytest

from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.core.agent import OwnTelemetry
from app.core.frames import wrap_pi
from app.core.mission import agent as logic
from app.core.mission.agent import TeammateFix
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


@pytest.mark.parametrize("credit", [-0.1, 1.5, math.nan])
def test_a_climb_credit_outside_zero_to_one_is_refused(credit: float) -> None:
    with pytest.raises(ValueError, match="climb_credit"):
        SeparationParams(climb_credit=credit)


CLIMB = 5.0  # m/s


def _crossing(
    own_up: float, other_up: float, other_level: float | None, own_climb: float = 0.0
) -> Resolution:
    """The agent at (0, 0) flying north, sent to 135 m (held by the band: no climb), and a
    teammate 40 m east and 168 m north flying south, climbing to ``other_level``: 40 m apart
    horizontally at the closest, 6 s ahead (less than the 45 m guard)."""
    other = Traffic(2, 40.0, 168.0, other_up, math.pi, SPEED, CLIMB, other_level)
    return resolve(
        0.0, 0.0, own_up, 0.0, SPEED, 0.0, [other], RATE, PARAMS,
        climb_m_s=own_climb, level_up_m=135.0,
    )  # fmt: skip


def test_a_climb_that_parts_the_pair_in_time_needs_no_turn() -> None:
    """The teammate 1 m above climbs on to 170 m: counting 0.8 of its climb the pair is 25 m
    apart in height at the closest, 47 m in 3-D, so the agent holds its height (the band) and
    flies its course. From the teammate's side alike: no turn, no descent."""
    r = _crossing(75.0, 76.0, 170.0)
    assert r.threat is None
    assert r.course_rad == 0.0
    assert r.max_up_m == pytest.approx(75.0)
    other = Traffic(1, 0.0, 0.0, 75.0, 0.0, SPEED, 0.0, 135.0)
    seen_from_it = resolve(
        40.0, 168.0, 76.0, math.pi, SPEED, math.pi, [other], RATE, PARAMS,
        climb_m_s=CLIMB, level_up_m=170.0,
    )  # fmt: skip
    assert seen_from_it.threat is None
    assert seen_from_it.course_rad == math.pi
    assert seen_from_it.min_up_m == pytest.approx(76.0)


@pytest.mark.parametrize(
    ("own_up", "own_climb", "other_up", "other_level", "why"),
    [
        (75.0, 0.0, 76.0, None, "its level unknown"),
        (75.0, 0.0, 76.0, 84.0, "it stops 8 m higher"),
        (75.0, 0.0, 75.2, 170.0, "within the tie: the climb not counted on"),
        (76.0, 0.0, 75.0, 170.0, "the agent above, sent lower than the teammate"),
        (75.0, CLIMB, 76.0, 170.0, "the agent still climbing after it at its rate"),
    ],
)
def test_without_a_climb_that_parts_the_pair_it_turns_as_before(
    own_up: float, own_climb: float, other_up: float, other_level: float | None, why: str
) -> None:
    r = _crossing(own_up, other_up, other_level, own_climb)
    assert r.threat == 2, why
    assert r.course_rad != 0.0, why


def test_within_the_tie_the_one_sent_lower_holds_its_height() -> None:
    """0.2 m below a teammate but sent higher (170 against 135 m): the agent is the upper one
    (no descent), and the teammate, seeing it 0.2 m below, holds its climb: both agents agree
    although a status apart they may not agree which is higher."""
    other = Traffic(2, 40.0, 168.0, 75.2, math.pi, SPEED, CLIMB, 135.0)
    r = resolve(
        0.0, 0.0, 75.0, 0.0, SPEED, 0.0, [other], RATE, PARAMS, climb_m_s=CLIMB, level_up_m=170.0
    )
    assert r.min_up_m == pytest.approx(75.0)
    assert r.max_up_m is None
    me = Traffic(1, 0.0, 0.0, 75.0, 0.0, SPEED, CLIMB, 170.0)
    seen_from_it = resolve(
        40.0, 168.0, 75.2, math.pi, SPEED, math.pi, [me], RATE, PARAMS,
        climb_m_s=CLIMB, level_up_m=135.0,
    )  # fmt: skip
    assert seen_from_it.max_up_m == pytest.approx(75.2)
    assert seen_from_it.min_up_m is None


def _climb_out(
    starts: list[tuple[float, float, float]],
    levels: list[float],
    goals: list[tuple[float, float]],
    levels_known: bool,
    seconds: float = 60.0,
    dt: float = 0.1,
) -> tuple[float, int]:
    """Vehicles at (east, north, up) each steering for its goal point at SPEED and climbing at
    up to CLIMB to its level within the guard's band, each its own agent hearing the others'
    positions, climb rates and (with ``levels_known``) levels of the tick; the least 3-D pair
    distance over the flight, and the ticks on which some vehicle was turned away."""
    n = len(starts)
    pos = np.array([s[:2] for s in starts], dtype=float)
    up = np.array([s[2] for s in starts], dtype=float)
    climb = np.zeros(n)
    course = [math.atan2(g[0] - p[0], g[1] - p[1]) for p, g in zip(pos, goals, strict=True)]
    least, turned = math.inf, 0
    for _ in range(int(seconds / dt)):
        commands, bands = [], []
        for i in range(n):
            wanted = math.atan2(goals[i][0] - pos[i, 0], goals[i][1] - pos[i, 1])
            traffic = [
                Traffic(
                    j,
                    pos[j, 0],
                    pos[j, 1],
                    up[j],
                    course[j],
                    SPEED,
                    climb[j],
                    levels[j] if levels_known else None,
                )
                for j in range(n)
                if j != i
            ]
            r = resolve(
                pos[i, 0], pos[i, 1], up[i], course[i], SPEED, wanted, traffic, RATE, PARAMS,
                climb_m_s=climb[i], level_up_m=levels[i] if levels_known else None,
            )  # fmt: skip
            turned += r.threat is not None
            commands.append(r.course_rad)
            bands.append((r.min_up_m, r.max_up_m))
        for i in range(n):
            error = wrap_pi(commands[i] - course[i])
            course[i] = wrap_pi(course[i] + max(-RATE * dt, min(RATE * dt, error)))
            pos[i] += SPEED * dt * np.array([math.sin(course[i]), math.cos(course[i])])
            low, high = bands[i]
            goal = levels[i]
            goal = goal if high is None else min(goal, high)
            goal = goal if low is None else max(goal, low)
            climb[i] = max(-CLIMB, min(CLIMB, (goal - up[i]) / dt))
            up[i] += climb[i] * dt
        for i in range(n):
            for j in range(i + 1, n):
                least = min(least, math.dist((*pos[i], up[i]), (*pos[j], up[j])))
    return least, turned


@pytest.mark.parametrize("seed", range(4))
def test_a_team_climbing_to_its_stack_keeps_apart_and_turns_less_when_levels_are_known(
    seed: int,
) -> None:
    """Three vehicles taking off side by side at one height and climbing to a 35 m stack on
    paths that converge while they climb: the minimum distance kept either way, and with the
    levels known (the climb that parts them counted on) fewer ticks turned away."""
    rng = np.random.default_rng(seed)
    starts = [(50.0 * i + rng.uniform(-5, 5), rng.uniform(-10, 10), 30.0) for i in range(3)]
    goals = [(50.0 + rng.uniform(-5, 5), 600.0 + rng.uniform(-5, 5)) for _ in range(3)]
    levels = [100.0, 135.0, 170.0]
    blind, blind_turns = _climb_out(starts, levels, goals, levels_known=False)
    known, known_turns = _climb_out(starts, levels, goals, levels_known=True)
    assert blind >= PARAMS.min_distance_m
    assert known >= PARAMS.min_distance_m
    assert known_turns < blind_turns


def test_a_teammates_height_is_dead_reckoned_at_its_climb_and_not_past_its_level() -> None:
    fix = TeammateFix(10.0, 0.0, 0.0, 0.0, SPEED, up_m=80.0, climb_m_s=CLIMB, level_up_m=90.0)
    assert fix.up_at(10.5, 3.0) == pytest.approx(82.5)
    assert fix.up_at(14.0, 3.0) == pytest.approx(90.0)  # levelled off
    assert fix.up_at(9.0, 3.0) == pytest.approx(80.0)  # never back in time
    assert replace(fix, climb_m_s=None).up_at(12.0, 3.0) == pytest.approx(80.0)
    sinking = replace(fix, climb_m_s=-CLIMB, level_up_m=70.0)
    assert sinking.up_at(20.0, 3.0) == pytest.approx(70.0)


@pytest.mark.parametrize("levels_known", [True, False])
def test_the_mission_agent_steers_on_the_climb_its_teammates_statuses_say(
    levels_known: bool,
) -> None:
    """The hil mission's second agent in standby, held at 75 m by the band (no climb), its
    teammate 1 m above climbing to the top of the stack on a course converging with the one
    the agent wants (40 m off it at the closest, 6 s ahead): with the levels (from the status
    and from its own link) it flies on and holds its height; without, it turns away."""
    config = load_config("hil", MissionConfig)
    plist = build_plan(config).agents
    p = replace(plist[1], course_id=None)
    assert p.separation is not None
    state = logic.hear_mission(logic.initial_agent_state(p), "standby", (0, 1, 2))
    own = OwnTelemetry(
        0.0, 0.0, 0.0, SPEED, SPEED, (0.0, 0.0), 75.0, 0.0, 135.0 if levels_known else None
    )
    _, alone, _ = logic.control(state, 0.0, own, p)
    wanted = alone.course_rad
    across, ahead = 40.0, 168.0  # the teammate's place: across and along the wanted course
    east = ahead * math.sin(wanted) + across * math.cos(wanted)
    north = ahead * math.cos(wanted) - across * math.sin(wanted)
    level = 170.0 if levels_known else None
    fix = TeammateFix(0.0, east, north, wrap_pi(wanted + math.pi), SPEED, 76.0, CLIMB, level)
    state = logic.hear_teammate(state, plist[2].vehicle, fix)
    _, _, events = logic.control(state, 0.0, own, p)
    said = " / ".join(e.detail for e in events if e.kind == "separation")
    assert "height held at most 75 m" in said
    assert ("turning" in said) != levels_known, said
