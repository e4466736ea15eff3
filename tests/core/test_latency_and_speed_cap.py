"""Latency compensation (``agent.predict_own``, ``MissionAgentParams.latency_s``) and the flyable
speed along an orbit around a moving target (``guidance.orbit_plan.orbit_speed_profile`` and
``orbit_speed_cap``)."""

import functools
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.compose.mission_fastsim import MissionSimSetup, run_mission_sim, track_figures
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.core.agent import (
    AgentInputs,
    AgentParams,
    AgentState,
    GuidanceParams,
    OwnTelemetry,
    PhaseParams,
    TargetInfo,
    agent_step,
    predict_own,
)
from app.core.guidance import orbit_plan
from app.core.plant import FixedWingState, VehicleEnvelope, step

ENV = VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.2)


# --- predict_own: the eq. (2) vehicle ahead of time ---------------------------------------------


@settings(max_examples=60, deadline=None)
@given(
    course=st.floats(-math.pi, math.pi),
    course_cmd=st.floats(-math.pi, math.pi),
    speed=st.floats(10.0, 18.0),
    speed_cmd=st.floats(5.0, 25.0),
)
def test_prediction_is_where_the_simulated_vehicle_goes(
    course: float, course_cmd: float, speed: float, speed_cmd: float
) -> None:
    """One prediction of 0.1 s against the simulator's own fixed-wing in 5 steps of 0.02 s."""
    state = FixedWingState(100.0, -50.0, course, speed)
    for _ in range(5):
        state = step(state, course_cmd, speed_cmd, ENV, 0.02)
    got = predict_own(OwnTelemetry(100.0, -50.0, course, speed), course_cmd, speed_cmd, ENV, 0.1)
    # the simulator re-evaluates the saturating course loop every step; the prediction holds
    # its first rate: within a few cm and a small fraction of a degree over 0.1 s
    assert math.hypot(got.east_m - state.east_m, got.north_m - state.north_m) < 0.05
    assert abs(math.remainder(got.course_rad - state.course_rad, math.tau)) < 0.01
    assert got.speed_m_s == pytest.approx(state.speed_m_s, abs=0.05)


def test_prediction_of_zero_time_is_the_telemetry_itself() -> None:
    own = OwnTelemetry(1.0, 2.0, 0.3, 14.0)
    assert predict_own(own, 2.0, 18.0, ENV, 0.0) is own
    with pytest.raises(ValueError, match="dt_s"):
        predict_own(own, 2.0, 18.0, ENV, math.nan)


@functools.cache
def _fly(
    latency_ticks: int, latency_s: float, hold_s: float, identify: bool = False
) -> tuple[float, np.ndarray]:
    """The mission fast-sim to a minute into the 7 m/s leg: its RMS distance error there and
    every command (t, vehicle, course, speed, implied course rate when it acts). Cached: the
    run without delay or compensation serves two tests. ``identify``: the agents' course-loop
    identifier (which also learns the delay) on, as the mission files have it by default; off,
    only the configured latency is compensated. The team gathers at one point, as when these
    figures were set: a seat each brings it to A elsewhere on its orbit, and the first minute of
    A-B is a different transient (without latency 22.1 against 27.0 m with a tick of it)."""
    plan = build_plan(load_config("hil", MissionConfig))
    agents = tuple(
        replace(
            a,
            latency_s=latency_s,
            hold_s=hold_s,
            course_id=a.course_id if identify else None,
            gather_join="point",
        )
        for a in plan.agents
    )
    setup = MissionSimSetup(
        replace(plan, agents=agents),
        seed=1,
        latency_ticks=latency_ticks,
        end_t_s=plan.config.tracking_command_s + 180.0,
    )
    result = run_mission_sim(setup)
    return track_figures(result, plan.target.labels)["A-B"]["dist_rms_m"], result.commands


def _within_limits(commands: np.ndarray, lead_s: float) -> None:
    """Finite, speeds within the envelope, and course rates within the limit of the course the
    vehicle has ``lead_s`` after a command starts to act (at its start: W (1 + k lead_s)),
    up to the prediction's error (the eq. 2 model holds the rate it starts with)."""
    assert np.isfinite(commands).all()
    w, k = ENV.max_course_rate_rad_s, ENV.course_gain_per_s
    assert np.abs(commands[:, 4]).max() <= w * (1.0 + k * lead_s) * 1.005
    assert commands[:, 3].min() >= ENV.min_speed_m_s
    assert commands[:, 3].max() <= ENV.max_speed_m_s


@pytest.mark.slow
def test_latency_compensation_recovers_the_figures_a_delay_costs() -> None:
    """Commands acting one 0.1 s tick late (and held for the next): without compensation the
    team flies the first minute of the 7 m/s leg clearly worse than with no delay; steering on
    the state predicted for the middle of the hold brings it back (the full comparison:
    benchmarks.bench_track)."""
    ideal, _ = _fly(0, 0.0, 0.0)
    late, _ = _fly(1, 0.0, 0.0)
    compensated, commands = _fly(1, 0.1, 0.1)
    assert late > 1.3 * ideal
    assert compensated < 1.1 * ideal
    _within_limits(commands, 0.05)


@pytest.mark.slow
def test_the_course_loop_identifier_learns_a_delay_nobody_configured() -> None:
    """The same one-tick delay with no latency configured: the agents' identifier finds the
    delay from their own telemetry and steers for it, recovering most of what it cost."""
    ideal, _ = _fly(0, 0.0, 0.0)
    late, _ = _fly(1, 0.0, 0.0)
    learnt, commands = _fly(1, 0.0, 0.0, identify=True)
    assert learnt < ideal + 0.5 * (late - ideal)
    _within_limits(commands, 0.15)


@pytest.mark.slow
def test_compensating_the_hold_alone_tracks_better_within_the_limits() -> None:
    """With no transport delay a command still acts over a 0.1 s hold; steering for its middle
    keeps the vehicle at the limit through the hold, and tracks the 7 m/s target better."""
    rms, commands = _fly(0, 0.0, 0.1)
    _within_limits(commands, 0.05)
    assert np.abs(commands[:, 4]).max() > ENV.max_course_rate_rad_s  # it does lead the start
    assert rms < 0.95 * _fly(0, 0.0, 0.0)[0]


# --- the flyable speed along an orbit -------------------------------------------------------------


def test_a_still_target_leaves_the_whole_speed_range() -> None:
    assert set(orbit_plan.orbit_speed_profile(90.0, 90.0, 0.0, 10.0, 18.0, 0.2)) == {18.0}


def test_against_a_3_m_s_target_the_speed_is_capped_at_the_closed_form() -> None:
    """Flying against a target at v_t on the circle r_d at ground speed g, the relative speed is
    g + v_t and the course turns at (g + v_t)^2 / (r_d g): within W up to the larger root of
    g^2 + (2 v_t - W r_d) g + v_t^2 = 0, 11.196 m/s for 3 m/s, r_d = 90 m, W = 0.2 rad/s."""
    profile = orbit_plan.orbit_speed_profile(90.0, 90.0, 3.0, 10.0, 18.0, 0.2)
    p = 2 * 3.0 - 0.2 * 90.0
    root = (-p + math.sqrt(p * p - 4 * 9.0)) / 2
    # s = pi/2: the point across the motion on the left, where a ccw orbit flies against it
    upwind = profile[len(profile) // 4]
    assert upwind == pytest.approx(root, abs=orbit_plan.PROFILE_SPEED_STEP_M_S)
    assert upwind <= root
    # flying with the target the whole range is flyable
    assert profile[3 * len(profile) // 4] == 18.0


def test_an_orbit_beyond_the_turn_rate_at_any_speed_gets_the_minimum_speed() -> None:
    profile = orbit_plan.orbit_speed_profile(90.0, 90.0, 7.0, 10.0, 18.0, 0.2)
    assert min(profile) == 10.0


def test_the_cap_brakes_ahead_of_the_slow_part_and_mirrors_for_clockwise() -> None:
    profile = orbit_plan.orbit_speed_profile(90.0, 90.0, 3.0, 10.0, 18.0, 0.2)
    brake = 0.3  # m/s^2

    def cap(x: float, y: float, sign: int = 1) -> float:
        # target moving east at 3 m/s; relative speed 14 m/s
        orbit = orbit_plan.PlannedOrbit(90.0, 90.0, 1.0, 0.0)
        return orbit_plan.orbit_speed_cap(x, y, 14.0, sign, orbit, profile, brake)

    # counter-clockwise: the north side flies against the target; the east side reaches it a
    # quarter orbit later (141 m at 14 m/s: 10.1 s), the south side half an orbit later
    north, east, south = cap(0.0, 90.0), cap(90.0, 0.0), cap(0.0, -90.0)
    assert north <= 11.2
    assert north < east < south
    quarter_s = 0.5 * math.pi * 90.0 / 14.0
    assert east == pytest.approx(north + brake * quarter_s, abs=0.3)
    # clockwise: the mirror image (the south side is now the one flown against the target)
    assert cap(0.0, -90.0, -1) == pytest.approx(north)
    assert cap(90.0, 0.0, -1) == pytest.approx(east, abs=0.3)


def test_agent_step_caps_the_speed_only_with_speed_cap() -> None:
    track = GuidanceParams(radius_m=90.0, law="frew", inverse_field=False)
    capped = replace(track, speed_cap=True)
    inputs = AgentInputs(
        t_s=0.0,
        own=OwnTelemetry(0.0, 90.0, 1.5 * math.pi, 16.0),  # north side, flying west
        target=TargetInfo(0.0, 0.0, 3.0, 0.0),  # moving east: the vehicle flies against it
        team_positions=((0.0, 90.0), (0.0, -90.0)),
    )
    phase = PhaseParams("paper", 0.5)
    # the phase law wants the top speed (the teammate is right opposite: the vehicle is far behind
    # its seat with a high gain); the cap holds it to what the circle allows there
    _, free, _ = agent_step(AgentState(), inputs, AgentParams(0, ENV, track, phase))
    _, held, _ = agent_step(AgentState(), inputs, AgentParams(0, ENV, capped, phase))
    assert held.speed_m_s <= 11.2 + 1e-9
    assert free.speed_m_s > held.speed_m_s


def test_speed_cap_parameters_are_checked() -> None:
    with pytest.raises(ValueError, match="speed_cap_margin"):
        GuidanceParams(radius_m=90.0, speed_cap_margin=0.0)
    with pytest.raises(ValueError, match="speed_cap_brake"):
        GuidanceParams(radius_m=90.0, speed_cap_brake=math.inf)


# --- turn_slow_rad: a long turn flown slow -------------------------------------------------------


def _turning(course_deg: float, target: TargetInfo) -> AgentInputs:
    # 40 m outside the circle on its north side, the teammate a quarter turn ahead of its seat
    # (the phase law wants the top speed)
    return AgentInputs(
        t_s=0.0,
        own=OwnTelemetry(0.0, 130.0, math.radians(course_deg), 17.0),
        target=target,
        team_positions=((0.0, 130.0), (90.0, 0.0)),
    )


@pytest.mark.parametrize("target", [TargetInfo(0.0, 0.0), TargetInfo(0.0, 0.0, 3.0, 0.0)])
def test_turn_slow_caps_the_speed_on_a_ramp_of_the_course_error(target: TargetInfo) -> None:
    track = GuidanceParams(radius_m=90.0, law="frew", inverse_field=False)
    slow = replace(track, turn_slow_rad=(math.radians(20.0), math.radians(40.0)))
    phase = PhaseParams("paper", 0.5)
    free_params, slow_params = AgentParams(0, ENV, track, phase), AgentParams(0, ENV, slow, phase)
    _, aligned, _ = agent_step(AgentState(), _turning(0.0, target), free_params)
    wanted = math.degrees(aligned.field_course_rad)
    assert aligned.speed_m_s > 15.0  # the law's speed, well above the minimum
    for error_deg, most in ((5.0, None), (30.0, 14.0 + 1e-6), (60.0, 10.0 + 1e-9)):
        inputs = _turning(wanted - error_deg, target)
        _, free, _ = agent_step(AgentState(), inputs, free_params)
        _, held, _ = agent_step(AgentState(), inputs, slow_params)
        assert math.isfinite(held.speed_m_s)
        assert math.isfinite(held.course_rad)
        assert ENV.min_speed_m_s <= held.speed_m_s <= ENV.max_speed_m_s
        if most is None:
            assert held == free  # below the ramp's start nothing changes
        else:
            assert held.speed_m_s <= most < free.speed_m_s


def test_turn_slow_parameters_are_checked() -> None:
    for bad in ((0.5, 0.5), (-0.1, 0.5), (0.2, 4.0), (0.1, math.nan)):
        with pytest.raises(ValueError, match="turn_slow_rad"):
            GuidanceParams(radius_m=90.0, turn_slow_rad=bad)


@pytest.mark.slow
def test_a_long_turn_flown_slow_keeps_the_team_closer_after_the_target_turns() -> None:
    """The ardupilot-sitl mission's B corner (a 7 m/s target stopping north and going east at
    3 m/s) flings the vehicle on the team's far side outward; flown at the phase law's speed
    its turn back at the rate limit is a circle of v / rate. The default track stage caps the
    speed in such a turn (``[guidance] track_turn_slow_deg``); without it the team flies B-C
    clearly worse (fast simulation, the mission file's own timing)."""
    plan = build_plan(load_config("ardupilot-sitl", MissionConfig))
    track = plan.agents[0].track
    assert track is not None
    assert track.guidance.turn_slow_rad is not None  # on by default
    off = replace(
        plan,
        agents=tuple(
            replace(
                a, track=replace(a.track, guidance=replace(a.track.guidance, turn_slow_rad=None))
            )
            for a in plan.agents
            if a.track is not None
        ),
    )
    figures = {}
    for name, p in (("slow", plan), ("off", off)):
        result = run_mission_sim(MissionSimSetup(p, seed=1, latency_ticks=1))
        assert np.isfinite(result.commands).all()
        figures[name] = track_figures(result, p.target.labels)["B-C"]
    slow, free = figures["slow"], figures["off"]
    assert slow["dist_rms_m"] < 0.85 * free["dist_rms_m"]
    assert slow["dist_max_m"] < free["dist_max_m"] - 5.0
    assert slow["spacing_rms_deg"] < 1.1 * free["spacing_rms_deg"]
