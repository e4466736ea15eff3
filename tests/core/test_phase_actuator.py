"""Phase keeping by orbit radius (``PhaseParams.actuator = "radius"``): the mapping from the
speed law's wanted speed to an effective radius, its clamps and filter, and the command."""

import math
from dataclasses import replace

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
    effective_radius,
    radius_bounds,
    resolve_actuator,
    with_phase_actuator,
)
from app.core.frames import wrap_pi
from app.core.guidance.field import optimal_c
from app.core.plant import VehicleEnvelope

# the default mission's vehicle (configs/hil.toml): 14 m/s cruise in [10, 18], 0.2 rad/s
ENV = VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.2, 1.0)
RD = 90.0
RADIUS = PhaseParams("paper", 0.1, actuator="radius", radius_band_m=15.0)


def _params(index=0, phase=RADIUS, **guidance):
    return AgentParams(index, ENV, GuidanceParams(RD, **guidance), phase)


def _on_circle(deg, r=RD, speed=14.0):
    a = math.radians(deg)
    return OwnTelemetry(r * math.cos(a), r * math.sin(a), -a, speed)


def _team(*degs, r=RD):
    return tuple((r * math.cos(math.radians(d)), r * math.sin(math.radians(d))) for d in degs)


# ---------------------------------------------------------------- the mapping and its clamps


def test_cruise_maps_to_r_d_and_the_wanted_speed_to_the_same_phase_rate():
    p = _params()
    assert effective_radius(14.0, p, 14.0) == RD
    # faster: a tighter circle; at cruise speed its phase rate is the wanted v_w / r_d
    r = effective_radius(15.0, p, 14.0)
    assert r == pytest.approx(RD * 14.0 / 15.0)
    assert 14.0 / r == pytest.approx(15.0 / RD)
    assert effective_radius(13.0, p, 14.0) == pytest.approx(RD * 14.0 / 13.0)


def test_the_radius_stays_within_the_band():
    p = _params()
    assert effective_radius(18.0, p, 14.0) == RD - 15.0  # 70 m wanted
    assert effective_radius(10.0, p, 14.0) == RD + 15.0  # 126 m wanted
    with pytest.raises(ValueError, match="wanted speed"):
        effective_radius(0.0, p, 14.0)
    with pytest.raises(ValueError, match="wanted speed"):
        effective_radius(math.nan, p, 14.0)


def test_the_lower_edge_keeps_the_circle_within_the_course_rate_limit():
    wide = replace(RADIUS, radius_band_m=40.0)
    # 1.05 turn radii at 14 m/s and 0.2 rad/s: 73.5 m, above r_d - 40
    assert radius_bounds(_params(phase=wide), 14.0) == pytest.approx((73.5, 130.0))
    # at the margin the optimal c uses, and at a higher speed (rounded up to the c step)
    lower, _ = radius_bounds(_params(phase=wide, curvature_margin=0.9), 14.0)
    assert lower == pytest.approx(1.05 * 14.0 / 0.18)
    lower, _ = radius_bounds(_params(phase=wide), 16.04)
    assert lower == pytest.approx(1.05 * 16.1 / 0.2)
    for speed in (10.0, 14.0, 16.0, 18.0):
        lower, _ = radius_bounds(_params(phase=wide), speed)
        assert max(speed, 14.0) / lower <= 0.2
        r = effective_radius(18.0, _params(phase=wide), speed)
        assert max(speed, 14.0) / r <= 0.2


def test_a_circle_that_is_already_tight_is_never_tightened():
    tight = AgentParams(0, ENV, GuidanceParams(60.0), replace(RADIUS, radius_band_m=10.0))
    lower, upper = radius_bounds(tight, 14.0)
    assert (lower, upper) == (60.0, 70.0)
    assert effective_radius(18.0, tight, 14.0) == 60.0


def test_phase_params_are_validated():
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="radius_band_m"):
            PhaseParams(actuator="radius", radius_band_m=bad)
    with pytest.raises(ValueError, match="actuator"):
        PhaseParams(actuator="throttle")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="radius_rate_m_s"):
        PhaseParams(radius_rate_m_s=0.0)
    with pytest.raises(ValueError, match="smaller than the standoff radius"):
        _params(phase=replace(RADIUS, radius_band_m=90.0))
    # the band matters only to the radius actuator
    _params(phase=PhaseParams(radius_band_m=200.0))


def test_auto_resolves_from_what_the_vehicle_honours():
    assert resolve_actuator("auto", honours_speed=True) == "speed"
    assert resolve_actuator("auto", honours_speed=False) == "radius"
    assert resolve_actuator("speed", honours_speed=False) == "speed"
    assert resolve_actuator("radius", honours_speed=True) == "radius"
    with pytest.raises(ValueError, match=r"auto\|speed\|radius"):
        resolve_actuator("fast", True)  # type: ignore[arg-type]
    speed = _params(phase=replace(RADIUS, actuator="speed"))
    assert with_phase_actuator(speed, "speed") is speed
    assert with_phase_actuator(speed, "radius").phase == RADIUS


# ---------------------------------------------------------------- the step


ORIGIN = TargetInfo(0.0, 0.0)


def _step(state, own, team, params=None, t=0.0, target=ORIGIN):
    params = params or _params()
    return agent_step(state, AgentInputs(t, own, target, team), params)


def test_the_speed_actuator_states_r_d_and_is_unchanged():
    speed = _params(phase=replace(RADIUS, actuator="speed"))
    own = _on_circle(0.0)
    _, cmd, _ = _step(AgentState(), own, _team(0.0, 15.0, 30.0), speed)
    assert cmd.actuator == "speed"
    assert cmd.radius_m == RD
    assert cmd.speed_m_s < 14.0  # vehicle 0 is ahead of its seat: it slows


def test_bunched_team_keeps_cruise_and_moves_the_radius_at_the_stated_rate():
    team = _team(0.0, 15.0, 30.0)
    params = [_params(i) for i in range(3)]
    owns = [_on_circle(d) for d in (0.0, 15.0, 30.0)]
    states = [AgentState()] * 3
    radii: list[list[float]] = [[], [], []]
    for tick in range(301):
        t = 0.1 * tick
        for i in range(3):
            prev = states[i].radius_m
            states[i], cmd, _ = _step(states[i], owns[i], team, params[i], t)
            assert cmd.actuator == "radius"
            assert cmd.speed_m_s == 14.0
            if tick > 0:
                assert abs(states[i].radius_m - prev) <= 0.1 + 1e-9
            else:
                assert states[i].radius_m == RD  # starts on r_d, no jump
            assert abs(cmd.radius_m - states[i].radius_m) <= 0.25 + 1e-9
            radii[i].append(cmd.radius_m)
    # seat law: vehicle 0 (105 deg ahead of its seat) widens to slow, vehicle 2 tightens,
    # vehicle 1 (on its seat) stays; both moved 1 m/s for 30 s, up to the 15 m band
    assert radii[0][-1] == RD + 15.0
    assert radii[2][-1] == RD - 15.0
    assert radii[1][-1] == RD
    assert radii[0][100] == pytest.approx(RD + 10.0, abs=0.5)


def test_c_is_solved_for_the_radius_flown_and_only_when_it_moves_a_step():
    team = _team(0.0, 15.0, 30.0)
    own = _on_circle(30.0)
    params = _params(2)
    state = AgentState()
    solved = 0
    last_radius = None
    for tick in range(60):
        before = state
        state, cmd, _ = _step(state, own, team, params, 0.1 * tick)
        assert cmd.c == pytest.approx(optimal_c(cmd.radius_m, 14.0, 0.2), abs=1e-12)
        if cmd.radius_m != last_radius:
            solved += 1
        else:
            assert state.c == before.c
            assert state.c_radius_m == before.c_radius_m
        last_radius = cmd.radius_m
    # 6 s at 1 m/s: 6 m in 0.5 m steps (and the first)
    assert solved == 13


def test_a_spaced_team_flies_r_d():
    team = _team(0.0, 120.0, 240.0)
    state = AgentState()
    for tick in range(50):
        state, cmd, _ = _step(state, _on_circle(120.0), team, _params(1), 0.1 * tick)
    assert cmd.radius_m == RD
    assert state.radius_m == pytest.approx(RD, abs=1e-9)


def test_around_a_moving_target_the_ground_speed_stays_at_cruise():
    target = TargetInfo(0.0, 0.0, 3.0, 1.0, 0.2, -0.1)
    team = _team(0.0, 15.0, 30.0)
    state = AgentState()
    for tick in range(20):
        state, cmd, _ = _step(state, _on_circle(15.0), team, _params(1), 0.1 * tick, target)
        assert cmd.speed_m_s == pytest.approx(14.0)
        assert cmd.actuator == "radius"


def test_radius_with_the_ellipse_plan_and_frew_law_is_finite():
    target = TargetInfo(0.0, 0.0, 7.0, 0.0)
    team = _team(0.0, 15.0, 30.0)
    for law in ("frew", "fixed"):
        params = _params(1, orbit_plan="ellipse", law=law, c=0.8)
        state = AgentState()
        for tick in range(20):
            state, cmd, _ = _step(state, _on_circle(15.0), team, params, 0.1 * tick, target)
            assert math.isfinite(cmd.course_rad)
            assert math.isfinite(cmd.radius_m)


@settings(max_examples=150, deadline=None)
@given(
    e=st.floats(-600.0, 600.0),
    n=st.floats(-600.0, 600.0),
    course=st.floats(-math.pi, math.pi),
    speed=st.floats(10.0, 18.0),
    phases=st.lists(st.floats(0.0, 360.0), min_size=2, max_size=2),
    vt=st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)),
    start_radius=st.floats(60.0, 120.0),
    dt=st.floats(0.0, 2.0),
)
def test_the_command_is_finite_within_the_envelope_and_the_course_rate_limit(
    e, n, course, speed, phases, vt, start_radius, dt
):
    own = OwnTelemetry(e, n, course, speed)
    team = ((e, n), *_team(*phases))
    state = AgentState(radius_m=start_radius, radius_t_s=0.0)
    target = TargetInfo(0.0, 0.0, vt[0], vt[1])
    new, cmd, _ = _step(state, own, team, _params(0), dt, target)
    values = (cmd.course_rad, cmd.speed_m_s, cmd.field_course_rad, cmd.course_rate_ff_rad_s)
    assert all(math.isfinite(v) for v in (*values, cmd.radius_m, cmd.c))
    assert ENV.min_speed_m_s <= cmd.speed_m_s <= ENV.max_speed_m_s
    assert abs(wrap_pi(cmd.course_rad - course)) * ENV.course_gain_per_s <= 0.2 + 1e-9
    lower, upper = radius_bounds(_params(0), speed)
    assert lower <= cmd.radius_m <= upper
    assert max(speed, 14.0) / cmd.radius_m <= 0.2
    # the filtered radius moved at most 1 m/s (or was pulled into a band that moved)
    moved = abs(new.radius_m - state.radius_m)
    assert moved <= 1.0 * dt + 1e-9 or not (lower <= state.radius_m <= upper)


def _time_phase_spaced(eps: float) -> list[float]:
    """Polar angles (deg, counter-clockwise) whose orbit-time phases psi + eps cos psi are
    0, 120 and 240 deg (a target moving east at eps * cruise)."""
    out = []
    for k in range(3):
        phi = math.radians(120.0 * k)
        psi = phi
        for _ in range(60):
            psi = phi - eps * math.cos(psi)
        out.append(math.degrees(psi))
    return out


def test_around_a_moving_target_a_team_spaced_in_orbit_time_holds_r_d():
    # at a held ground speed the phase rate is uneven round the orbit: a team that keeps its
    # spacing in time (theta + v_t . r_hat / s) is the steady state, and needs no radius change
    target = TargetInfo(0.0, 0.0, 1.5, 0.0)
    degs = _time_phase_spaced(1.5 / 14.0)
    team = _team(*degs)
    even = _team(0.0, 120.0, 240.0)
    for i, deg in enumerate(degs):
        state = even_state = AgentState()
        for tick in range(30):
            t = 0.1 * tick
            state, cmd, _ = _step(state, _on_circle(deg), team, _params(i), t, target)
            even_state, even_cmd, _ = _step(
                even_state, _on_circle(120.0 * i), even, _params(i), t, target
            )
        assert cmd.radius_m == RD
        if i > 0:
            # spaced evenly in angle instead, the two not at the reference move off r_d
            assert abs(even_cmd.radius_m - RD) >= 2.0


POLAR = replace(RADIUS, radius_phase="polar")


@pytest.mark.parametrize(("deg", "inside"), [(0.0, True), (180.0, False)])
def test_polar_spacing_flies_inside_where_the_target_moves_with_the_orbit(deg, inside):
    """A team spaced evenly in angle around a target driving north at 1.5 m/s (ccw orbit): at
    0 deg (east of it) the orbit runs north with the target, the relative speed along it is
    s - 1.5, so the polar rate needs a tighter orbit, r_d (s - 1.5) / s = 80.4 m; at 180 deg it
    runs against it: r_d (s + 1.5) / s = 99.6 m. The orbit-time phase holds r_d there."""
    target = TargetInfo(0.0, 0.0, 0.0, 1.5)
    team = _team(deg, deg + 120.0, deg + 240.0)
    polar = timed = AgentState()
    for tick in range(300):  # 30 s: the slew (1 m/s + |v_t|) has long arrived
        t = 0.1 * tick
        polar, cmd, _ = _step(polar, _on_circle(deg), team, _params(0, POLAR), t, target)
        timed, timed_cmd, _ = _step(timed, _on_circle(deg), team, _params(0), t, target)
    expected = RD * (14.0 - 1.5) / 14.0 if inside else RD * (14.0 + 1.5) / 14.0
    lower, upper = radius_bounds(_params(0, POLAR), 14.0)
    assert cmd.radius_m == pytest.approx(min(max(expected, lower), upper), abs=0.5)
    assert (cmd.radius_m < RD) is inside
    assert timed_cmd.radius_m != pytest.approx(cmd.radius_m, abs=2.0)


def test_polar_spacing_around_a_parked_target_is_the_radius_law_itself():
    target = TargetInfo(0.0, 0.0)
    team = _team(0.0, 100.0, 250.0)
    a = b = AgentState()
    for tick in range(50):
        t = 0.1 * tick
        a, cmd_a, _ = _step(a, _on_circle(0.0), team, _params(0, POLAR), t, target)
        b, cmd_b, _ = _step(b, _on_circle(0.0), team, _params(0), t, target)
        assert cmd_a == cmd_b


def test_an_unknown_radius_phase_is_refused():
    with pytest.raises(ValueError, match="radius_phase"):
        replace(RADIUS, radius_phase="sideways")  # type: ignore[arg-type]
