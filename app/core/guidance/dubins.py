"""Shortest paths for a vehicle with a least turn radius (Dubins), and joining a team to a circle
at a seat each (improvement over the paper's gather, issue #15): the planning the mission's
gather uses with ``[guidance] gather_join = "seat"`` and ``benchmarks/bench_gather_bound.py``.

Poses are (east m, north m, heading rad counter-clockwise from east); plain floats and ``math``.
"""

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

TAU = 2.0 * math.pi
EPS = 1e-9  # a square root's argument this far below 0 is rounding: a segment of length 0

Pose = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class DubinsPath:
    """A shortest path: its ``word`` (L: left arc, R: right arc, S: straight), the three
    segments' lengths in units of the turn radius, and its length in metres."""

    word: str
    segments: Pose
    length_m: float


def _mod(angle: float) -> float:
    return angle % TAU


def dubins(start: Pose, goal: Pose, radius_m: float) -> DubinsPath:
    """The shortest path from ``start`` to ``goal`` (east m, north m, heading rad counter-
    clockwise from east) with turns no tighter than ``radius_m``: the shortest of the six
    Dubins words (``dubins_words``)."""
    return min(dubins_words(start, goal, radius_m), key=lambda p: p.length_m)


def dubins_words(start: Pose, goal: Pose, radius_m: float) -> list[DubinsPath]:
    """Every Dubins word (LSL, RSR, LSR, RSL, RLR, LRL) that joins ``start`` to ``goal``."""
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        raise ValueError(f"radius_m must be finite and > 0, got {radius_m!r}")
    dx, dy = goal[0] - start[0], goal[1] - start[1]
    d = math.hypot(dx, dy) / radius_m
    theta = math.atan2(dy, dx) if d > 0.0 else 0.0
    a, b = _mod(start[2] - theta), _mod(goal[2] - theta)
    sa, sb, ca, cb = math.sin(a), math.sin(b), math.cos(a), math.cos(b)
    cab = math.cos(a - b)
    found: list[tuple[str, Pose]] = []
    p2 = 2.0 + d * d - 2.0 * cab + 2.0 * d * (sa - sb)
    if p2 >= -EPS:
        t = math.atan2(cb - ca, d + sa - sb)
        found.append(("LSL", (_mod(t - a), math.sqrt(max(p2, 0.0)), _mod(b - t))))
    p2 = 2.0 + d * d - 2.0 * cab + 2.0 * d * (sb - sa)
    if p2 >= -EPS:
        t = math.atan2(ca - cb, d - sa + sb)
        found.append(("RSR", (_mod(a - t), math.sqrt(max(p2, 0.0)), _mod(t - b))))
    p2 = -2.0 + d * d + 2.0 * cab + 2.0 * d * (sa + sb)
    if p2 >= -EPS:
        p = math.sqrt(max(p2, 0.0))
        t = math.atan2(-ca - cb, d + sa + sb) - math.atan2(-2.0, p)
        found.append(("LSR", (_mod(t - a), p, _mod(t - b))))
    p2 = d * d - 2.0 + 2.0 * cab - 2.0 * d * (sa + sb)
    if p2 >= -EPS:
        p = math.sqrt(max(p2, 0.0))
        t = math.atan2(ca + cb, d - sa - sb) - math.atan2(2.0, p)
        found.append(("RSL", (_mod(a - t), p, _mod(b - t))))
    q = (6.0 - d * d + 2.0 * cab + 2.0 * d * (sa - sb)) / 8.0
    if abs(q) <= 1.0 + EPS:
        p = _mod(TAU - math.acos(min(max(q, -1.0), 1.0)))
        t = _mod(a - math.atan2(ca - cb, d - sa + sb) + p / 2.0)
        found.append(("RLR", (t, p, _mod(a - b - t + p))))
    q = (6.0 - d * d + 2.0 * cab + 2.0 * d * (sb - sa)) / 8.0
    if abs(q) <= 1.0 + EPS:
        p = _mod(TAU - math.acos(min(max(q, -1.0), 1.0)))
        t = _mod(-a + math.atan2(-ca + cb, d + sa - sb) + p / 2.0)
        found.append(("LRL", (t, p, _mod(b - a - t + p))))
    return [DubinsPath(word, seg, sum(seg) * radius_m) for word, seg in found]


def follow(start: Pose, path: DubinsPath, radius_m: float) -> Pose:
    """Where flying ``path`` from ``start`` ends (east, north, heading), arc by arc."""
    x, y, h = start
    for letter, length in zip(path.word, path.segments, strict=True):
        if letter == "S":
            x += length * radius_m * math.cos(h)
            y += length * radius_m * math.sin(h)
            continue
        turn = length if letter == "L" else -length
        side = 1.0 if letter == "L" else -1.0
        cx, cy = x - side * radius_m * math.sin(h), y + side * radius_m * math.cos(h)
        h2 = h + turn
        x, y = cx + side * radius_m * math.sin(h2), cy - side * radius_m * math.cos(h2)
        h = h2
    return x, y, _mod(h + math.pi) - math.pi


def ground_speed(airspeed_m_s: float, heading_rad: float, wind: tuple[float, float]) -> float:
    """The speed over the ground along ``heading_rad`` (counter-clockwise from east) of a
    vehicle that keeps its track on it at ``airspeed_m_s`` in ``wind`` (east, north m/s),
    crabbing into the cross wind; 0 where it cannot make way along it."""
    along = wind[0] * math.cos(heading_rad) + wind[1] * math.sin(heading_rad)
    across = -wind[0] * math.sin(heading_rad) + wind[1] * math.cos(heading_rad)
    if abs(across) >= airspeed_m_s:
        return 0.0
    return max(0.0, along + math.sqrt(airspeed_m_s * airspeed_m_s - across * across))


def flight_time(
    start: Pose,
    path: DubinsPath,
    radius_m: float,
    airspeed_m_s: float,
    wind: tuple[float, float] = (0.0, 0.0),
) -> float:
    """Seconds to fly ``path`` from ``start`` at ``airspeed_m_s`` in a steady ``wind``: each
    straight at its ground speed, each turn in 10-degree pieces (inf where the wind stops it)."""
    if wind == (0.0, 0.0):
        return path.length_m / airspeed_m_s
    h = start[2]
    total = 0.0
    for letter, length in zip(path.word, path.segments, strict=True):
        if length <= 0.0:
            continue
        if letter == "S":
            speed = ground_speed(airspeed_m_s, h, wind)
            if speed <= 0.0:
                return math.inf
            total += length * radius_m / speed
            continue
        turn = 1.0 if letter == "L" else -1.0
        pieces = max(1, math.ceil(length / math.radians(10.0)))
        piece = length / pieces
        for i in range(pieces):
            speed = ground_speed(airspeed_m_s, h + turn * piece * (i + 0.5), wind)
            if speed <= 0.0:
                return math.inf
            total += piece * radius_m / speed
        h += turn * length
    return total


def sample_path(
    start: Pose, path: DubinsPath, radius_m: float, step_m: float
) -> tuple[tuple[float, float, float, float], ...]:
    """Points along ``path`` from ``start`` about every ``step_m`` (and its end): (east, north,
    heading, curvature 1/m counter-clockwise positive)."""
    if not (math.isfinite(step_m) and step_m > 0.0):
        raise ValueError(f"step_m must be finite and > 0, got {step_m!r}")
    x, y, h = start
    out = [(x, y, h, 0.0)]
    for letter, length in zip(path.word, path.segments, strict=True):
        metres = length * radius_m
        if metres <= 0.0:
            continue
        kappa = 0.0 if letter == "S" else (1.0 if letter == "L" else -1.0) / radius_m
        count = max(1, math.ceil(metres / step_m))
        cx = cy = 0.0
        if kappa != 0.0:
            side = 1.0 if kappa > 0.0 else -1.0
            cx, cy = x - side * radius_m * math.sin(h), y + side * radius_m * math.cos(h)
        for i in range(1, count + 1):
            s = metres * i / count
            if kappa == 0.0:
                px, py, ph = x + s * math.cos(h), y + s * math.sin(h), h
            else:
                ph = h + kappa * s
                px = cx + side * radius_m * math.sin(ph)
                py = cy - side * radius_m * math.cos(ph)
            out.append((px, py, ph, kappa))
        x, y, h = out[-1][0], out[-1][1], out[-1][2]
    return tuple(out)


def seat_pose(centre: tuple[float, float], radius_m: float, angle_rad: float, sign: int) -> Pose:
    """The pose on the circle at polar ``angle_rad``, flying it (sign +1 counter-clockwise)."""
    return (
        centre[0] + radius_m * math.cos(angle_rad),
        centre[1] + radius_m * math.sin(angle_rad),
        angle_rad + sign * math.pi / 2.0,
    )


@dataclass(frozen=True, slots=True)
class JoinPlan:
    """Where each vehicle joins the circle (polar angles about its centre, rad, in the order
    the starts were given) and how long the slowest needs to get there (s)."""

    seat_angles_rad: tuple[float, ...]
    time_s: float


#: the largest team whose seat assignment is searched over every permutation
MAX_JOIN_TEAM = 5


def join_plan(
    starts: Sequence[Pose],
    centre: tuple[float, float],
    radius_m: float,
    sign: int,
    speed_m_s: float,
    turn_radius_m: float,
    wind: tuple[float, float] = (0.0, 0.0),
    band_s: float = 0.5,
    order: Sequence[int] | None = None,
    min_speed_m_s: float | None = None,
) -> JoinPlan:
    """Seats 2 pi / n apart on the circle (``radius_m`` about ``centre``, flown
    counter-clockwise for ``sign`` +1), placed in one-degree steps and assigned to the vehicles
    at ``starts`` so that the slowest flight (``flight_time`` of the shortest path, ``dubins``
    at ``turn_radius_m``, at ``speed_m_s`` through the air in ``wind``) to a seat, joining the
    circle in its direction, is as quick as it can be, give or take ``band_s``: of the placings
    within ``band_s`` of the quickest (and with its assignment) the middle one is taken, which
    small differences between the agents' views of the team do not move. With ``order`` (the
    vehicles' indices in the order their seats go round, from the first placed) the assignment
    is that one; without it every assignment is tried, at most ``MAX_JOIN_TEAM`` vehicles (the
    slowest flight alone decides, so the others' seats are ties, broken by
    ``itertools.permutations`` order: agents whose views differ may break them differently,
    which is why the mission gives the order). Ties of placings go to the smaller angle.

    With ``min_speed_m_s`` (the slowest a vehicle can fly), a placing is as quick as its
    slowest flight plus the most any vehicle must arrive before it: one whose shortest path
    flown at the least speed is still quicker than the slowest flight reaches its seat that
    much early (a fixed wing cannot wait), and the team is spaced only once the phase keeping
    has taken the lead back. (On the ArduPlane personality's start, side by side, two placings
    were both 34.9 s for the slowest; in one a vehicle had 285 m to fly and joined the circle
    20 s before the team, and the team was spaced 30 s later than in the other.)"""
    n = len(starts)
    if not 1 <= n <= MAX_JOIN_TEAM:
        raise ValueError(f"1 to {MAX_JOIN_TEAM} vehicles, got {n}")
    if not (math.isfinite(speed_m_s) and speed_m_s > 0.0):
        raise ValueError(f"speed_m_s must be finite and > 0, got {speed_m_s!r}")
    if min_speed_m_s is not None and not (0.0 < min_speed_m_s <= speed_m_s):
        raise ValueError(f"min_speed_m_s must be in (0, speed_m_s], got {min_speed_m_s!r}")
    seats = [seat_pose(centre, radius_m, math.radians(k), sign) for k in range(360)]
    paths = [[dubins(start, seat, turn_radius_m) for seat in seats] for start in starts]
    lengths = [
        [flight_time(start, path, turn_radius_m, speed_m_s, wind) for path in row]
        for start, row in zip(starts, paths, strict=True)
    ]
    longest = (
        None
        if min_speed_m_s is None
        else [
            [flight_time(start, path, turn_radius_m, min_speed_m_s, wind) for path in row]
            for start, row in zip(starts, paths, strict=True)
        ]
    )
    # per placing k (degrees), the quickest assignment, its cost and its slowest flight
    per_k: list[tuple[float, tuple[int, ...], float]] = []
    for k in range(360):
        angles = [round(k + 360.0 * j / n) % 360 for j in range(n)]
        best_k = (math.inf, tuple(range(n)), math.inf)
        for each in itertools.permutations(range(n)) if order is None else (tuple(order),):
            slowest = max(lengths[v][angles[j]] for j, v in enumerate(each))
            cost = slowest
            if longest is not None:
                cost += max(0.0, slowest - min(longest[v][angles[j]] for j, v in enumerate(each)))
            if cost < best_k[0] - 1e-9:
                best_k = (cost, each, slowest)
        per_k.append(best_k)
    k_best = min(range(360), key=lambda k: per_k[k][0])
    quickest = per_k[k_best][0]
    if not math.isfinite(quickest):
        raise ValueError("no seat can be reached against this wind")
    # the middle of the run of placings, about the quickest, within ``band_s`` of it with the
    # same assignment: agents that plan from statuses a tick apart find the same seats (the
    # quickest placing alone moved by 5 degrees between them over MAVLink)
    chosen = per_k[k_best][1]

    def near(k: int) -> bool:
        return per_k[k % 360][1] == chosen and per_k[k % 360][0] <= quickest + band_s

    low = high = k_best
    while near(low - 1) and k_best - low < 179:
        low -= 1
    while near(high + 1) and high - k_best < 179:
        high += 1
    k = ((low + high) // 2) % 360
    seat_of = [0.0] * n
    for j, v in enumerate(chosen):
        seat_of[v] = math.radians(round(k + 360.0 * j / n) % 360)
    return JoinPlan(tuple(seat_of), per_k[k][2])
