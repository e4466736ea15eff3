"""The mission agent in the wind: commands carry the airspeed that flies their ground speed."""

import math

import numpy as np
import pytest

from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.core.agent import AgentEvent, Command, OwnTelemetry
from app.core.estimation.messages import GlobalEstimate
from app.core.guidance.wind import airspeed_for
from app.core.mission import agent as logic

WIND = (3.0, -2.0)  # east, north m/s


def _fly(
    params,
    airspeed_known=True,
    seconds=40.0,
    gust=(0.0, 0.0),
    gust_from_s=math.inf,
    radius=100.0,
    reported=None,
):
    """Control ticks at 10 Hz of a vehicle orbiting its standby point at 14 m/s through the
    air in the wind (the standby loiter: no target yet), with ``gust`` (east, north m/s) added
    to the wind from ``gust_from_s`` on, on a circle of ``radius`` m about it, the autopilot
    reporting the wind ``reported`` (None: no estimate of its own); the commands and events."""
    state = logic.initial_agent_state(params)
    commands: list[Command] = []
    events: list[AgentEvent] = []
    for k in range(round(seconds * 10)):
        t = 0.1 * (k + 1)
        heading = 0.15 * t
        extra = gust if t >= gust_from_s else (0.0, 0.0)
        g_e = 14.0 * math.sin(heading) + WIND[0] + extra[0]
        g_n = 14.0 * math.cos(heading) + WIND[1] + extra[1]
        own = OwnTelemetry(
            -1000.0 + radius * math.cos(heading),
            radius * math.sin(heading),
            math.atan2(g_e, g_n),
            math.hypot(g_e, g_n),
            14.0 if airspeed_known else None,
            reported,
        )
        state, out = logic.step(state, logic.Control(t, own), params)
        assert out.command is not None
        commands.append(out.command)
        events.extend(e for e in out.events if e.kind == "wind_estimated")
    return commands, events


def _params(wind: str):
    config = load_config("hil", MissionConfig)
    config = config.model_copy(
        update={"guidance": config.guidance.model_copy(update={"wind": wind})}
    )
    return build_plan(config).agents[0]


def test_once_the_wind_is_known_commands_carry_the_airspeed_for_their_ground_speed():
    commands, events = _fly(_params("estimate"))
    assert len(events) == 1  # said once, with the wind it found
    assert "3.6 m/s toward 124 deg" in events[0].detail
    early, late = commands[:100], commands[-200:]  # the last 20 s: half a turn
    assert all(c.airspeed_m_s is None for c in early)  # 10 s, 1.5 rad of turn: not yet known
    for c in late:
        assert c.airspeed_m_s is not None
        # for the course one speed-loop time constant (1 / speed_gain_per_s = 1 s) ahead
        ahead = c.field_course_rad + c.course_rate_ff_rad_s * 1.0
        want = airspeed_for(ahead, c.speed_m_s, WIND, 10.0, 18.0)
        assert c.airspeed_m_s == pytest.approx(want, abs=0.05)
        assert 10.0 <= c.airspeed_m_s <= 18.0
    # upwind and downwind: the airspeeds differ by about twice the wind along the course
    spread = max(c.airspeed_m_s - c.speed_m_s for c in late) - min(
        c.airspeed_m_s - c.speed_m_s for c in late
    )
    assert spread > 4.0


def test_without_an_airspeed_or_with_wind_off_the_command_is_the_ground_speed():
    for params, known in ((_params("estimate"), False), (_params("off"), True)):
        commands, events = _fly(params, airspeed_known=known)
        assert events == []
        assert all(c.airspeed_m_s is None for c in commands)


def test_a_gust_along_the_track_is_flown_out_by_the_airspeed():
    """Once the wind is known, a sudden extra wind the slow fit has not taken in yet shows as
    ground speed the airspeed does not explain; within a few seconds the airspeed commanded
    is what flies the command in the wind plus that gust (here a 1.5 m/s gust along the
    vehicle's track; the slow fit takes in a little of it meanwhile)."""
    params = _params("estimate")
    # on the standby loiter's own circle (150 m), so the command's course is the vehicle's
    calm, _ = _fly(params, seconds=40.0, radius=150.0)
    # the vehicle's ground course at t = 40 s: the gust blows along it
    heading = 0.15 * 40.0
    g_e, g_n = 14.0 * math.sin(heading) + WIND[0], 14.0 * math.cos(heading) + WIND[1]
    course = math.atan2(g_e, g_n)
    gust = (1.5 * math.sin(course), 1.5 * math.cos(course))
    gusty, _ = _fly(params, seconds=40.0, gust=gust, gust_from_s=35.0, radius=150.0)
    # 5 s of a 1 s low-pass: nearly the whole gust is taken
    c = gusty[-1]
    ahead = c.field_course_rad + c.course_rate_ff_rad_s * 1.0
    blowing = (WIND[0] + gust[0], WIND[1] + gust[1])
    with_gust = airspeed_for(ahead, c.speed_m_s, blowing, 10.0, 18.0)
    without = airspeed_for(ahead, c.speed_m_s, WIND, 10.0, 18.0)
    assert abs(with_gust - without) > 0.8  # the gust matters along the command's course
    assert c.airspeed_m_s == pytest.approx(with_gust, abs=0.25)
    assert calm[-300].airspeed_m_s == gusty[-300].airspeed_m_s  # before the gust: the same


def test_the_autopilots_own_wind_is_flown_from_the_first_frame():
    """An autopilot that reports its wind (PX4 WIND_COV, ArduPilot WIND) is believed at once,
    with no half turn to fit; a non-finite report is not, and the agent fits its own."""
    commands, events = _fly(_params("estimate"), seconds=5.0, reported=WIND)
    assert len(events) == 1
    assert "3.6 m/s toward 124 deg (the autopilot's estimate)" in events[0].detail
    c = commands[0]
    ahead = c.field_course_rad + c.course_rate_ff_rad_s * 1.0
    assert c.airspeed_m_s == pytest.approx(airspeed_for(ahead, c.speed_m_s, WIND, 10.0, 18.0))
    commands, events = _fly(_params("estimate"), seconds=40.0, reported=(math.nan, 1.0))
    assert all(c.airspeed_m_s is None for c in commands[:100])
    assert "fitted to ground velocity and airspeed" in events[0].detail


def _team_speeds(lead, reported):
    """One control tick of a three-vehicle team in adjust on the default mission's circle about
    a target at the origin, nearly spaced (each within 0.2 rad of its seat), each autopilot
    reporting the wind ``reported``: the ground speeds commanded."""
    config = load_config("hil", MissionConfig)
    config = config.model_copy(
        update={"phase": config.phase.model_copy(update={"gather_lead_speed_m_s": lead})}
    )
    plist = build_plan(config).agents
    angles = (0.0, 1.9, 4.0)  # counter-clockwise from east
    positions = [(90.0 * math.cos(a), 90.0 * math.sin(a), -a) for a in angles]
    estimate = GlobalEstimate(0.0, np.zeros(6), np.eye(6), (("0", 1.0),))
    speeds = []
    for i, p in enumerate(plist):
        state = logic.hear_mission(
            logic.initial_agent_state(p), "adjust", tuple(p.vehicle for p in plist)
        )
        state = logic.hear_fused(state, estimate, p)
        for j, (e, n, course) in enumerate(positions):
            fix = logic.TeammateFix(0.0, e, n, course, 14.0)
            state = logic.hear_teammate(state, plist[j].vehicle, fix)
        e, n, course = positions[i]
        own = OwnTelemetry(e, n, course, 14.0, 14.0, reported)
        _, command, _ = logic.control(state, 0.0, own, p)
        speeds.append(command.speed_m_s)
    return speeds


def test_a_lead_speed_is_flown_only_where_the_circle_can_be_flown_at_it_in_the_wind():
    """In gather and adjust the vehicle furthest behind its seat flies the lead speed, but only
    where the circle can be flown all round at that ground speed in the wind the agent knows
    (18 m/s on 90 m at 0.2 rad/s in still air); in 3 m/s it is not, and the paper's law about
    cruise is flown, as with no lead."""
    paper = _team_speeds(None, (0.0, 0.0))
    assert max(paper) < 16.0  # about cruise (14 m/s)
    still = _team_speeds(18.0, (0.0, 0.0))
    # the vehicle furthest behind leads, in adjust at 0.9 of the 18 m/s (the mission's
    # adjust_lead_turn_share of W r_d; 18 m/s in gather)
    assert max(still) == pytest.approx(0.9 * 18.0, abs=1e-3)
    assert min(still) > 12.0  # and the others slower by the law
    # the same gaps: the speeds differ by the same amounts
    assert np.subtract(still, max(still)) == pytest.approx(np.subtract(paper, max(paper)))
    windy = _team_speeds(18.0, WIND)  # 3.6 m/s
    assert windy == pytest.approx(_team_speeds(None, WIND))
    # a lead the wind allows stays: 15 m/s is flyable in 1.5 m/s (up to 16.3 m/s)
    assert max(_team_speeds(15.0, (1.5, 0.0))) == pytest.approx(15.0)
    assert max(_team_speeds(17.0, (1.5, 0.0))) < 16.0
