"""Single messages that once killed a process or pushed the mission (issue #14), against the
pure core: each is refused and counted, and the state goes on as if it had not come."""

import math
from dataclasses import replace

import numpy as np

from app.core.estimation.federated import MainParams
from app.core.estimation.imm import default_imm_params
from app.core.estimation.messages import GlobalEstimate, LocalEstimate, Observation
from app.core.mission import agent as agent_logic
from app.core.mission import ground as ground_logic
from app.core.mission.ground import GroundParams, HeardLocal, HeardStatuses, VehicleReport
from app.core.plant import FixedWingState
from tests.core.test_mission_agent import own, params

IMM = default_imm_params()
R = len(IMM.models)
GROUND = GroundParams(
    vehicles=(0, 1, 2), radius_m=90.0, tracking_command_t_s=5.0, main=MainParams(imm=IMM)
)


def report(t: float, vehicle: int) -> VehicleReport:
    a = math.radians(120.0 * vehicle)
    return VehicleReport(t, 90.0 * math.cos(a), 90.0 * math.sin(a), -a, 14.0)


def local(vehicle: int, t: float, east: float = 0.0, models: int = R) -> LocalEstimate:
    x = np.array([east, 0.0, 0.0, 0.0, 0.0, 0.0])
    return LocalEstimate(
        str(vehicle),
        t,
        x,
        np.eye(6) * 4.0,
        np.full(models, 1.0 / models),
        model_x=np.tile(x, (models, 1)),
        model_p=np.tile(np.eye(6) * 4.0, (models, 1, 1)),
    )


def ground_run(state, t0: float, t1: float, clock: bool = True):
    t = t0
    while t < t1 + 1e-9:
        heard = tuple((v, report(t, v)) for v in (0, 1, 2))
        state, _ = ground_logic.step(state, HeardStatuses(heard, t if clock else None), GROUND)
        for v in (0, 1, 2):
            state, _ = ground_logic.step(
                state, HeardLocal(local(v, t), t if clock else None), GROUND
            )
        t = round(t + 0.1, 6)
    return state


def test_a_status_far_ahead_neither_moves_mission_time_nor_ends_the_formation() -> None:
    for clock in (True, False):
        state = ground_run(ground_logic.initial_ground_state(), 0.0, 10.0, clock)
        assert state.active == (0, 1, 2)
        for t_s in (10_010.0, 1e308):
            forged = HeardStatuses(((0, report(t_s, 0)),), 10.0 if clock else None)
            state, out = ground_logic.step(state, forged, GROUND)
            assert out.refused
            assert state.mission_t_s == 10.0
        assert state.statuses_refused == 2
        state = ground_run(state, 10.1, 12.0, clock)  # no OverflowError in the coasting
        assert state.active == (0, 1, 2)
        assert state.report(0).t_s == 12.0


def test_mission_time_never_passes_the_stations_own_clock() -> None:
    state = ground_run(ground_logic.initial_ground_state(), 0.0, 2.0)
    ahead = HeardStatuses(((1, report(2.9, 1)),), 2.0)  # inside the window
    state, out = ground_logic.step(state, ahead, GROUND)
    assert not out.refused
    assert state.mission_t_s == 2.0


def test_a_one_model_local_estimate_is_refused_and_the_fusion_goes_on() -> None:
    state = ground_run(ground_logic.initial_ground_state(), 0.0, 2.0)
    state, out = ground_logic.step(state, HeardLocal(local(0, 2.05, models=1), 2.05), GROUND)
    assert out.refused
    assert state.locals_refused == 1
    state = ground_run(state, 2.1, 3.0)  # the IMM fusion runs (it raised on the shape before)
    assert state.fused is not None
    assert abs(state.fused.x[0]) < 1.0


def test_a_diverged_local_estimate_is_refused_and_the_others_are_still_taken() -> None:
    """An agent's track that ran away (seen in a run of twenty: its filter coasted to 1e36 m
    with a covariance to match, which the outlier gate let through, and the fused estimate
    went with it, after which every healthy agent's estimate was refused as an outlier)."""
    state = ground_run(ground_logic.initial_ground_state(), 0.0, 6.0)
    runaway = replace(local(0, 6.05), x=np.full(6, 1e36), p=np.eye(6) * 1e74)
    lost = replace(local(0, 6.06), p=np.eye(6) * 1e12)  # a sane state, no information
    for estimate in (runaway, lost):
        state, out = ground_logic.step(state, HeardLocal(estimate, estimate.t_s), GROUND)
        assert out.refused
    assert state.locals_refused == 2
    state = ground_run(state, 6.1, 8.0)
    assert state.fused is not None
    assert abs(state.fused.x[0]) < 1.0
    assert state.locals_refused == 2  # the healthy ones after it are taken


def test_a_local_estimate_500_m_off_is_an_outlier_and_does_not_move_the_fusion() -> None:
    state = ground_run(ground_logic.initial_ground_state(), 0.0, 6.0)
    for k in range(50):
        t = 6.0 + 0.02 * k
        state, out = ground_logic.step(state, HeardLocal(local(0, t, east=500.0), t), GROUND)
        assert out.refused
    state = ground_run(state, 7.0, 8.0)
    assert state.fused is not None
    assert abs(state.fused.x[0]) < 1.0
    assert state.locals_refused == 50


# --- the agent ------------------------------------------------------------------------------


def flying_agent(seconds: float = 5.0):
    p = params(0, feedback="modewise")
    state = agent_logic.initial_agent_state(p, 0.2, 0.1)
    state = agent_logic.hear_mission(state, "track", (0,))
    v = FixedWingState(90.0, 0.0, 0.0, 14.0)
    rng = np.random.default_rng(1)
    t = 0.0
    while t < seconds:
        obs = Observation(t, "0", float(rng.normal(0, 2)), float(rng.normal(0, 2)), 2.0)
        state, _ = agent_logic.step(state, agent_logic.Observed(obs), p)
        state, _ = agent_logic.step(state, agent_logic.Control(t, own(v)), p)
        t = round(t + 0.1, 6)
    return state, p, v, t


def test_a_fused_estimate_at_1e200_is_refused_and_the_command_stays_finite() -> None:
    state, p, v, t = flying_agent()
    bomb = GlobalEstimate(t, np.array([1e200, 0, 0, 0, 0, 0.0]), np.eye(6), (("0", 1.0),))
    state, out = agent_logic.step(state, agent_logic.HeardFused(bomb), p)
    assert "beyond" in out.refused
    state, out = agent_logic.step(state, agent_logic.Control(t, own(v)), p)
    assert out.command is not None
    assert all(math.isfinite(x) for x in (out.command.course_rad, out.command.speed_m_s))


def test_a_fused_estimate_500_m_off_the_agents_own_is_refused() -> None:
    state, p, _v, t = flying_agent()
    off = GlobalEstimate(t, np.array([500.0, 0, 0, 0, 0, 0.0]), np.eye(6), (("0", 1.0),))
    state2, out = agent_logic.step(state, agent_logic.HeardFused(off), p)
    assert "from the agent's own estimate" in out.refused
    assert state2.fused is state.fused
    near = GlobalEstimate(t, np.array([0.5, 0, 0.3, 0, 0, 0.0]), np.eye(6), (("0", 1.0),))
    state3, out = agent_logic.step(state, agent_logic.HeardFused(near), p)
    assert not out.refused
    assert state3.fused is near


def test_observations_stamped_ahead_are_refused_and_the_real_ones_still_used() -> None:
    state, p, _v, t = flying_agent()
    for t_s in (1e308, t + 1e5):
        state, out = agent_logic.step(
            state, agent_logic.Observed(Observation(t_s, "0", 0.0, 0.0, 2.0)), p
        )
        assert out.report is not None
        assert out.report.outcome == "invalid"
    state, out = agent_logic.step(
        state, agent_logic.Observed(Observation(t, "0", 0.5, 0.5, 2.0)), p
    )
    assert out.report is not None
    assert out.report.used


def test_a_burst_of_fake_fixes_does_not_restart_the_track_on_them() -> None:
    state, p, _v, t = flying_agent()
    fused = GlobalEstimate(t, np.zeros(6), np.eye(6), (("0", 1.0),))
    state, out = agent_logic.step(state, agent_logic.HeardFused(fused), p)
    assert not out.refused
    for k in range(40):
        fake = Observation(t + 0.005 * k, "0", 10_000.0, 0.0, 2.0)
        state, out = agent_logic.step(state, agent_logic.Observed(fake), p)
        assert out.report is not None
        assert not out.report.used
    estimate = state.local.estimate()
    assert estimate is not None
    assert math.hypot(estimate.x[0], estimate.x[2]) < 10.0
    assert state.local.counters.restarts == 0


def test_without_a_fused_estimate_a_lost_track_still_restarts() -> None:
    state, p, _v, t = flying_agent()
    assert state.fused is None
    for k in range(p.local.max_consecutive_gated):
        fake = Observation(t + 0.01 * k, "0", 10_000.0, 0.0, 2.0)
        state, _ = agent_logic.step(state, agent_logic.Observed(fake), p)
    assert state.local.counters.restarts == 1


def test_a_silent_ground_orbits_the_last_estimate_then_holds() -> None:
    state, p, v, t = flying_agent()
    fused = GlobalEstimate(t, np.array([3.0, 0, 4.0, 0, 0, 0.0]), np.eye(6), (("0", 1.0),))
    state, _ = agent_logic.step(state, agent_logic.HeardFused(fused), p)
    heard_t = state.ground_heard_t_s
    assert heard_t is not None
    local = replace(state, local=replace(state.local, imm=None))  # its camera has nothing
    kinds: list[str] = []
    while t < heard_t + p.ground_silent_hold_s + 1.0:
        t = round(t + 0.1, 6)
        local, out = agent_logic.step(local, agent_logic.Control(t, own(v)), p)
        kinds += [e.kind for e in out.events]
        if t < heard_t + p.ground_silent_hold_s:
            target = agent_logic.target_at(local, t, p)
            assert target is not None
            assert (target.east_m, target.north_m) == (3.0, 4.0)
            assert out.command is not None
    assert kinds.count("ground_silent") == 1
    assert local.holding
    assert out.command is None


def test_messages_from_the_future_are_refused_by_the_agent() -> None:
    state, p, _v, t = flying_agent()
    mission = agent_logic.HeardMission("standby", (0,), t + 100.0)
    state2, out = agent_logic.step(state, mission, p)
    assert out.refused
    assert state2.stage == state.stage
    fix = agent_logic.TeammateFix(t + 100.0, 0.0, 0.0, 0.0, 14.0)
    state2, out = agent_logic.step(state, agent_logic.HeardTeammates(((1, fix),)), p)
    assert out.refused
    assert [v for v, _ in out.refused_teammates] == [1]
    assert state2.teammates == state.teammates


def test_without_a_clock_the_team_back_from_an_outage_moves_mission_time_one_liar_does_not() -> (
    None
):
    state = ground_run(ground_logic.initial_ground_state(), 0.0, 5.0, clock=False)
    liar = HeardStatuses(((0, report(30.0, 0)),))
    state, out = ground_logic.step(state, liar, GROUND)
    assert out.refused
    assert state.mission_t_s == 5.0
    back = HeardStatuses(((1, report(30.1, 1)),))  # a second vehicle at about that time
    state, out = ground_logic.step(state, back, GROUND)
    assert not out.refused
    assert state.mission_t_s == 30.1


def test_a_forged_fused_estimate_stamped_away_from_the_local_filters_time_is_judged_too() -> None:
    state, p, _v, t = flying_agent()
    off = GlobalEstimate(t + 4.0, np.array([500.0, 0, 0, 0, 0, 0.0]), np.eye(6), (("0", 1.0),))
    _state, out = agent_logic.step(state, agent_logic.HeardFused(off), p)
    assert "from the agent's own estimate" in out.refused
