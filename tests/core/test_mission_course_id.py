"""The mission agent flying the course loop it identified (``MissionAgentParams.course_id``):
a vehicle whose autopilot turns at k = 0.55 /s while guidance assumes 1 /s, closed-loop on the
eq. (2) fixed-wing of ``plant.step``."""

import math
from collections import deque
from dataclasses import replace

import pytest

from app.core.agent import AgentEvent, AgentParams, GuidanceParams, OwnTelemetry, PhaseParams
from app.core.estimation.imm import default_imm_params
from app.core.estimation.local import LocalParams
from app.core.guidance import course_id as cid
from app.core.mission import agent as logic
from app.core.plant import FixedWingState, VehicleEnvelope, step

ENVELOPE = VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.2)  # guidance assumes k = 1 /s
STANDBY = (-1000.0, 0.0)
RADIUS_M = 90.0  # 0.156 rad/s at 14 m/s: more than a 0.55 /s loop turns at the clamp W / 1


def _params(identify: bool, fly: bool = True, latency_s: float = 0.01) -> logic.MissionAgentParams:
    return logic.MissionAgentParams(
        vehicle=0,
        agent=AgentParams(0, ENVELOPE, GuidanceParams(radius_m=90.0), PhaseParams("none")),
        standby=AgentParams(0, ENVELOPE, GuidanceParams(radius_m=RADIUS_M), PhaseParams("none")),
        standby_east_m=STANDBY[0],
        standby_north_m=STANDBY[1],
        local=LocalParams(imm=default_imm_params()),
        latency_s=latency_s,
        hold_s=0.1,
        course_id=cid.params_for(ENVELOPE) if identify else None,
        fly_identified=fly,
    )


def _loiter(
    params: logic.MissionAgentParams,
    k_true: float,
    seconds: float,
    delay_ticks: int = 0,
    k_later: float | None = None,
) -> tuple[list[float], list[AgentEvent], logic.MissionAgentState, list[float]]:
    """The agent loitering around its standby point (no target yet) at 10 Hz, its commands
    reaching a vehicle of gain ``k_true`` (``k_later`` from half-time) ``delay_ticks`` ticks
    late; r - r_d every tick, the events, the final state and every course command."""
    state = logic.initial_agent_state(params)
    vehicle = FixedWingState(STANDBY[0] + 400.0, STANDBY[1] + 300.0, math.pi, 14.0)
    pending: deque[tuple[float, float]] = deque([(vehicle.course_rad, 14.0)] * delay_ticks)
    errors: list[float] = []
    events: list[AgentEvent] = []
    commands: list[float] = []
    ticks = round(seconds / 0.1)
    for i in range(ticks):
        t = i * 0.1
        own = OwnTelemetry(vehicle.east_m, vehicle.north_m, vehicle.course_rad, vehicle.speed_m_s)
        state, out = logic.step(state, logic.Control(t, own), params)
        assert out.command is not None
        events.extend(out.events)
        commands.append(out.command.course_rad)
        pending.append((out.command.course_rad, out.command.speed_m_s))
        course, speed = pending.popleft()
        k = k_true if k_later is None or i < ticks // 2 else k_later
        env = replace(ENVELOPE, course_gain_per_s=k)
        for _ in range(5):
            vehicle = step(vehicle, course, speed, env, 0.02)
        errors.append(
            math.hypot(vehicle.east_m - STANDBY[0], vehicle.north_m - STANDBY[1]) - RADIUS_M
        )
    return errors, events, state, commands


def _rms(values: list[float]) -> float:
    return math.sqrt(sum(v * v for v in values) / len(values))


def test_a_weak_course_loop_is_learned_and_the_orbit_closes_in() -> None:
    """k = 0.55 /s against the 1 /s assumed: flying the assumed k the lead is too small and the
    clamp W / k too tight, and the vehicle orbits well outside the circle; identified, it is
    learned within a minute and the vehicle holds the circle."""
    seconds = 240.0
    off, _, _, _ = _loiter(_params(False), 0.55, seconds)
    on, events, state, _ = _loiter(_params(True), 0.55, seconds)
    settled = slice(len(off) // 2, None)  # the second half: on the circle, or as close as it gets
    rms_off, rms_on = _rms(off[settled]), _rms(on[settled])
    assert rms_off > 20.0
    assert rms_on < 0.2 * rms_off
    assert rms_on < 3.0
    learned = [e for e in events if e.kind == "course_loop_identified"]
    assert len(learned) == 1  # once ready; k does not move materially after
    assert learned[0].t_s < 60.0
    assert "k = 0.55" in learned[0].detail
    assert "flown with k = 0.55" in learned[0].detail
    gain, delay = logic.identified_course_loop(state) or (math.nan, math.nan)
    assert gain == pytest.approx(0.55, rel=0.03)
    assert delay == 0.0


def test_identifying_a_loop_that_is_as_assumed_changes_nothing() -> None:
    """The built-in simulator's k is exactly the assumed 1 /s: the identifier finds it (within
    the 1 % of plant.step's Euler steps), reports it, and every command is the same as without
    identification."""
    _, _, _, off = _loiter(_params(False), 1.0, 120.0)
    _, events, state, on = _loiter(_params(True), 1.0, 120.0)
    assert on == off
    (learned,) = [e for e in events if e.kind == "course_loop_identified"]
    assert "flown as assumed" in learned.detail
    tuned = state.tuned
    assert tuned is not None
    assert tuned.flown is tuned.base
    assert tuned.gain_per_s == pytest.approx(1.0, rel=0.02)


def test_identified_but_not_flown_is_reported_only() -> None:
    _, _, _, off = _loiter(_params(False), 0.55, 120.0)
    _, events, state, on = _loiter(_params(True, fly=False), 0.55, 120.0)
    assert on == off
    (learned,) = [e for e in events if e.kind == "course_loop_identified"]
    assert "not flown" in learned.detail
    assert logic.identified_course_loop(state) is not None


def test_a_delay_is_learned_and_steered_ahead_of() -> None:
    """Commands acting three ticks (0.3 s) late on the weak loop: the delay is found and the
    latency compensation steers 0.3 s ahead (instead of the configured 0.01 s)."""
    on, events, state, _ = _loiter(_params(True), 0.55, 240.0, delay_ticks=3)
    assert state.tuned is not None
    assert state.tuned.delay_s == pytest.approx(0.3)
    assert state.tuned.flown.latency_s == pytest.approx(0.3)
    assert any("delay = 0.30 s" in e.detail for e in events)
    off, _, _, _ = _loiter(_params(False), 0.55, 240.0, delay_ticks=3)
    settled = slice(len(on) // 2, None)
    assert _rms(on[settled]) < 0.2 * _rms(off[settled])


def test_a_material_change_of_the_loop_is_learned_again_and_reported() -> None:
    """The autopilot's gain changes mid-flight (0.55 -> 0.9 /s, e.g. a parameter change): the
    forgetting identifier follows and a second event reports the new k."""
    _, events, state, _ = _loiter(_params(True), 0.55, 480.0, k_later=0.9)
    learned = [e for e in events if e.kind == "course_loop_identified"]
    assert len(learned) >= 2
    assert learned[-1].t_s > 240.0
    assert state.tuned is not None
    assert state.tuned.gain_per_s == pytest.approx(0.9, rel=0.06)


def test_the_report_says_how_far_the_identification_got() -> None:
    """The summary's ``course_loop``: None with identification off; after 5 s of flight not
    identified, with fewer informative seconds than needed; after the weak loop is learned,
    identified at the k and delay the agent flies, with the identifier's counts."""
    params = _params(True)
    assert logic.course_loop_report(logic.initial_agent_state(params), _params(False)) is None
    _, _, early, _ = _loiter(params, 0.55, 5.0)
    report = logic.course_loop_report(early, params)
    assert report is not None
    assert not report.identified
    assert report.gain_per_s is None
    assert report.delay_s is None
    assert report.fit_gain_per_s > 0.0
    assert report.informative_s < report.min_s == 10.0
    assert report.max_rel_se == 0.05
    _, _, learned, _ = _loiter(params, 0.55, 120.0)
    report = logic.course_loop_report(learned, params)
    assert report is not None
    assert report.identified
    assert (report.gain_per_s, report.delay_s) == pytest.approx(
        logic.identified_course_loop(learned), abs=1e-4
    )
    assert report.gain_per_s == pytest.approx(0.55, rel=0.03)
    assert report.fit_gain_per_s == pytest.approx(0.55, rel=0.03)
    assert report.informative_samples > 100
    assert report.rel_se is not None
    assert 0.0 <= report.rel_se <= report.max_rel_se
    assert report.informative_s >= report.min_s


def test_holding_feeds_no_command_to_the_identifier() -> None:
    params = _params(True)
    state = logic.set_holding(logic.initial_agent_state(params), True)
    own = OwnTelemetry(0.0, 0.0, 0.0, 14.0)
    for i in range(50):
        state, out = logic.step(state, logic.Control(i * 0.1, own), params)
        assert out.command is None
    assert state.course_id.commands == ()
    assert state.course_id.informative_count == 0


def test_course_id_change_is_validated() -> None:
    with pytest.raises(ValueError, match="course_id_change"):
        replace(_params(True), course_id_change=0.0)


@pytest.mark.slow
def test_the_hil_mission_on_a_weak_autopilot_flies_the_circle_once_identified() -> None:
    """The whole mission logic (``compose.mission_fastsim``: cameras, fusion, stages, three
    agents) on vehicles that turn at k = 0.55 /s while the plan assumes 1 /s. Flying the assumed
    k the team orbits far outside the circle and never arrives (it goes from gather to track
    only once the target has left); with identification every agent learns k in the first
    seconds and the team arrives, forms and tracks."""
    from app.compose.mission_fastsim import MissionSimSetup, run_mission_sim
    from app.config import load_config
    from app.config.mission import MissionConfig
    from app.config.plan import build_plan

    plan = build_plan(load_config("hil", MissionConfig))
    weak = replace(plan.config.limits.build(), course_gain_per_s=0.55)

    def fly(identify: bool) -> tuple[float, list[str], set[str]]:
        agents = tuple(
            replace(a, course_id=cid.params_for(a.agent.envelope) if identify else None)
            for a in plan.agents
        )
        setup = MissionSimSetup(replace(plan, agents=agents), end_t_s=200.0, vehicle_limits=weak)
        result = run_mission_sim(setup)
        errors = [
            e for s in result.samples if s.t_s >= 150.0 for e in s.distance_errors(90.0).values()
        ]
        learned = [d for _, kind, d in result.events if kind == "course_loop_identified"]
        return _rms(errors), learned, {s.stage for s in result.samples}

    rms_off, learned_off, stages_off = fly(False)
    rms_on, learned_on, stages_on = fly(True)
    assert learned_off == []
    assert len(learned_on) == 3
    assert all("flown with k = 0.55" in d for d in learned_on)
    assert "adjust" not in stages_off
    assert {"adjust", "track"} <= stages_on
    assert rms_off > 30.0
    assert rms_on < 0.25 * rms_off
