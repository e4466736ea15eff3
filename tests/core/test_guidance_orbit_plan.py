"""The planned orbit around a fast target (GuidanceParams(orbit_plan="ellipse"))."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.core.agent import (
    AgentInputs,
    AgentParams,
    AgentState,
    GuidanceParams,
    OwnTelemetry,
    PhaseParams,
    TargetInfo,
    agent_step,
)
from app.core.guidance import orbit_plan
from app.core.guidance.field import FieldParams, field_course
from app.core.guidance.orbit_plan import PlannedOrbit, ellipse_course_and_rate
from app.core.plant import FixedWingState, VehicleEnvelope
from app.runtime.fastsim import SimulationSetup, run_simulation
from sitl.target import Maneuver, TargetPath

ENV = VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.2)


def test_the_circle_is_kept_while_it_is_flyable():
    assert orbit_plan.planned_orbit_axes(90.0, 0.0, 10.0, 0.2) == (90.0, 90.0)
    assert orbit_plan.planned_orbit_axes(90.0, 3.0, 10.0, 0.2) == (90.0, 90.0)


def test_a_fast_target_gets_a_flyable_ellipse_along_its_motion():
    a, b = orbit_plan.planned_orbit_axes(90.0, 7.0, 10.0, 0.2)
    assert a > 90.0 >= b
    need, _ = orbit_plan._turn_need(np.float64(a), np.float64(b), 7.0, 10.0, np.linspace(0, 7, 400))
    assert need <= 0.2 + 1e-3
    # the circle itself is not flyable at that speed
    need_circle, _ = orbit_plan._turn_need(
        np.float64(90.0), np.float64(90.0), 7.0, 10.0, np.linspace(0, 7, 400)
    )
    assert need_circle > 0.25


def test_ellipse_field_with_equal_axes_is_the_ordinary_field():
    for x, y, vx, vy in ((120.0, -30.0, 3.0, 11.0), (-40.0, 60.0, -9.0, 2.0)):
        ref = field_course(x, y, vx, vy, FieldParams(90.0, 0.34))
        got = ellipse_course_and_rate(
            x, y, vx, vy, FieldParams(90.0, 0.34), PlannedOrbit(90.0, 90.0, 0.6, 0.8)
        )
        assert math.isclose(math.remainder(got[0] - ref[0], math.tau), 0.0, abs_tol=1e-9)
        assert math.isclose(got[1], ref[1], rel_tol=1e-9, abs_tol=1e-12)


def test_on_the_ellipse_the_field_is_its_tangent_and_the_rate_is_exact():
    a, b, c = 110.0, 80.0, 0.34
    ux, uy = 0.0, 1.0  # the target moves north: the major axis points north
    field, orbit = FieldParams(90.0, c), PlannedOrbit(a, b, ux, uy)
    for t in np.linspace(0.1, 6.2, 9):
        # along u: a cos t, across (w = west): b sin t
        pu, pw = a * math.cos(t), b * math.sin(t)
        x, y = pu * ux - pw * uy, pu * uy + pw * ux
        du, dw = -a * math.sin(t), b * math.cos(t)
        tx, ty = du * ux - dw * uy, du * uy + dw * ux
        norm = math.hypot(tx, ty)
        speed = 12.0
        vx, vy = speed * tx / norm, speed * ty / norm
        course, rate = ellipse_course_and_rate(x, y, vx, vy, field, orbit)
        assert math.isclose(
            math.remainder(course - math.atan2(vx, vy), math.tau), 0.0, abs_tol=1e-9
        )
        # rate: the tangent's course change along the ellipse, numerically
        h = 1e-4
        x2, y2 = x + vx * h, y + vy * h
        c2, _ = ellipse_course_and_rate(x2, y2, vx, vy, field, orbit)
        assert math.isclose(
            math.remainder(c2 - course, math.tau) / h, rate, rel_tol=1e-3, abs_tol=1e-6
        )


@settings(max_examples=200, deadline=None)
@given(
    st.floats(min_value=-2000.0, max_value=2000.0),
    st.floats(min_value=-2000.0, max_value=2000.0),
    st.floats(min_value=-math.pi, max_value=math.pi),
    st.floats(min_value=0.0, max_value=25.0),
    st.floats(min_value=-15.0, max_value=15.0),
    st.floats(min_value=-15.0, max_value=15.0),
)
def test_planned_orbit_commands_are_finite_and_within_the_envelope(e, n, course, speed, tve, tvn):
    params = AgentParams(
        1,
        ENV,
        GuidanceParams(90.0, inverse_field=False, orbit_plan="ellipse"),
        PhaseParams("paper", 0.1, predictive=True),
    )
    team = ((200.0, 0.0), (e, n), (-100.0, 50.0))
    inputs = AgentInputs(
        0.0, OwnTelemetry(e, n, course, speed), TargetInfo(5.0, -5.0, tve, tvn), team
    )
    _, cmd, _ = agent_step(AgentState(), inputs, params)
    assert math.isfinite(cmd.course_rad)
    assert math.isfinite(cmd.course_rate_ff_rad_s)
    assert 10.0 <= cmd.speed_m_s <= 18.0
    implied = abs(math.remainder(cmd.course_rad - course, math.tau))
    assert implied <= 0.2 + 1e-9


def test_inverse_mode_is_left_when_the_switch_is_off():
    params = AgentParams(0, ENV, GuidanceParams(90.0, inverse_field=False))
    inputs = AgentInputs(1.0, OwnTelemetry(150.0, 0.0, 0.0, 14.0), TargetInfo(0.0, 0.0))
    state, cmd, events = agent_step(AgentState(mode="inverse"), inputs, params)
    assert state.mode == "field"
    assert not cmd.inverse
    assert [e.kind for e in events] == ["inverse-field-off"]


def _team_around(target_speed: float, orbit_plan: str) -> float:
    path = TargetPath.from_maneuvers(0.0, 0.0, 0.0, target_speed, (Maneuver(200.0),))
    starts = tuple(
        FixedWingState(90.0 * math.cos(a), 90.0 * math.sin(a), -a, 14.0)
        for a in (0.0, 2 * math.pi / 3, 4 * math.pi / 3)
    )
    agents = tuple(
        AgentParams(
            i,
            ENV,
            GuidanceParams(90.0, inverse_field=False, orbit_plan=orbit_plan),  # type: ignore[arg-type]
            PhaseParams("paper", 0.1, predictive=True),
        )
        for i in range(3)
    )
    result = run_simulation(SimulationSetup(starts, agents, ENV, path, 0.05, 200.0))
    err = result.distance_error_m()[result.t_s >= 60.0]
    return float(np.sqrt(np.mean(err * err)))


@pytest.mark.slow
def test_planned_orbit_beats_the_circle_around_a_7_m_s_target():
    paper = _team_around(7.0, "circle")
    planned = _team_around(7.0, "ellipse")
    assert planned < 0.75 * paper
    assert planned < 20.0
