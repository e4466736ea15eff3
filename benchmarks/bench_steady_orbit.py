"""The best steady orbit a team can fly around a target at constant velocity, beside what the
mission flies there.

Run:  .venv/bin/python -m benchmarks.bench_steady_orbit [CONFIG] [--speed 7] [--shares 1 0.95 0.9]
      [--leg-s 600] [--seeds 1]

Around a target at constant velocity a team that keeps its shape repeats itself: vehicle i flies
the path of vehicle 0 shifted by i / n of the period. So the best *steady* flight is one closed
relative path, and its figures follow from it alone: the distance error, and the gaps between
the path and itself a period / n later against 2 pi / n. ``steady_optimum`` finds it: SLSQP on
the course rate and acceleration held over each of ``BLOCKS`` blocks (the airframe of
``bench_oracle``: course rate within the limit with no lag, |acceleration| within its limit,
speed in its band), the start state and the period, with the flight closed after one period
(position relative to the target, speed, and the course one turn on), minimising the cost
``bench_oracle`` scores, mean (d / 3 m)^2 + (e / 4 deg)^2. It is flown at each ``--shares`` of
the course-rate limit: what a controller that keeps that much of the limit in reserve could
hold.

Beside it, the mission's fast simulation (``app.compose.mission_fastsim``, the config's track
stage with its estimator, or with ``--truth`` on the true target) around a target that sets
off from A at ``--speed`` on one straight leg of ``--leg-s`` seconds, scored from 60 s after
the target starts until 60 s before the leg's end (the transient of the start left out).

Prints each optimum's RMS distance / spacing error, largest distance error and period, the
mission's steady figures, and the mission's ratios to each optimum.
"""

import argparse
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize  # type: ignore[import-untyped]

from app.compose.mission_fastsim import MissionSimSetup, run_mission_sim
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.config.schema import LegConfig, WaypointTargetConfig

Array = NDArray[np.float64]

#: blocks of held controls over the period (rounded up to a multiple of the team's size)
BLOCKS = 36
#: samples of the flight in each block (the cost's samples)
SUBSTEPS = 4
#: the cost's scales, as ``bench_oracle``'s: (d / 3 m)^2 + (e / 4 deg)^2
DIST_REF_M = 3.0
SPACING_REF_RAD = math.radians(4.0)
#: how far the flight may end from its start and its speeds leave the band (m, rad, m/s)
TOLERANCE = 1e-3
#: the steady part of the mission's leg: from this long after the target sets off until this
#: long before the leg ends, s
SETTLE_S = 60.0


@dataclass(frozen=True, slots=True)
class SteadyOrbit:
    """The best steady flight found: the relative path (samples, 2) with the target moving
    along the first axis, the ground course rates (blocks) and speeds (samples + 1), its period
    and figures."""

    path: Array
    rates: Array
    speeds: Array
    period_s: float
    cost: float
    dist_rms_m: float
    dist_max_m: float
    spacing_rms_deg: float


def steady_optimum(
    radius_m: float,
    target_speed_m_s: float,
    vehicles: int,
    min_speed_m_s: float,
    max_speed_m_s: float,
    max_accel_m_s2: float,
    max_course_rate_rad_s: float,
) -> SteadyOrbit | None:
    """The team's best closed steady flight (module docstring), counter-clockwise around a
    target moving at ``target_speed_m_s`` along the first axis; None if the optimiser found no
    flight that closes within the limits."""
    rd, v, n, w = radius_m, target_speed_m_s, vehicles, max_course_rate_rad_s
    nb = n * math.ceil(BLOCKS / n)
    shift = SUBSTEPS * nb // n

    def flight(x: Array) -> tuple[Array, Array, Array]:
        rates = np.repeat(x[:nb] * w, SUBSTEPS)
        accels = np.repeat(x[nb : 2 * nb] * max_accel_m_s2, SUBSTEPS)
        pu0, pw0, chi0, s0, period = x[2 * nb :]
        h = period / (nb * SUBSTEPS)
        chi = chi0 + np.concatenate([[0.0], np.cumsum(rates * h)])
        speed = s0 + np.concatenate([[0.0], np.cumsum(accels * h)])
        mid_chi = 0.5 * (chi[1:] + chi[:-1])
        mid_s = 0.5 * (speed[1:] + speed[:-1])
        step = np.stack([mid_s * np.cos(mid_chi) - v, mid_s * np.sin(mid_chi)], 1) * h
        rel = np.concatenate([[[pu0, pw0]], np.array([pu0, pw0]) + np.cumsum(step, axis=0)])
        return rel, chi, speed

    def errors(x: Array) -> tuple[Array, Array]:
        p = flight(x)[0][:-1]
        polar = np.arctan2(p[:, 1], p[:, 0])
        gap = np.mod(np.roll(polar, -shift) - polar, 2.0 * math.pi) - 2.0 * math.pi / n
        return np.hypot(p[:, 0], p[:, 1]) - rd, gap

    def cost(x: Array) -> float:
        d, e = errors(x)
        return float(np.mean((d / DIST_REF_M) ** 2) + np.mean((e / SPACING_REF_RAD) ** 2))

    def closed(x: Array) -> Array:
        rel, chi, speed = flight(x)
        return np.array(
            [
                rel[-1, 0] - rel[0, 0],
                rel[-1, 1] - rel[0, 1],
                chi[-1] - chi[0] - 2.0 * math.pi,
                speed[-1] - speed[0],
            ]
        )

    def band(x: Array) -> Array:
        speed = flight(x)[2]
        return np.concatenate([speed - min_speed_m_s, max_speed_m_s - speed])

    # start: the circle r_d at the middle of the speed band
    s0 = 0.5 * (min_speed_m_s + max_speed_m_s)
    period0 = 2.0 * math.pi * rd / s0
    x0 = np.concatenate(
        [
            np.full(nb, min(2.0 * math.pi / period0 / w, 1.0)),
            np.zeros(nb),
            [rd, 0.0, 0.5 * math.pi, s0, period0],
        ]
    )
    bounds = [(-1.0, 1.0)] * (2 * nb) + [(None, None)] * 4 + [(5.0, 600.0)]
    res = minimize(
        cost,
        x0,
        method="SLSQP",
        bounds=bounds,
        constraints=[{"type": "eq", "fun": closed}, {"type": "ineq", "fun": band}],
        options={"maxiter": 500, "ftol": 1e-9},
    )
    x = res.x
    if (
        not np.all(np.isfinite(x))
        or float(np.max(np.abs(closed(x)))) > TOLERANCE
        or float(np.min(band(x))) < -TOLERANCE
    ):
        return None
    rel, _, speed = flight(x)
    d, e = errors(x)
    return SteadyOrbit(
        path=rel[:-1],
        rates=x[:nb] * w,
        speeds=speed,
        period_s=float(x[-1]),
        cost=cost(x),
        dist_rms_m=float(np.sqrt(np.mean(d**2))),
        dist_max_m=float(np.max(np.abs(d))),
        spacing_rms_deg=math.degrees(float(np.sqrt(np.mean(e**2)))),
    )


def straight_leg(config: MissionConfig, speed_m_s: float, leg_s: float) -> MissionConfig:
    """``config`` with its target replaced by one straight leg north from where it waits, at
    ``speed_m_s`` for ``leg_s`` seconds."""
    target = config.target
    if not isinstance(target, WaypointTargetConfig):
        raise SystemExit(f"'{config.name}' has no waypoint target to replace with a straight leg")
    leg = LegConfig.model_validate(
        {
            "to_east_m": target.start_east_m,
            "to_north_m": target.start_north_m + speed_m_s * leg_s,
            "speed_m_s": speed_m_s,
            "accel_m_s2": target.legs[0].accel_m_s2,
            "label": "leg",
        }
    )
    return config.model_copy(update={"target": target.model_copy(update={"legs": [leg]})})


def mission_steady(
    config: MissionConfig, seed: int, leg_s: float, truth: bool
) -> tuple[float, float, float]:
    """The mission's RMS distance error (m), largest distance error (m) and RMS spacing error
    (deg) over the steady part of the straight leg (fast simulation)."""
    result = run_mission_sim(MissionSimSetup(build_plan(config), seed=seed, truth_fed=truth))
    start = config.target.wait_s if isinstance(config.target, WaypointTargetConfig) else 0.0
    rows = [s for s in result.samples if start + SETTLE_S <= s.t_s <= start + leg_s - SETTLE_S]
    if not rows:
        raise SystemExit("the leg is too short for a steady part: raise --leg-s")
    east = np.array([[v.east_m for v in s.vehicles] for s in rows])
    north = np.array([[v.north_m for v in s.vehicles] for s in rows])
    rel_e = east - np.array([s.target_east_m for s in rows])[:, None]
    rel_n = north - np.array([s.target_north_m for s in rows])[:, None]
    d = np.hypot(rel_e, rel_n) - config.radius_m
    polar = (1.0 if config.orbit == "ccw" else -1.0) * np.arctan2(rel_n, rel_e)
    order = np.argsort(np.mod(polar[0], 2.0 * math.pi))
    successor = np.empty(len(order), dtype=int)
    successor[order] = np.roll(order, -1)
    e = np.mod(polar[:, successor] - polar, 2.0 * math.pi) - 2.0 * math.pi / len(order)
    return (
        float(np.sqrt(np.mean(d**2))),
        float(np.max(np.abs(d))),
        math.degrees(float(np.sqrt(np.mean(e**2)))),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="hil")
    parser.add_argument("--speed", type=float, default=7.0, help="the target's speed, m/s")
    parser.add_argument(
        "--shares",
        type=float,
        nargs="+",
        default=[1.0, 0.95, 0.9],
        help="shares of the course-rate limit the optimum may use",
    )
    parser.add_argument("--leg-s", type=float, default=600.0)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--truth", action="store_true", help="the agents steer on the true target")
    args = parser.parse_args()
    config = load_config(args.config, MissionConfig)
    lim = config.limits
    n = config.vehicles
    print(
        f"steady orbit around a target at {args.speed:g} m/s: '{config.name}', {n} vehicles, "
        f"r_d {config.radius_m:g} m, {lim.min_speed_m_s:g}-{lim.max_speed_m_s:g} m/s, "
        f"{lim.max_accel_m_s2:g} m/s^2, course rate {lim.max_course_rate_rad_s:g} rad/s"
    )
    optima: dict[float, SteadyOrbit | None] = {}
    for share in args.shares:
        optima[share] = steady_optimum(
            config.radius_m,
            args.speed,
            n,
            lim.min_speed_m_s,
            lim.max_speed_m_s,
            lim.max_accel_m_s2,
            share * lim.max_course_rate_rad_s,
        )
        o = optima[share]
        if o is None:
            print(f"  optimum at {share:.2f} of the course-rate limit: none found")
            continue
        print(
            f"  optimum at {share:.2f} of the course-rate limit: {o.dist_rms_m:.2f} m / "
            f"{o.spacing_rms_deg:.2f} deg RMS, largest {o.dist_max_m:.1f} m, period "
            f"{o.period_s:.1f} s, cost {o.cost:.2f}"
        )
    leg = straight_leg(config, args.speed, args.leg_s)
    flown = [mission_steady(leg, seed, args.leg_s, args.truth) for seed in args.seeds]
    d_rms, d_max, e_rms = (float(np.mean(col)) for col in zip(*flown, strict=True))
    source = "true target" if args.truth else "its estimator"
    print(
        f"  mission ({source}, seeds {args.seeds}), {SETTLE_S:g} s after the start to "
        f"{SETTLE_S:g} s before the leg's end: {d_rms:.2f} m / {e_rms:.2f} deg RMS, largest "
        f"{d_max:.1f} m, cost {(d_rms / DIST_REF_M) ** 2 + (e_rms / 4.0) ** 2:.2f}"
    )
    for share, o in optima.items():
        if o is not None:
            print(
                f"  mission / optimum at {share:.2f}: distance {d_rms / o.dist_rms_m:.2f}x, "
                f"spacing {e_rms / o.spacing_rms_deg:.2f}x"
            )


if __name__ == "__main__":
    main()
