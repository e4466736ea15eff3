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
import json
import math
from collections.abc import Sequence
from pathlib import Path

from app.config import load_config
from app.config.mission import MissionConfig
from app.core.guidance.dubins import MAX_JOIN_TEAM, TAU, Pose, dubins, join_plan, seat_pose


def gather_times(
    starts: Sequence[Pose],
    centre: tuple[float, float],
    radius_m: float,
    sign: int,
    speed_m_s: float,
    turn_radius_m: float,
) -> tuple[float, float]:
    """(one joining point, a seat each): the seconds until a team starting at ``starts`` (one
    pose per vehicle) is on the circle and spaced, flying ``speed_m_s`` (see the module). With
    one joining point the vehicles join in the order they can get there, each at least
    (2 pi r_d / n) / v after the one before; with a seat each, ``dubins.join_plan`` (teams of
    up to ``MAX_JOIN_TEAM``)."""
    n = len(starts)
    if not 1 <= n <= MAX_JOIN_TEAM:
        raise ValueError(f"1 to {MAX_JOIN_TEAM} vehicles, got {n}")
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
    each = join_plan(starts, centre, radius_m, sign, speed_m_s, turn_radius_m, band_s=0.0).time_s
    return one_point, each


def run_starts(run_dir: Path) -> tuple[list[Pose], float, float | None]:
    """A run folder's team at the tracking command (each vehicle's first track.csv row from
    then on: east, north, heading counter-clockwise from east), the command's time and the
    formation time it measured (s after the command; None: never)."""
    mission = json.loads((run_dir / "config.json").read_text())["mission"]
    command = float(mission["tracking_command_s"])
    starts: dict[int, Pose] = {}
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


def run_bounds(run_dir: Path, cfg: MissionConfig) -> tuple[float, float, float | None]:
    """(one joining point, a seat each, measured): the bounds from where a run folder's team
    was at the tracking command (``run_starts``), at ``cfg``'s top speed and tightest turn onto
    its circle about the target's start, beside the formation time the run measured (s after
    the command; None: never)."""
    starts, _, formed = run_starts(run_dir)
    lim = cfg.limits
    speed = lim.max_speed_m_s
    target = cfg.target
    centre = (getattr(target, "start_east_m", 0.0), getattr(target, "start_north_m", 0.0))
    sign = 1 if cfg.orbit == "ccw" else -1
    one, each = gather_times(
        starts, centre, cfg.radius_m, sign, speed, speed / lim.max_course_rate_rad_s
    )
    return one, each, formed


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
        command = float(
            json.loads((run_dir / "config.json").read_text())["mission"]["tracking_command_s"]
        )
        one, each, formed = run_bounds(run_dir, cfg)
        measured = "never" if formed is None else f"{formed:.1f} s"
        print(
            f"run {run_dir} (command at {command:g} s): formed {measured}; from where the team "
            f"was, one joining point {one:.1f} s, a seat each {each:.1f} s"
        )


if __name__ == "__main__":
    main()
