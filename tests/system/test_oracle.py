"""The perfect-foresight optimiser of benchmarks/bench_oracle.py: its gradient, its limits, and
that it finds what is known to be possible."""

import argparse
import json
import math

import numpy as np
import pytest

from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from benchmarks.bench_oracle import (
    Airframe,
    Problem,
    case,
    cost_and_gradient,
    fly,
    run_figures,
    run_samples,
    solve,
)

AIRFRAME = Airframe(10.0, 18.0, 2.0, 0.2)


@pytest.mark.parametrize("score_from", [1, 7])
def test_the_gradient_is_the_costs_derivative(score_from):
    rng = np.random.default_rng(3)
    steps, n = 40, 3
    problem = Problem(
        position=rng.normal(0.0, 60.0, (n, 2)) + np.array([100.0, 0.0]),
        heading=rng.uniform(-math.pi, math.pi, n),
        speed=np.array([12.0, 17.9, 10.05]),  # two of them run into a speed limit
        target=np.cumsum(np.full((steps + 1, 2), 0.4), axis=0),
        dt_s=0.25,
        radius_m=90.0,
        airframe=AIRFRAME,
        score_from=score_from,
    )
    x = np.concatenate([rng.uniform(-0.2, 0.2, steps * n), rng.uniform(-2.0, 2.0, steps * n)])
    _, grad = cost_and_gradient(x, problem)
    h = 1e-4  # the cost is ~4e3: a smaller step drowns the difference in rounding
    for i in rng.choice(x.size, 20, replace=False):
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        numeric = (cost_and_gradient(up, problem)[0] - cost_and_gradient(down, problem)[0]) / (
            2 * h
        )
        assert math.isclose(grad[i], numeric, rel_tol=1e-5, abs_tol=1e-8), i


def test_it_finds_the_orbit_a_vehicle_on_the_circle_can_hold():
    # On the circle about a still target, flying its tangent at 14 m/s: holding it takes
    # 14 / 90 rad/s, within the 0.2 limit. Started flying straight on, the optimiser turns.
    steps = 100
    problem = Problem(
        position=np.array([[90.0, 0.0]]),
        heading=np.array([math.pi / 2]),
        speed=np.array([14.0]),
        target=np.zeros((steps + 1, 2)),
        dt_s=0.2,
        radius_m=90.0,
        airframe=AIRFRAME,
    )
    straight = np.zeros(2 * steps)
    best, found = solve(problem, {"straight": straight}, max_iter=600)
    start_cost = cost_and_gradient(straight, problem)[0]
    assert found["straight"] is best
    assert best.cost < start_cost
    assert best.dist_rms_m < 0.5
    speed = best.flight.speed
    assert speed.min() >= 10.0
    assert speed.max() <= 18.0
    rates = np.diff(best.flight.heading, axis=0) / problem.dt_s
    assert np.abs(rates).max() <= 0.2 + 1e-9
    assert np.abs(np.diff(speed, axis=0) / problem.dt_s).max() <= 2.0 + 1e-9


def test_it_cannot_hold_a_circle_tighter_than_the_airframe_turns():
    # A still target and a 40 m circle: at 10 m/s and 0.2 rad/s the tightest turn is 50 m
    # across, so the best any controller can do is orbit at about 50 m, 10 m off.
    steps = 200
    problem = Problem(
        position=np.array([[40.0, 0.0]]),
        heading=np.array([math.pi / 2]),
        speed=np.array([10.0]),
        target=np.zeros((steps + 1, 2)),
        dt_s=0.2,
        radius_m=40.0,
        airframe=AIRFRAME,
    )
    best, _ = solve(problem, {"straight": np.zeros(2 * steps)})
    flight = fly(problem, np.zeros((steps, 1)), np.zeros((steps, 1)))
    assert flight.position.shape == (steps + 1, 1, 2)
    assert 5.0 < best.dist_rms_m < 15.0


@pytest.mark.slow
def test_a_flown_run_folder_is_read_and_its_segment_handed_to_the_oracle(tmp_path, capsys):
    # a run folder whose team circles the true target exactly (90 m, 120 degrees apart, at
    # 0.155 rad/s: 11-17 m/s over the ground, within the limits) over 12 s of B-C from 10 s
    # after the turn: the oracle, started from that flight, stays on the circle
    plan = build_plan(load_config("hil", MissionConfig))
    times = np.arange(0.0, 400.0, 0.1)
    t_b = next(t for t in times if plan.target.segment_at(float(t)) == "B-C")
    times = times[(times >= t_b + 10.0) & (times <= t_b + 22.0)]
    rows = []
    for t in times:
        here = plan.target.state_at(float(t))
        later = plan.target.state_at(float(t) + 0.01)
        for i in range(3):
            angle = 0.155 * t + 2 * math.pi * i / 3
            east = here.east_m + 90.0 * math.cos(angle)
            north = here.north_m + 90.0 * math.sin(angle)
            ve = (later.east_m - here.east_m) / 0.01 - 90.0 * 0.155 * math.sin(angle)
            vn = (later.north_m - here.north_m) / 0.01 + 90.0 * 0.155 * math.cos(angle)
            rows.append(
                f"{t:.3f},{i},{east},{north},{math.atan2(ve, vn)},{math.hypot(ve, vn)},"
                f"{here.east_m},{here.north_m},1,nan,nan,track"
            )
    header = "t_s,vehicle,east_m,north_m,course_rad,speed_m_s,target_east_m,target_north_m,"
    header += "active,estimate_east_m,estimate_north_m,stage"
    (tmp_path / "track.csv").write_text("\n".join([header, *rows]) + "\n")
    team = {"distance_error_m": {"rms": 5.0}, "spacing_error_deg": {"rms": 2.0}}
    (tmp_path / "summary.json").write_text(json.dumps({"parts": {"track:B-C": {"team": team}}}))
    samples = run_samples(tmp_path, plan)
    assert len(samples) == len(times)
    assert {s.target_segment for s in samples} == {"B-C"}
    assert samples[-1].vehicles[2].east_m == pytest.approx(float(rows[-1].split(",")[2]))
    assert run_figures(tmp_path, "B-C") == (5.0, 2.0)
    args = argparse.Namespace(segment="B-C", lead=0.0, blind=0.0, dt=0.2, perturbed=0, max_iter=200)
    limits = plan.config.limits
    airframe = Airframe(limits.min_speed_m_s, limits.max_speed_m_s, limits.max_accel_m_s2, 0.2)
    mission_d, mission_s, oracle_d, oracle_s = case(
        "run", samples, plan, (5.0, 2.0), args, airframe, 0
    )
    assert (mission_d, mission_s) == (5.0, 2.0)
    assert oracle_d < 1.0
    assert oracle_s < 1.0
    assert "mission/oracle" in capsys.readouterr().out
