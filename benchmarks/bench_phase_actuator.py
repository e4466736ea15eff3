"""Phase keeping by speed against phase keeping by orbit radius, side by side.

Run:  .venv/bin/python -m benchmarks.bench_phase_actuator [--duration S] [--dt S]

Flies ``configs/phase-radius.toml`` (three vehicles with the default mission's limits: 14 m/s
cruise in [10, 18] m/s, |a| <= 2 m/s^2, 0.2 rad/s; bunched 15 degrees apart on the 90 m circle;
the seat law at k = 0.1, predictive) in the fast simulation, once with ``actuator = "speed"``
(the speed law commands its speed) and once with ``actuator = "radius"`` (cruise speed held, as
PX4 fixed-wing offboard holds its trim airspeed; the wanted speed flown as an orbit radius within
15 m of r_d), around a stationary target and around targets driving east at 1.5 and 3 m/s;
around a moving target also with ``radius_phase = "polar"`` (the radius keeps the polar angles
spaced, not the orbit-time phases).

Prints for each: the spacing settle time (every adjacent gap within 5 and within 2 degrees of
120 for good), the time every vehicle is within 3 m of r_d for good, and the RMS spacing error
(degrees, over every adjacent gap) and RMS distance error (m, over every vehicle), over the
whole run and over its last part (from ``--steady-from`` s), with the radius/speed ratio.
"""

import argparse
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from app.config import load_config
from app.config.scenario import ScenarioConfig, build_setup
from app.config.schema import LegConfig, StationaryTargetConfig, TargetConfig, WaypointTargetConfig
from app.core.frames import TAU
from app.core.mission.stage import adjacent_phase_differences
from app.core.sampled_run import SimulationResult
from app.runtime.fastsim import phase_settle_time_s, run_simulation, settle_time_s


@dataclass(frozen=True, slots=True)
class Figures:
    spaced_5_s: float
    spaced_2_s: float
    on_circle_s: float
    spacing_rms_deg: float
    distance_rms_m: float
    steady_spacing_rms_deg: float
    steady_distance_rms_m: float
    speed_range_m_s: tuple[float, float]
    cpu_s: float


def _figures(result: SimulationResult, steady_from_s: float, cpu_s: float) -> Figures:
    phases = result.phases_rad()
    n = phases.shape[1]
    spacing = np.degrees(adjacent_phase_differences(phases) - TAU / n)
    distance = result.distance_error_m()
    steady = result.t_s >= steady_from_s

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.square(x))))

    return Figures(
        spaced_5_s=phase_settle_time_s(result.t_s, phases, math.radians(5.0)),
        spaced_2_s=phase_settle_time_s(result.t_s, phases, math.radians(2.0)),
        on_circle_s=settle_time_s(result.t_s, distance, 3.0),
        spacing_rms_deg=rms(spacing),
        distance_rms_m=rms(distance),
        steady_spacing_rms_deg=rms(spacing[steady]),
        steady_distance_rms_m=rms(distance[steady]),
        speed_range_m_s=(float(result.speed_m_s.min()), float(result.speed_m_s.max())),
        cpu_s=cpu_s,
    )


def _target(speed_m_s: float, duration_s: float) -> TargetConfig:
    if speed_m_s == 0.0:
        return StationaryTargetConfig(kind="stationary")
    leg = LegConfig(to_east_m=speed_m_s * (duration_s + 60.0), to_north_m=0.0, speed_m_s=speed_m_s)
    return WaypointTargetConfig(legs=[leg])


def _fly(
    base: ScenarioConfig,
    actuator: str,
    target_speed_m_s: float,
    steady_from_s: float,
    radius_phase: str = "orbit_time",
) -> Figures:
    phase = base.phase.model_copy(update={"actuator": actuator, "radius_phase": radius_phase})
    target = _target(target_speed_m_s, base.duration_s)
    scenario = base.model_copy(update={"phase": phase, "target": target})
    setup = build_setup(scenario)
    start = time.process_time()
    result = run_simulation(setup)
    return _figures(result, steady_from_s, time.process_time() - start)


def _ratio(a: float, b: float) -> str:
    """a / b, or "-" where it says nothing (a never-settled time, a denominator that rounds
    to zero in the table)."""
    if math.isinf(a) or math.isinf(b) or abs(b) < 0.005:
        return "  -  "
    return f"{a / b:5.2f}"


def _t(value: float) -> str:
    return "never" if math.isinf(value) else f"{value:6.1f} s"


def _row(
    label: str, pick: Callable[[Figures], float], is_time: bool, variants: list[Figures]
) -> None:
    """One figure of each variant, and each's ratio to the first (by speed)."""
    fmt = _t if is_time else (lambda x: f"{x:8.2f}")
    first = pick(variants[0])
    line = f"  {label:34s} {fmt(first):>12s}"
    for f in variants[1:]:
        value = pick(f)
        line += f" {fmt(value):>12s}  {_ratio(value, first):>12s}"
    print(line)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=300.0, help="run length, s")
    parser.add_argument("--dt", type=float, default=0.02, help="step, s")
    parser.add_argument("--steady-from", type=float, default=150.0, help="steady window start, s")
    parser.add_argument(
        "--target-speeds", type=float, nargs="+", default=[0.0, 1.5, 3.0], help="m/s, east"
    )
    args = parser.parse_args()
    base = load_config("phase-radius", ScenarioConfig).model_copy(
        update={"duration_s": args.duration, "dt_s": args.dt}
    )
    print(
        f"phase-radius: 3 vehicles bunched 15 deg apart on r_d = {base.radius_m:.0f} m, "
        f"cruise {base.limits.cruise_speed_m_s} m/s in [{base.limits.min_speed_m_s}, "
        f"{base.limits.max_speed_m_s}], seat law k = {base.phase.gain_per_s}, "
        f"band {base.phase.radius_band_m} m, {args.duration:.0f} s at dt {args.dt} s"
    )
    for speed in args.target_speeds:
        by_speed = _fly(base, "speed", speed, args.steady_from)
        by_radius = _fly(base, "radius", speed, args.steady_from)
        polar = _fly(base, "radius", speed, args.steady_from, "polar") if speed > 0.0 else None
        where = "stationary target" if speed == 0.0 else f"target driving east at {speed} m/s"
        print(f"\n{where}")
        head = f"  {'':34s} {'speed':>12s} {'radius':>12s}  radius/speed"
        print(head + (f" {'polar':>12s}  polar/speed" if polar else ""))

        variants = [by_speed, by_radius] + ([polar] if polar is not None else [])

        _row("spaced within 5 deg", lambda f: f.spaced_5_s, True, variants)
        _row("spaced within 2 deg", lambda f: f.spaced_2_s, True, variants)
        _row("within 3 m of r_d", lambda f: f.on_circle_s, True, variants)
        _row("RMS spacing error, deg", lambda f: f.spacing_rms_deg, False, variants)
        _row("RMS distance error, m", lambda f: f.distance_rms_m, False, variants)
        steady = f"t>={args.steady_from:.0f} s"
        _row(
            f"RMS spacing error {steady}, deg", lambda f: f.steady_spacing_rms_deg, False, variants
        )
        _row(f"RMS distance error {steady}, m", lambda f: f.steady_distance_rms_m, False, variants)
        flown = [
            f"{f.speed_range_m_s[0]:.1f}-{f.speed_range_m_s[1]:.1f}" for f in (by_speed, by_radius)
        ]
        print(f"  {'speed flown, m/s':34s} {flown[0]:>12s} {flown[1]:>12s}")
        _row("CPU, s", lambda f: f.cpu_s, False, variants)


if __name__ == "__main__":
    main()
