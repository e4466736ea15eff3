"""``standoff optimal-c``: the guidance-parameter search of section 4.1."""

import argparse
import math
import time

from app.errors import ConfigError

ORDER = 50


def register(subparsers: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    parser = subparsers.add_parser(
        "optimal-c",
        help="the smallest guidance parameter c that a vehicle can fly (section 4.1)",
        description=(
            "The smallest c whose peak |curvature| of the field lines over r >= r_d (eq. 11) "
            "stays within (max course rate)/speed (eq. 12), found as an exact root."
        ),
    )
    parser.add_argument("--radius-m", type=float, required=True, help="standoff radius r_d, m")
    parser.add_argument("--speed-m-s", type=float, required=True, help="vehicle speed s, m/s")
    parser.add_argument(
        "--max-course-rate-rad-s", type=float, required=True, help="course-rate limit, rad/s"
    )
    parser.add_argument(
        "--margin",
        type=float,
        default=1.0,
        help="fraction (0, 1] of the course-rate limit the field may use (default 1)",
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from app.core.guidance.field import optimal_c, peak_curvature

    for flag, value in (
        ("--radius-m", args.radius_m),
        ("--speed-m-s", args.speed_m_s),
        ("--max-course-rate-rad-s", args.max_course_rate_rad_s),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise ConfigError(f"{flag} must be a finite number > 0, got {value}")
    if not (math.isfinite(args.margin) and 0.0 < args.margin <= 1.0):
        raise ConfigError(f"--margin must be in (0, 1], got {args.margin}")
    rd, s, w = args.radius_m, args.speed_m_s, args.max_course_rate_rad_s
    repeats = 200
    started = time.perf_counter()
    for _ in range(repeats):
        c = optimal_c(rd, s, w, args.margin)
    elapsed_ms = (time.perf_counter() - started) / repeats * 1e3
    peak, where = peak_curvature(rd, c)
    limit = args.margin * w / s
    print(f"c_opt = {c:.6f}")
    print(f"  peak |curvature| {peak:.6f} 1/m at r = {where:.1f} m; limit {limit:.6f} 1/m")
    print(f"  search time {elapsed_ms:.3f} ms (mean of {repeats})")
    if rd * w / s < 1.0:
        print(
            f"  infeasible: the circle itself needs {s / rd:.4f} rad/s > {w} rad/s; "
            "c_opt is the smallest c that asks no more than the circle does"
        )
        return 1
    return 0
