"""The agent's mission logic, closed-loop on the eq. 2 fixed-wing, with no I/O."""

import math
from dataclasses import replace

import numpy as np
import pytest

from app.core.agent import AgentParams, GuidanceParams, OwnTelemetry, PhaseParams
from app.core.estimation.federated import MainParams
from app.core.estimation.imm import default_imm_params
from app.core.estimation.local import LocalParams
from app.core.estimation.messages import GlobalEstimate, Observation
from app.core.mission.agent import (
    MissionAgentParams,
    MissionAgentState,
    TeammateFix,
    control,
    hear_fused,
    hear_mission,
    hear_teammate,
    hear_teammates,
    initial_agent_state,
    observe,
    target_at,
)
from app.core.mission.stage import spacing_errors
from app.core.plant import FixedWingState, VehicleEnvelope, step

ENVELOPE = VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.2)


def params(vehicle: int, feedback: str = "none") -> MissionAgentParams:
    return MissionAgentParams(
        vehicle=vehicle,
        agent=AgentParams(
            0, ENVELOPE, GuidanceParams(radius_m=90.0), PhaseParams("paper", 0.1, predictive=True)
        ),
        standby=AgentParams(0, ENVELOPE, GuidanceParams(radius_m=150.0), PhaseParams("none")),
        standby_east_m=-1000.0,
        standby_north_m=0.0,
        local=LocalParams(imm=default_imm_params()),
        main=MainParams(feedback=feedback),  # type: ignore[arg-type]
    )


def own(s: FixedWingState) -> OwnTelemetry:
    return OwnTelemetry(s.east_m, s.north_m, s.course_rad, s.speed_m_s)


def fused_at(t_s: float, east: float, north: float) -> GlobalEstimate:
    return GlobalEstimate(
        t_s, np.array([east, 0.0, north, 0.0, 0.0, 0.0]), np.eye(6), (("0", 1.0),)
    )


def fly_team(starts, states, plist, seconds, dt=0.1, fused=None, t0=0.0):
    vehicles = list(starts)
    for k in range(int(seconds / dt)):
        t = t0 + k * dt
        for i, p in enumerate(plist):
            fix = TeammateFix(
                t,
                vehicles[i].east_m,
                vehicles[i].north_m,
                vehicles[i].course_rad,
                vehicles[i].speed_m_s,
            )
            states = [hear_teammate(s, p.vehicle, fix) for s in states]
        for i, p in enumerate(plist):
            if fused is not None:
                states[i] = hear_fused(states[i], fused(t), p)
            states[i], cmd, _ = control(states[i], t, own(vehicles[i]), p)
            assert math.isfinite(cmd.course_rad)
            assert ENVELOPE.min_speed_m_s <= cmd.speed_m_s <= ENVELOPE.max_speed_m_s
            vehicles[i] = step(vehicles[i], cmd.course_rad, cmd.speed_m_s, ENVELOPE, dt)
    return vehicles, states


def test_standby_loiters_around_the_standby_point():
    p = params(0)
    state = initial_agent_state(p)
    start = FixedWingState(-1400.0, 300.0, 0.5, 14.0)
    vehicles, _ = fly_team([start], [state], [p], 200.0)
    r = math.hypot(vehicles[0].east_m + 1000.0, vehicles[0].north_m)
    assert r == pytest.approx(150.0, abs=3.0)


def test_gather_flies_to_the_observed_target_and_orbits_it():
    p = params(0)
    state = hear_mission(initial_agent_state(p), "gather", (0,))
    for k in range(50):  # observations of a target standing at the origin
        state, report = observe(state, Observation(0.1 * k, "0", 0.5, -0.5, math.sqrt(10.0)), p)
        assert report.used
    start = FixedWingState(-1000.0, 150.0, 0.0, 14.0)
    fused = lambda t: fused_at(t, 0.0, 0.0)  # noqa: E731
    vehicles, _ = fly_team([start], [state], [p], 160.0, fused=fused)
    assert math.hypot(vehicles[0].east_m, vehicles[0].north_m) == pytest.approx(90.0, abs=3.0)


def team_setup(active):
    plist = [params(i) for i in range(3)]
    states = [hear_mission(initial_agent_state(p), "adjust", active) for p in plist]
    starts = [
        FixedWingState(90.0 * math.cos(a), 90.0 * math.sin(a), -a, 14.0) for a in (0.0, 0.4, 0.9)
    ]  # on the circle, counter-clockwise, bunched
    return plist, states, starts


def angles(vehicles, which):
    return [math.atan2(vehicles[i].north_m, vehicles[i].east_m) for i in which]


@pytest.mark.slow
def test_the_active_team_spaces_evenly_and_respaces_when_one_leaves():
    plist, states, starts = team_setup((0, 1, 2))
    fused = lambda t: fused_at(t, 0.0, 0.0)  # noqa: E731
    vehicles, states = fly_team(starts, states, plist, 150.0, fused=fused)
    errors = spacing_errors(angles(vehicles, (0, 1, 2)))
    assert max(abs(math.degrees(e)) for e in errors) < 2.0
    # vehicle 1 leaves the formation: the two others go to 180 degrees apart
    states = [hear_mission(s, "track", (0, 2)) for s in states]
    vehicles, states = fly_team(vehicles, states, plist, 150.0, fused=fused, t0=150.0)
    errors = spacing_errors(angles(vehicles, (0, 2)))
    assert max(abs(math.degrees(e)) for e in errors) < 2.0


def test_target_falls_back_to_the_local_estimate_and_expires():
    p = params(0)
    state = initial_agent_state(p)
    assert target_at(state, 0.0, p) is None
    state, _ = observe(state, Observation(1.0, "0", 10.0, 20.0), p)
    tgt = target_at(state, 1.5, p)
    assert tgt is not None
    assert (tgt.east_m, tgt.north_m) == pytest.approx((10.0, 20.0))
    assert target_at(state, 1.0 + p.max_age_s + 0.1, p) is None
    state = hear_fused(state, fused_at(2.0, 50.0, 60.0), p)
    tgt = target_at(state, 2.0, p)
    assert tgt is not None
    assert (tgt.east_m, tgt.north_m) == pytest.approx((50.0, 60.0))


def test_stale_messages_do_not_replace_newer_ones():
    p = params(0)
    state = hear_fused(initial_agent_state(p), fused_at(5.0, 1.0, 1.0), p)
    assert hear_fused(state, fused_at(4.0, 9.0, 9.0), p).fused is state.fused
    state = hear_teammate(state, 1, TeammateFix(5.0, 1.0, 2.0, 0.0, 14.0))
    older = hear_teammate(state, 1, TeammateFix(4.0, 7.0, 7.0, 0.0, 14.0))
    assert dict(older.teammates)[1].t_s == 5.0


def test_a_ticks_statuses_heard_at_once_leave_the_state_they_leave_heard_one_by_one():
    p = params(0)
    state = hear_mission(initial_agent_state(p), "gather", (0, 1, 2))
    state = replace(state, join_since_t_s=4.5)
    fixes = [
        (1, TeammateFix(4.0, 1.0, 2.0, 0.0, 14.0)),
        (2, TeammateFix(4.6, 3.0, 4.0, 0.1, 15.0)),
        (1, TeammateFix(5.0, 1.5, 2.0, 0.0, 14.0)),
        (2, TeammateFix(4.5, 9.0, 9.0, 0.0, 14.0)),  # older than the one held: not kept
        (1, TeammateFix(5.1, 2.0, 2.0, 0.0, 14.0)),
    ]
    one_by_one = state
    for vehicle, fix in fixes:
        one_by_one = hear_teammate(one_by_one, vehicle, fix)
    at_once = hear_teammates(state, fixes)
    assert at_once == one_by_one
    assert dict(at_once.teammates)[2].east_m == 3.0
    assert [(v, f.t_s) for v, f in at_once.join_fixes] == [(1, 5.0), (2, 4.6)]
    assert hear_teammates(state, []) is state


def test_feedback_moves_the_local_filter_onto_the_fused_estimate():
    p = params(0, feedback="mixture")
    state = initial_agent_state(p)
    for k in range(20):
        state, _ = observe(state, Observation(0.1 * k, "0", 0.0, 0.0, 3.0), p)
    fused = GlobalEstimate(
        1.9, np.array([2.0, 0.0, 1.0, 0.0, 0.0, 0.0]), np.eye(6) * 0.5, (("0", 0.5),)
    )
    state = hear_fused(state, fused, p)
    local = state.local.estimate()
    assert local is not None
    assert local.x[[0, 2]] == pytest.approx([2.0, 1.0])
    assert state.local.counters.feedback == 1


def test_a_vehicle_left_out_orbits_without_phase_keeping():
    plist, states, starts = team_setup((0, 2))
    for i, start in enumerate(starts):
        fix = TeammateFix(0.0, start.east_m, start.north_m, start.course_rad, start.speed_m_s)
        states = [hear_teammate(s, i, fix) for s in states]
    states = [hear_fused(s, fused_at(0.0, 0.0, 0.0), p) for s, p in zip(states, plist, strict=True)]
    _, left_out, _ = control(states[1], 0.0, own(starts[1]), plist[1])
    assert left_out.speed_m_s == ENVELOPE.cruise_speed_m_s
    # the same vehicle inside the team is asked to change speed to open the bunched spacing
    joined: MissionAgentState = hear_mission(states[1], "adjust", (0, 1, 2))
    _, member, _ = control(joined, 0.0, own(starts[1]), plist[1])
    assert abs(member.speed_m_s - ENVELOPE.cruise_speed_m_s) > 0.1


def _adjust_around_moving_target(moving_speed_m_s: float) -> float:
    """One vehicle that heard "adjust" but never "track", around a target driving north at
    7 m/s: its RMS distance error (m) over the last 60 s of 150."""
    base = params(0)
    track_guidance = GuidanceParams(
        radius_m=90.0, law="frew", inverse_field=False, orbit_plan="ellipse"
    )
    p = replace(
        base,
        track=replace(base.agent, guidance=track_guidance),
        moving_speed_m_s=moving_speed_m_s,
    )
    state = hear_mission(initial_agent_state(p), "adjust", (0,))
    vehicle = FixedWingState(0.0, -90.0, math.pi / 2, 14.0)
    errors = []
    for k in range(1500):
        t = k * 0.1
        fused = GlobalEstimate(
            t, np.array([0.0, 0.0, 7.0 * t, 7.0, 0.0, 0.0]), np.eye(6), (("0", 1.0),)
        )
        state = hear_fused(state, fused, p)
        state, cmd, _ = control(state, t, own(vehicle), p)
        assert math.isfinite(cmd.course_rad)
        vehicle = step(vehicle, cmd.course_rad, cmd.speed_m_s, ENVELOPE, 0.1)
        if t >= 90.0:
            errors.append(math.hypot(vehicle.east_m, vehicle.north_m - 7.0 * (t + 0.1)) - 90.0)
    return float(np.sqrt(np.mean(np.square(errors))))


@pytest.mark.slow
def test_an_agent_that_missed_track_flies_the_track_guidance_around_a_moving_target():
    # the ground starts tracking once the target moves faster than moving_speed_m_s; an agent
    # that never heard it (cut off from the bus) applies the same rule itself
    with_rule = _adjust_around_moving_target(1.5)
    without = _adjust_around_moving_target(math.inf)
    assert with_rule < 25.0
    assert without > 2.0 * with_rule


def test_moving_speed_must_be_a_non_negative_number():
    with pytest.raises(ValueError, match="moving_speed_m_s"):
        replace(params(0), moving_speed_m_s=math.nan)
    with pytest.raises(ValueError, match="moving_speed_m_s"):
        replace(params(0), moving_speed_m_s=-1.0)


def _lead_speed_in(stage: str, phase: PhaseParams, vehicle_0: FixedWingState) -> float:
    """The speed commanded to vehicle 0 (furthest behind its seat, at ``vehicle_0``) in
    ``stage``, its teammates on the 90 m circle at 150 and 270 degrees."""
    base = params(0)
    p = replace(base, agent=replace(base.agent, phase=phase))
    state = hear_mission(initial_agent_state(p), stage, (0, 1, 2))
    state = hear_fused(state, fused_at(0.0, 0.0, 0.0), p)
    for vehicle, deg in ((1, 150.0), (2, 270.0)):
        a = math.radians(deg)
        fix = TeammateFix(0.0, 90.0 * math.cos(a), 90.0 * math.sin(a), -a, 14.0)
        state = hear_teammate(state, vehicle, fix)
    _, cmd, _ = control(state, 0.0, own(vehicle_0), p)
    return cmd.speed_m_s


def test_in_adjust_a_leader_blown_far_outside_is_held_to_a_speed_that_turns_it_back():
    # The lead speed 18 m/s is W r_d: the 90 m circle takes the whole turn there. 40 m outside,
    # beyond the lead's 20 m band, gather keeps the lead (a leader still flying in from afar);
    # adjust, with the team gathered, holds it to W r_d^2 / r so that it can turn back in.
    lead, r = 18.0, 130.0
    phase = PhaseParams("paper", 0.1, lead_speed_m_s=lead)
    outside = FixedWingState(r, 0.0, 0.0, lead)
    held = 0.2 * 90.0 * 90.0 / r
    assert _lead_speed_in("adjust", phase, outside) <= held + 1e-9
    assert _lead_speed_in("gather", phase, outside) > held + 2.0


def test_in_adjust_the_lead_on_the_circle_keeps_a_share_of_the_turn_rate_to_spare():
    # On the circle, gather flies the 18 m/s lead (W r_d: the whole turn); adjust, with the
    # team gathered, at most 0.9 of it, the mission's adjust_lead_turn_share.
    lead, share = 18.0, 0.9
    phase = PhaseParams("paper", 0.1, lead_speed_m_s=lead, held_lead_turn_share=share)
    on_circle = FixedWingState(90.0, 0.0, math.pi / 2, lead)
    assert _lead_speed_in("gather", phase, on_circle) == pytest.approx(lead)
    assert _lead_speed_in("adjust", phase, on_circle) == pytest.approx(share * 0.2 * 90.0)
