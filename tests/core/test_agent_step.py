"""agent_step: one vehicle's pure decision step."""

import math

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
from app.core.guidance.field import optimal_c
from app.core.plant import VehicleEnvelope

ENV = VehicleEnvelope(20.0, 13.0, 25.0, 2.0, 0.2, 1.0)
PARAMS = AgentParams(0, ENV, GuidanceParams(300.0))
ORIGIN = TargetInfo(0.0, 0.0)


def _inputs(e, n, course, speed, t=0.0, target=ORIGIN, team=()):
    return AgentInputs(t, OwnTelemetry(e, n, course, speed), target, team)


def test_on_the_circle_it_commands_the_tangent_and_cruise():
    # east of the target, counter-clockwise: tangent is due north
    state, cmd, events = agent_step(AgentState(), _inputs(300.0, 0.0, 0.0, 20.0), PARAMS)
    assert cmd.field_course_rad == pytest.approx(0.0, abs=1e-12)
    assert cmd.speed_m_s == 20.0
    # the lead is the orbit's own turn rate / k: s / r_d anticlockwise = -0.0667 rad of course
    assert cmd.course_rad == pytest.approx(-20.0 / 300.0, rel=1e-6)
    assert cmd.c == pytest.approx(optimal_c(300.0, 20.0, 0.2), abs=1e-3)
    assert not cmd.inverse
    assert events == ()
    assert state.c == cmd.c


def test_clockwise_orbit_goes_the_other_way():
    params = AgentParams(0, ENV, GuidanceParams(300.0, orbit="cw"))
    _, cmd, _ = agent_step(AgentState(), _inputs(300.0, 0.0, math.pi, 20.0), params)
    assert abs(cmd.field_course_rad) == pytest.approx(math.pi)


def test_the_step_is_pure_and_deterministic():
    state = AgentState()
    inputs = _inputs(300.0, 300.0, math.pi, 18.0)
    first = agent_step(state, inputs, PARAMS)
    second = agent_step(state, inputs, PARAMS)
    assert first == second
    assert state == AgentState()  # the input state is untouched


def test_simulation_b_start_switches_to_the_inverse_field_with_an_event():
    state, cmd, events = agent_step(AgentState(), _inputs(300.0, 300.0, math.pi, 18.0), PARAMS)
    assert cmd.inverse
    assert state.mode == "inverse"
    assert [e.kind for e in events] == ["inverse-field-on"]
    # the next check waits for the period, so the next tick keeps the mode without events
    _, cmd2, events2 = agent_step(state, _inputs(300.0, 299.8, math.pi, 18.0, t=0.01), PARAMS)
    assert cmd2.inverse
    assert events2 == ()


def test_frew_and_fixed_laws_never_use_the_inverse_field():
    for guidance in (GuidanceParams(300.0, law="frew"), GuidanceParams(300.0, law="fixed", c=0.5)):
        params = AgentParams(0, ENV, guidance)
        _, cmd, _ = agent_step(AgentState(), _inputs(300.0, 300.0, math.pi, 18.0), params)
        assert not cmd.inverse
        assert cmd.c == (2.0 if guidance.law == "frew" else 0.5)


@pytest.mark.parametrize(
    ("field", "inputs"),
    [
        ("own.east_m", _inputs(math.nan, 0.0, 0.0, 20.0)),
        ("own.course_rad", _inputs(300.0, 0.0, math.inf, 20.0)),
        ("target.v_east_m_s", _inputs(300.0, 0.0, 0.0, 20.0, target=TargetInfo(0, 0, math.nan))),
        ("team_positions", _inputs(300.0, 0.0, 0.0, 20.0, team=((1.0, math.nan), (0.0, 0.0)))),
    ],
)
def test_non_finite_inputs_are_rejected_by_name(field, inputs):
    with pytest.raises(ValueError, match=field.replace(".", r"\.").replace("[", r"\[")):
        agent_step(AgentState(), inputs, PARAMS)


def test_bad_params_are_rejected():
    with pytest.raises(ValueError, match="needs c"):
        GuidanceParams(300.0, law="fixed")
    with pytest.raises(ValueError, match="cruise"):
        VehicleEnvelope(30.0, 13.0, 25.0, 2.0, 0.2)
    with pytest.raises(ValueError, match="radius_m"):
        GuidanceParams(-1.0)


coords = st.floats(min_value=-3000.0, max_value=3000.0)


@settings(max_examples=300, deadline=None)
@given(
    coords,
    coords,
    st.floats(min_value=-math.pi, max_value=math.pi),
    st.floats(min_value=0.0, max_value=30.0),
    st.floats(min_value=-15.0, max_value=15.0),
    st.floats(min_value=-15.0, max_value=15.0),
    st.sampled_from(["proposed", "frew"]),
    st.sampled_from(["paper", "frew"]),
)
def test_commands_are_finite_and_within_the_envelope(e, n, course, speed, tve, tvn, law, plaw):
    params = AgentParams(
        1, ENV, GuidanceParams(300.0, law=law), PhaseParams(law=plaw, gain_per_s=0.3)
    )
    team = ((400.0, 0.0), (e, n), (-200.0, 100.0))
    inputs = _inputs(e, n, course, speed, target=TargetInfo(10.0, -5.0, tve, tvn), team=team)
    _, cmd, _ = agent_step(AgentState(), inputs, params)
    assert math.isfinite(cmd.course_rad)
    assert math.isfinite(cmd.course_rate_ff_rad_s)
    assert 13.0 <= cmd.speed_m_s <= 25.0
    implied = abs(math.remainder(cmd.course_rad - course, 2.0 * math.pi))
    assert implied * ENV.course_gain_per_s <= ENV.max_course_rate_rad_s + 1e-9


def test_phase_keeping_speeds_up_the_vehicle_behind_its_seat():
    params = [
        AgentParams(i, ENV, GuidanceParams(400.0), PhaseParams("paper", 0.05)) for i in range(3)
    ]
    # on the circle at 0, 30 and 50 deg: vehicle 2 must move up, vehicle 0 drop back
    pos = [(400 * math.cos(math.radians(a)), 400 * math.sin(math.radians(a))) for a in (0, 30, 50)]
    team = tuple(pos)
    speeds = []
    for i, (e, n) in enumerate(pos):
        course = -math.atan2(n, e)
        _, cmd, _ = agent_step(AgentState(), _inputs(e, n, course, 20.0, team=team), params[i])
        speeds.append(cmd.speed_m_s)
    assert speeds[0] < 20.0 < speeds[2]
    assert speeds[1] == pytest.approx(20.0 - 0.05 * math.radians(3.333) * 400.0, abs=0.01)


def test_a_lead_speed_flies_the_vehicle_furthest_behind_at_it_and_the_rest_slower() -> None:
    """With ``lead_speed_m_s`` the law's speeds are shifted so that the largest error (the
    vehicle furthest behind its seat) flies the lead speed; the gaps close at the same rate as
    about cruise, and a spaced team flies the lead speed."""
    pos = [(400 * math.cos(math.radians(a)), 400 * math.sin(math.radians(a))) for a in (0, 30, 50)]

    def speeds(phase: PhaseParams, angles: list[tuple[float, float]]) -> list[float]:
        out = []
        for i, (e, n) in enumerate(angles):
            params = AgentParams(i, ENV, GuidanceParams(400.0), phase)
            inputs = _inputs(e, n, -math.atan2(n, e), 20.0, team=tuple(angles))
            out.append(agent_step(AgentState(), inputs, params)[1].speed_m_s)
        return out

    about_cruise = speeds(PhaseParams("paper", 0.005), pos)
    led = speeds(PhaseParams("paper", 0.005, lead_speed_m_s=24.0), pos)
    assert led[2] == pytest.approx(24.0)  # vehicle 2 is furthest behind its seat
    assert led[0] < led[1] < 24.0
    # the differences between the vehicles are the law's, only shifted
    for a, b in ((0, 1), (1, 2)):
        assert led[b] - led[a] == pytest.approx(about_cruise[b] - about_cruise[a], abs=1e-9)
    spaced = [
        (400 * math.cos(math.radians(a)), 400 * math.sin(math.radians(a))) for a in (0, 120, 240)
    ]
    assert speeds(PhaseParams("paper", 0.005, lead_speed_m_s=24.0), spaced) == pytest.approx(
        [24.0] * 3
    )
    # the radius actuator holds its speed: no lead
    radius = PhaseParams("paper", 0.005, actuator="radius", lead_speed_m_s=24.0)
    assert speeds(radius, pos) == [20.0, 20.0, 20.0]
    with pytest.raises(ValueError, match="lead_speed_m_s"):
        PhaseParams("paper", lead_speed_m_s=math.nan)


def _leader_speed(
    rd: float, lead: float, radius_m: float, held: bool = False, share: float = 1.0
) -> float:
    """The speed commanded to vehicle 2 of three on the circle ``rd`` (vehicles 0 and 1), the
    one furthest behind its seat, ``radius_m`` from the target."""
    angles = (0.0, 30.0, 50.0)  # vehicle 2 is furthest behind its seat
    team = tuple(
        (r * math.cos(math.radians(a)), r * math.sin(math.radians(a)))
        for r, a in zip((rd, rd, radius_m), angles, strict=True)
    )
    phase = PhaseParams(
        "paper",
        0.005,
        lead_speed_m_s=lead,
        lead_held_outside=held,
        held_lead_turn_share=share,
    )
    params = AgentParams(2, ENV, GuidanceParams(rd), phase)
    e, n = team[2]
    inputs = _inputs(e, n, -math.atan2(n, e), 20.0, team=team)
    return agent_step(AgentState(), inputs, params)[1].speed_m_s


def test_a_held_lead_keeps_a_share_of_the_turn_rate_to_spare_on_the_circle() -> None:
    """Held (the mission's adjust stage), the lead is at most ``held_lead_turn_share`` of
    W r_d on, inside and outside the circle, and W r_d^2 / r further out where that is less;
    in gather (not held) the share does not apply."""
    rd, lead, share = 110.0, 0.2 * 110.0, 0.9
    cap = share * 0.2 * rd
    assert _leader_speed(rd, lead, rd, held=True, share=share) == pytest.approx(cap)
    assert _leader_speed(rd, lead, rd - 8.0, held=True, share=share) == pytest.approx(cap)
    assert _leader_speed(rd, lead, rd + 5.0, held=True, share=share) == pytest.approx(cap)
    assert _leader_speed(rd, lead, rd + 30.0, held=True, share=share) == pytest.approx(
        0.2 * rd * rd / (rd + 30.0)
    )
    assert _leader_speed(rd, lead, rd, share=share) == pytest.approx(lead)
    # a lead already below the share is flown as it is
    slow = 0.8 * 0.2 * rd
    assert _leader_speed(rd, slow, rd, held=True, share=share) == pytest.approx(slow)
    with pytest.raises(ValueError, match="held_lead_turn_share"):
        PhaseParams("paper", held_lead_turn_share=0.0)
    with pytest.raises(ValueError, match="held_lead_turn_share"):
        PhaseParams("paper", held_lead_turn_share=math.nan)


def test_a_leader_outside_the_circle_is_slowed_to_a_speed_that_turns_it_back_in() -> None:
    """At the lead speed W r_d the circle takes the whole turn-rate limit W; a leader blown
    outside it is held to W r_d^2 / r, whose full turn is tighter than the circle, and flies
    the lead speed again on or inside it."""
    rd, lead = 110.0, 0.2 * 110.0  # W r_d = 22 m/s

    def leader_speed(radius_m: float, held: bool = False) -> float:
        return _leader_speed(rd, lead, radius_m, held)

    assert leader_speed(rd) == pytest.approx(lead)
    assert leader_speed(rd - 8.0) == pytest.approx(lead)
    assert leader_speed(rd + 10.0) == pytest.approx(0.2 * rd * rd / (rd + 10.0))
    assert leader_speed(rd + 10.0) < lead - 1.5
    # fading back to the lead by 20 m out: a leader flying in from afar keeps it
    assert leader_speed(rd + 15.0) == pytest.approx(0.5 * (lead + 0.2 * rd * rd / (rd + 15.0)))
    assert leader_speed(rd + 20.0) == pytest.approx(lead)
    assert leader_speed(rd + 500.0) == pytest.approx(lead)
    # held outside (the mission's adjust stage): no fade, whatever the distance
    for out in (10.0, 15.0, 30.0, 60.0):
        assert leader_speed(rd + out, held=True) == pytest.approx(0.2 * rd * rd / (rd + out))
    assert leader_speed(rd, held=True) == pytest.approx(lead)
    assert leader_speed(rd - 8.0, held=True) == pytest.approx(lead)


def test_moving_target_speed_is_relative_to_the_target():
    target = TargetInfo(0.0, 0.0, 5.0, 0.0)
    _, cmd, _ = agent_step(AgentState(), _inputs(300.0, 0.0, 0.0, 20.0, target=target), PARAMS)
    # relative velocity due north (the tangent) at 20 m/s: v_g = (5, 20)
    assert cmd.speed_m_s == pytest.approx(math.hypot(5.0, 20.0))
    assert cmd.field_course_rad == pytest.approx(math.atan2(5.0, 20.0))
    ground = AgentParams(0, ENV, GuidanceParams(300.0, relative_speed=False))
    _, cmd, _ = agent_step(AgentState(), _inputs(300.0, 0.0, 0.0, 20.0, target=target), ground)
    assert cmd.speed_m_s == pytest.approx(20.0)
    assert cmd.field_course_rad == pytest.approx(math.atan2(5.0, math.sqrt(375.0)))


def test_a_vehicle_over_the_target_gets_a_finite_command():
    for law in ("proposed", "frew"):
        params = AgentParams(0, ENV, GuidanceParams(300.0, law=law))
        _, cmd, _ = agent_step(AgentState(), _inputs(0.0, 0.0, 1.0, 20.0), params)
        assert math.isfinite(cmd.course_rad)
        # the field is undefined there: the vehicle keeps its course and flies out
        assert cmd.field_course_rad == pytest.approx(1.0)
