"""Phase keeping by speed against phase keeping by orbit radius, side by side.

Run:  .venv/bin/python -m benchmarks.bench_phase_actuator [--duration S] [--dt S]

Flies ``configs/phase-radius.toml`` (three vehicles with the default mission's limits: 14 m/s
cruise in [10, 18] m/s, |a| <= 2 m/s^2, 0.2 rad/s; bunched 15 degrees apart on the 90 m circle;
the seat law at k = 0.1, predictive) in the fast simulation, once with ``actuator = "speed"``
(the speed law commands its speed) and once with ``actuator = "radius"`` (cruise speed held, as
PX4 fixed-wing offboard holds its trim airspeed; the wanted speed flown as an orbit radius within
15 m of r_d), around a stationary target and around targets driving east at 1.5 and 3 m/s.

Prints for each: the spacing settle time (every adjacent gap within 5 and within 2 degrees of
120 for good), the time every vehicle is within 3 m of r_d for good, and the RMS spacing error
(degrees, over every adjacent gap) and RMS distance error (m, over every vehicle), over the
whole run and over its last part (from ``--steady-from`` s), with the radius/speed ratio.
"""

import argparse
import math
import time
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
    base: ScenarioConfig, actuator: str, target_speed_m_s: float, steady_from_s: float
) -> Figures:
    phase = base.phase.model_copy(update={"actuator": actuator})
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
        where = "stationary target" if speed == 0.0 else f"target driving east at {speed} m/s"
        print(f"\n{where}")
        print(f"  {'':34s} {'speed':>12s} {'radius':>12s}  radius/speed")
        rows = [
            ("spaced within 5 deg", by_speed.spaced_5_s, by_radius.spaced_5_s, True),
            ("spaced within 2 deg", by_speed.spaced_2_s, by_radius.spaced_2_s, True),
            ("within 3 m of r_d", by_speed.on_circle_s, by_radius.on_circle_s, True),
            ("RMS spacing error, deg", by_speed.spacing_rms_deg, by_radius.spacing_rms_deg, False),
            ("RMS distance error, m", by_speed.distance_rms_m, by_radius.distance_rms_m, False),
            (
                f"RMS spacing error t>={args.steady_from:.0f} s, deg",
                by_speed.steady_spacing_rms_deg,
                by_radius.steady_spacing_rms_deg,
                False,
            ),
            (
                f"RMS distance error t>={args.steady_from:.0f} s, m",
                by_speed.steady_distance_rms_m,
                by_radius.steady_distance_rms_m,
                False,
            ),
        ]
        for label, a, b, is_time in rows:
            sa, sb = (_t(a), _t(b)) if is_time else (f"{a:8.2f}", f"{b:8.2f}")
            print(f"  {label:34s} {sa:>12s} {sb:>12s}  {_ratio(b, a)}")
        lo_a, hi_a = by_speed.speed_range_m_s
        lo_b, hi_b = by_radius.speed_range_m_s
        print(
            f"  {'speed flown, m/s':34s} {f'{lo_a:.1f}-{hi_a:.1f}':>12s} "
            f"{f'{lo_b:.1f}-{hi_b:.1f}':>12s}"
        )
        print(
            f"  {'CPU, s':34s} {by_speed.cpu_s:12.2f} {by_radius.cpu_s:12.2f}  "
            f"{_ratio(by_radius.cpu_s, by_speed.cpu_s)}"
        )


if __name__ == "__main__":
    main()
