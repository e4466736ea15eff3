"""How soon a team could form up from its standby loiter: joining the circle at one point, as the
mission's gather does, against each vehicle joining at its own seat (issue #15: formation at
most 80 s after the tracking command).

Run:  .venv/bin/python -m benchmarks.bench_gather_bound [CONFIG] [--step 30]

Ideal airframes at the top speed v with the tightest turn it allows (radius R = v / W, W the
course-rate limit), on the shortest paths between two poses (Dubins: two arcs of radius R and a
straight line, or three arcs). The team starts together at one point of the standby loiter,
flying along it (the simulator launches it bunched there), at every ``--step`` degrees round it.

- **One joining point.** The first vehicle takes the shortest path onto the circle r_d about the
  target's start, flying its direction there (the seat angle that is quickest to reach); the
  others join at the same point, each (2 pi r_d / n) / v after the one before, so that they
  arrive spaced. The team is formed when the last one joins.
- **A seat each.** The n seats, 2 pi / n apart, are placed (in steps of one degree) so that the
  slowest vehicle's shortest path to its seat is as short as it can be; the others lose time on
  the way (slower, or a longer path) and every vehicle reaches its seat at that moment.

Both are bounds for vehicles that fly the top speed all the way with no lag in their turns
(the mission's vehicles accelerate from cruise and answer their course commands with a lag);
their difference is what a gather that plans a joining point per vehicle could save over one
that joins the whole team at one point. Prints both per start point, and their means.
"""

import argparse
import csv
import itertools
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from app.config import load_config
from app.config.mission import MissionConfig

TAU = 2.0 * math.pi
EPS = 1e-9  # a word whose square root's argument is this far below 0 is one of length 0


@dataclass(frozen=True, slots=True)
class DubinsPath:
    """A shortest path: its ``word`` (L: left arc, R: right arc, S: straight), the three
    segments' lengths in units of the turn radius, and its length in metres."""

    word: str
    segments: tuple[float, float, float]
    length_m: float


def _mod(angle: float) -> float:
    return angle % TAU


def dubins(
    start: tuple[float, float, float], goal: tuple[float, float, float], radius_m: float
) -> DubinsPath:
    """The shortest path from ``start`` to ``goal`` (east m, north m, heading rad counter-
    clockwise from east) with turns no tighter than ``radius_m``: the shortest of the six
    Dubins words (``dubins_words``)."""
    return min(dubins_words(start, goal, radius_m), key=lambda p: p.length_m)


def dubins_words(
    start: tuple[float, float, float], goal: tuple[float, float, float], radius_m: float
) -> list[DubinsPath]:
    """Every Dubins word (LSL, RSR, LSR, RSL, RLR, LRL) that joins ``start`` to ``goal``."""
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        raise ValueError(f"radius_m must be finite and > 0, got {radius_m!r}")
    dx, dy = goal[0] - start[0], goal[1] - start[1]
    d = math.hypot(dx, dy) / radius_m
    theta = math.atan2(dy, dx) if d > 0.0 else 0.0
    a, b = _mod(start[2] - theta), _mod(goal[2] - theta)
    sa, sb, ca, cb = math.sin(a), math.sin(b), math.cos(a), math.cos(b)
    cab = math.cos(a - b)
    found: list[tuple[str, tuple[float, float, float]]] = []
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


def follow(
    start: tuple[float, float, float], path: DubinsPath, radius_m: float
) -> tuple[float, float, float]:
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


def seat_pose(
    centre: tuple[float, float], radius_m: float, angle_rad: float, sign: int
) -> tuple[float, float, float]:
    """The pose on the circle at polar ``angle_rad``, flying it (sign +1 counter-clockwise)."""
    return (
        centre[0] + radius_m * math.cos(angle_rad),
        centre[1] + radius_m * math.sin(angle_rad),
        angle_rad + sign * math.pi / 2.0,
    )


def gather_times(
    starts: Sequence[tuple[float, float, float]],
    centre: tuple[float, float],
    radius_m: float,
    sign: int,
    speed_m_s: float,
    turn_radius_m: float,
) -> tuple[float, float]:
    """(one joining point, a seat each): the seconds until a team starting at ``starts`` (one
    pose per vehicle) is on the circle and spaced, flying ``speed_m_s`` (see the module). With
    one joining point the vehicles join in the order they can get there, each at least
    (2 pi r_d / n) / v after the one before; with a seat each, every assignment of vehicles to
    seats is tried (teams of up to 7)."""
    n = len(starts)
    if not 1 <= n <= 7:
        raise ValueError(f"1 to 7 vehicles, got {n}")
    seats = [seat_pose(centre, radius_m, math.radians(k), sign) for k in range(360)]
    times = [
        [dubins(start, seat, turn_radius_m).length_m / speed_m_s for seat in seats]
        for start in starts
    ]
    gap_s = TAU * radius_m / n / speed_m_s
    one_point = math.inf
    for k in range(360):
        arrivals = sorted(t[k] for t in times)
        first = max(a - j * gap_s for j, a in enumerate(arrivals))
        one_point = min(one_point, first + (n - 1) * gap_s)
    each = math.inf
    for k in range(360):
        angles = [round(k + 360.0 * j / n) % 360 for j in range(n)]
        for order in itertools.permutations(range(n)):
            slowest = max(times[v][angles[j]] for j, v in enumerate(order))
            each = min(each, slowest)
    return one_point, each


def run_starts(
    run_dir: Path,
) -> tuple[list[tuple[float, float, float]], float, float | None]:
    """A run folder's team at the tracking command (each vehicle's first track.csv row from
    then on: east, north, heading counter-clockwise from east), the command's time and the
    formation time it measured (s after the command; None: never)."""
    mission = json.loads((run_dir / "config.json").read_text())["mission"]
    command = float(mission["tracking_command_s"])
    starts: dict[int, tuple[float, float, float]] = {}
    with (run_dir / "track.csv").open() as f:
        for row in csv.DictReader(f):
            vehicle = int(row["vehicle"])
            if float(row["t_s"]) < command or vehicle in starts:
                continue
            course = float(row["course_rad"])
            starts[vehicle] = (float(row["east_m"]), float(row["north_m"]), math.pi / 2 - course)
    summary = json.loads((run_dir / "summary.json").read_text())
    formed = summary["convergence"].get("time_to_formation_s")
    return [starts[v] for v in sorted(starts)], command, formed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="hil")
    parser.add_argument("--step", type=float, default=30.0, help="deg between start points (30)")
    parser.add_argument(
        "--run",
        type=Path,
        nargs="+",
        default=[],
        help="also run folders of the config flown (standoff fly --out DIR): the bounds from "
        "where the team was at the tracking command, beside the formation time measured",
    )
    args = parser.parse_args()
    cfg = load_config(args.config, MissionConfig)
    lim = cfg.limits
    speed = lim.max_speed_m_s
    turn = speed / lim.max_course_rate_rad_s
    sign = 1 if cfg.orbit == "ccw" else -1
    target = cfg.target
    centre = (getattr(target, "start_east_m", 0.0), getattr(target, "start_north_m", 0.0))
    sb = cfg.standby
    print(
        f"{cfg.name}: {cfg.vehicles} vehicles from the standby loiter (r {sb.radius_m:g} m about "
        f"({sb.east_m:g}, {sb.north_m:g})) onto r_d {cfg.radius_m:g} m about {centre}, at "
        f"{speed:g} m/s turning on {turn:.0f} m"
    )
    print(f"{'team together at':>20s} {'one point s':>12s} {'a seat each s':>14s} {'saved s':>8s}")
    rows = []
    k = 0.0
    while k < 360.0 - 1e-9:
        a = math.radians(k)
        start = (
            sb.east_m + sb.radius_m * math.cos(a),
            sb.north_m + sb.radius_m * math.sin(a),
            a + sign * math.pi / 2.0,
        )
        one, each = gather_times([start] * cfg.vehicles, centre, cfg.radius_m, sign, speed, turn)
        rows.append((one, each))
        print(f"{k:13.0f} deg on it {one:12.1f} {each:14.1f} {one - each:8.1f}")
        k += args.step
    one_mean = sum(r[0] for r in rows) / len(rows)
    each_mean = sum(r[1] for r in rows) / len(rows)
    print(
        f"mean: one joining point {one_mean:.1f} s, a seat each {each_mean:.1f} s "
        f"({each_mean / one_mean:.2f}x); worst {max(r[0] for r in rows):.1f} s against "
        f"{max(r[1] for r in rows):.1f} s"
    )
    for run_dir in args.run:
        starts, command, formed = run_starts(run_dir)
        one, each = gather_times(starts, centre, cfg.radius_m, sign, speed, turn)
        measured = "never" if formed is None else f"{formed:.1f} s"
        print(
            f"run {run_dir} (command at {command:g} s): formed {measured}; from where the team "
            f"was, one joining point {one:.1f} s, a seat each {each:.1f} s"
        )


if __name__ == "__main__":
    main()
