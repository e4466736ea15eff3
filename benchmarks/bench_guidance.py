"""Guidance and phase keeping against the paper and against the physical limits.

Run:  .venv/bin/python -m benchmarks.bench_guidance [--skip-phase]

Prints, in one run:
- optimal c for Table 1 and Table 2 against an independent exact root, and the search time;
- Simulation A and B (paper section 5.1.1) for the proposed law (optimal c, ILVF, lag
  compensation), the same without lag compensation (the paper's literal eq. 2 loop), Frew's
  field (c = 2) with and without it, beside the shortest tangential join any 20 m/s,
  0.2 rad/s vehicle can fly;
- the compute time of a 400 s Simulation A at 0.01 s steps (best of 3);
- phase keeping (section 5.1.3) from the circle and from a gather: the paper's seat law and
  Frew's neighbour law over a gain sweep, literal and predictive, beside the speed-limited bound.
"""

import argparse
import math
import time
import warnings
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.optimize import brentq, minimize_scalar  # type: ignore[import-untyped]

from app.config import load_config
from app.config.scenario import ScenarioConfig, build_setup
from app.core.guidance.field import curvature, optimal_c
from app.runtime.fastsim import (
    SimulationSetup,
    phase_figures,
    phase_lower_bound_s,
    run_simulation,
    standoff_figures,
)


def exact_optimal_c(rd: float, s: float, w: float) -> float:
    """Independent reference: numerical peak of |eq. 11| over r >= r_d, Brent root in c."""

    def peak(c: float) -> float:
        res = minimize_scalar(
            lambda lr: -abs(curvature(rd * math.exp(lr), rd, c)),
            bounds=(0.0, 4.0),
            method="bounded",
            options={"xatol": 1e-12},
        )
        grid = max(abs(curvature(rd * math.exp(x), rd, c)) for x in np.linspace(0, 4, 4001))
        return max(-float(res.fun), grid)

    return float(brentq(lambda c: peak(c) - w / s, 0.02, 1.4, xtol=1e-12))


def shortest_join_s(
    east: float, north: float, course_rad: float, rd: float, speed: float, w: float
) -> float:
    """Shortest time to join the circle tangentially, counter-clockwise, for a vehicle at
    constant ``speed`` with turn radius speed / w, over paths turn-straight-turn whose last turn
    is the join arc (clockwise, externally tangent to the circle): the CSC Dubins families that
    end on the circle. A grid over the first turn, refined, gives the minimum. (Not a bound
    for every path family, and "settled" only needs |r - r_d| < 3 m, so it can be beaten by a
    little, e.g. by a vehicle that starts slower and so turns tighter.)"""
    big_r = speed / w
    h0 = math.pi / 2 - course_rad  # paper angle, counter-clockwise from east

    def time_for(alpha: float) -> float:
        # first turn by alpha (counter-clockwise > 0) at the limit
        if abs(alpha) < 1e-12:
            x, y, h = east, north, h0
        else:
            side = 1.0 if alpha > 0 else -1.0
            cx = east - side * big_r * math.sin(h0)
            cy = north + side * big_r * math.cos(h0)
            h = h0 + alpha
            x = cx + side * big_r * math.sin(h)
            y = cy - side * big_r * math.cos(h)
        ux, uy = math.cos(h), math.sin(h)
        # centre of the clockwise (right) join turn moves along the straight
        c0x, c0y = x + big_r * uy, y - big_r * ux
        b = c0x * ux + c0y * uy
        q = c0x * c0x + c0y * c0y - (rd + big_r) ** 2
        disc = b * b - q
        if disc < 0.0:
            return math.inf
        roots = [L for L in (-b - math.sqrt(disc), -b + math.sqrt(disc)) if L >= 0.0]
        if not roots:
            return math.inf
        straight = min(roots)
        cx, cy = c0x + straight * ux, c0y + straight * uy
        contact = math.atan2(cy, cx)
        h_final = contact + math.pi / 2
        arc = (h - h_final) % (2 * math.pi)
        return (abs(alpha) * big_r + straight + arc * big_r) / speed

    alphas = np.linspace(-2 * math.pi, 2 * math.pi, 4001)
    best = min(alphas, key=time_for)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # inf where no join exists
        res = minimize_scalar(time_for, bounds=(best - 0.01, best + 0.01), method="bounded")
    return min(time_for(float(best)), float(res.fun))


def _setup(name: str, **guidance: Any) -> SimulationSetup:
    setup = build_setup(load_config(name, ScenarioConfig))
    if guidance:
        agents = tuple(replace(a, guidance=replace(a.guidance, **guidance)) for a in setup.agents)
        setup = replace(setup, agents=agents)
    return setup


def _fmt(t: float) -> str:
    return "  never" if math.isinf(t) else f"{t:7.2f}"


def bench_optimal_c() -> None:
    print("optimal c (section 4.1): closed-form extremum + bisection vs independent exact root")
    for rd, s, w, label in ((300.0, 20.0, 0.2, "Table 1"), (90.0, 14.0, 0.2, "Table 2")):
        c = optimal_c(rd, s, w)
        exact = exact_optimal_c(rd, s, w)
        n = 2000
        t0 = time.perf_counter()
        for _ in range(n):
            optimal_c(rd, s, w)
        us = (time.perf_counter() - t0) / n * 1e6
        print(
            f"  {label} (r_d {rd:g} m, s {s:g} m/s, {w:g} rad/s): c_opt {c:.6f}, exact "
            f"{exact:.6f}, |diff| {abs(c - exact):.1e}, {us:.0f} us per search"
        )


def bench_standoff() -> None:
    cases: tuple[tuple[str, dict[str, Any]], ...] = (
        ("proposed (optimal c, ILVF, feed-forward)", {}),
        ("proposed, literal eq. 2 loop (no feed-forward)", {"feed_forward": False}),
        ("Frew c = 2, feed-forward", {"law": "frew"}),
        ("Frew c = 2, literal eq. 2 loop", {"law": "frew", "feed_forward": False}),
    )
    for name, start in (
        ("sim-a", (600.0, 600.0, math.radians(225.0))),
        ("sim-b", (300.0, 300.0, math.pi)),
    ):
        limit = shortest_join_s(*start, 300.0, 20.0, 0.2)
        print(
            f"{name}: settle (|r - r_d| < 3 m to 400 s), min r - r_d, crossings > 0.5 m; "
            f"shortest tangential join at 20 m/s, 0.2 rad/s: {limit:.2f} s"
        )
        for label, overrides in cases:
            fig = standoff_figures(run_simulation(_setup(name, **overrides)))
            print(
                f"  {label:48s} settle {_fmt(fig.settle_s)} s"
                f"  min {fig.min_distance_error_m:8.2f} m  crossings {fig.crossings}"
            )
    print("  (paper: sim-a 53 s for its law, 210 s for Frew's)")


def bench_speed() -> None:
    setup = _setup("sim-a")
    best = math.inf
    for _ in range(3):
        t0 = time.process_time()
        run_simulation(setup)
        best = min(best, time.process_time() - t0)
    print(f"compute: 400 s of sim-a at 0.01 s steps (40000 steps) in {best:.2f} s CPU (best of 3)")


def bench_phase() -> None:
    gains = (0.1, 0.2, 0.3, 0.5, 1.0)
    for name in ("phase", "phase-gather"):
        base = replace(_setup(name), duration_s=250.0)
        bound = phase_lower_bound_s(base)
        kind = "exact" if name == "phase" else "estimate on cruise paths"
        print(
            f"{name}: spacing within 2 deg for good (s); speed-limited bound {bound:.1f} s ({kind})"
        )
        variants = [(False, "literal")] + ([(True, "predictive")] if name != "phase" else [])
        for law in ("paper", "frew"):
            for predictive, tag in variants:
                row = []
                best = (math.inf, 0.0)
                for gain in gains:
                    agents = tuple(
                        replace(
                            a,
                            phase=replace(a.phase, law=law, gain_per_s=gain, predictive=predictive),
                        )
                        for a in base.agents
                    )
                    result = run_simulation(replace(base, agents=agents))
                    ph = phase_figures(result)
                    ok = ph.min_speed_m_s >= 13 - 1e-9 and ph.max_speed_m_s <= 25 + 1e-9
                    ok = ok and ph.max_abs_accel_m_s2 <= 2 + 1e-9
                    row.append(f"k={gain:g}: {_fmt(ph.settle_s).strip()}{'' if ok else '!'}")
                    best = min(best, (ph.settle_s, gain))
                print(f"  {law:5s} {tag:10s} " + ", ".join(row))
                print(f"  {'':5s} {'':10s} best {best[0]:.2f} s at k = {best[1]:g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-phase", action="store_true", help="skip the phase gain sweeps")
    args = parser.parse_args()
    bench_optimal_c()
    bench_standoff()
    bench_speed()
    if not args.skip_phase:
        bench_phase()


if __name__ == "__main__":
    main()
