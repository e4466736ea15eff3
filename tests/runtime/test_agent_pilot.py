"""The agent and the vehicle's bring-up around a fake link: the pilot always wins (a mode change
by someone else is left alone until ``resume``), the hand-over waits for height and airspeed, the
course rate reaches the link, and every vehicle flies its own altitude of the stack."""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any

import pytest

from app.adapters.bus import InProcessBroker, InProcessBus
from app.compose.mission import parse_operator_line, relay_operator
from app.compose.parts import bring_up, vehicle_agent
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.runtime.agent import AgentRuntimeParams, VehicleAgent
from app.runtime.ports import messages as bus
from app.runtime.ports import topics
from app.runtime.vehicle import BringUp, HandoverTimeout, prepare_vehicle
from tests.support.fake_link import QueueLink, frame

WAIT_S = 5.0


class Events:
    def __init__(self) -> None:
        self.seen: list[tuple[str, float, dict[str, Any]]] = []

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        self.seen.append((kind, t_s, fields))

    def of(self, kind: str) -> list[dict[str, Any]]:
        return [f for k, _t, f in self.seen if k == kind]


async def until(predicate: Callable[[], bool]) -> None:
    async with asyncio.timeout(WAIT_S):
        while not predicate():  # noqa: ASYNC110
            await asyncio.sleep(0.001)


class Flyer:
    """Feeds the fake link frames 0.1 s of vehicle time apart, flying the hil mission's
    standby circle (150 m about (-1000, 0)) counter-clockwise at 14 m/s."""

    def __init__(self, link: QueueLink) -> None:
        self.link = link
        self.t = 0.0

    async def frames(self, n: int) -> None:
        for _ in range(n):
            self.t += 0.1
            a = 14.0 / 150.0 * self.t
            east, north = -1000.0 + 150.0 * math.cos(a), 150.0 * math.sin(a)
            course = -a % (2.0 * math.pi)
            self.link.put(frame(self.t, east, north, course_rad=course, flight_mode=self.link.mode))
            await asyncio.sleep(0.002)


@asynccontextmanager
async def agent_and_ground(
    client_id: str,
) -> AsyncIterator[tuple[InProcessBus, InProcessBus, list[bus.VehicleStatus], asyncio.TaskGroup]]:
    """An agent's bus and the ground's on one in-process broker, every status the ground hears
    in the list yielded, and a task group to run the agent in."""
    broker = InProcessBroker()
    statuses: list[bus.VehicleStatus] = []
    async with (
        InProcessBus(broker, client_id=client_id) as agent_bus,
        InProcessBus(broker, client_id="ground") as ground,
        ground.subscribe(topics.ALL_STATUS) as heard,
        asyncio.TaskGroup() as tg,
    ):

        async def listen() -> None:
            async for _topic, message in heard:
                if isinstance(message, bus.VehicleStatus):
                    statuses.append(message)

        listener = tg.create_task(listen())
        try:
            yield agent_bus, ground, statuses, tg
        finally:
            listener.cancel()


async def test_a_mode_change_by_someone_else_is_not_fought_until_resume() -> None:
    plan = build_plan(load_config("hil", MissionConfig))
    link = QueueLink()
    events = Events()
    async with agent_and_ground("agent-1") as (agent_bus, ground, statuses, tg):

        def control() -> str:
            return statuses[-1].control

        def piloted() -> bool:
            return agent.pilot_has_control

        agent = VehicleAgent(plan.agents[0], link, agent_bus, events)
        running = tg.create_task(agent.run())
        fly = Flyer(link)
        await fly.frames(20)
        await until(lambda: link.sent >= 10)
        assert statuses
        assert control() == "mission"

        link.leave_offboard("POSCTL", fly.t)  # an RC pilot takes it
        await until(lambda: bool(events.of("pilot_took_over")))
        sent = link.sent
        await fly.frames(40)  # 4 s of frames: past the old 2 s retry
        await until(lambda: statuses[-1].t_s >= fly.t - 0.2)
        assert link.sent == sent
        assert link.offboard_starts == 0
        assert link.holds == 0
        assert events.of("pilot_took_over") == [{"vehicle": 0, "flight_mode": "POSCTL"}]
        assert piloted()
        assert control() == "pilot"
        assert statuses[-1].flight_mode == "POSCTL"

        # a hold for every vehicle leaves this one in its pilot's mode
        await ground.publish(
            topics.command(), bus.Command(sender="ground", t_s=0.0, command="hold")
        )
        await until(lambda: bool(events.of("command")))
        assert link.holds == 0
        await ground.publish(
            topics.command(), bus.Command(sender="ground", t_s=0.0, command="resume")
        )
        await until(lambda: link.offboard_starts == 1)
        assert events.of("resumed") == [{"vehicle": 0, "from_mode": "POSCTL"}]
        assert not piloted()
        await fly.frames(20)
        await until(lambda: link.sent > sent)
        await until(lambda: control() == "mission")
        running.cancel()


async def test_the_commands_carry_the_wanted_course_rate_and_the_stack_altitude() -> None:
    plan = build_plan(load_config("hil", MissionConfig))
    stack_m = plan.config.link.altitude_stack_m
    assert stack_m > 0.0
    broker = InProcessBroker()
    altitudes = []
    for i in range(plan.count):
        link = QueueLink()
        async with (
            InProcessBus(broker, client_id=f"agent-{i + 1}") as agent_bus,
            asyncio.TaskGroup() as tg,
        ):
            agent = vehicle_agent(plan, i, link, agent_bus, Events(), builtin=True)
            running = tg.create_task(agent.run())
            await Flyer(link).frames(30)
            await until(lambda link=link: link.sent >= 20)  # type: ignore[misc]
            running.cancel()
        assert {c.altitude_m for c in link.commands} == {bring_up(plan, i).altitude_m}
        altitudes.append(link.commands[-1].altitude_m)
        # loitering at standby, the wanted course turns: its rate reaches the link
        rates = [c.course_rate_rad_s for c in link.commands]
        assert all(math.isfinite(r) for r in rates)
        limit = plan.agents[i].agent.envelope.max_course_rate_rad_s
        assert all(abs(r) <= limit for r in rates)  # never more than the airframe turns
        assert any(abs(r) > 0.01 for r in rates)
        # counter-clockwise seen from above: the course falls (clockwise positive)
        assert sum(r < 0.0 for r in rates) > 0.8 * len(rates)
        # the wanted course goes with the led command: behind it by about rate / k in a turn
        # (the offboard-start command, the vehicle's own course, has none)
        sent = link.commands[1:]
        assert all(c.path_course_rad is not None for c in sent)
        k = plan.agents[i].agent.envelope.course_gain_per_s
        leads = [
            math.remainder(c.course_rad - c.path_course_rad, 2.0 * math.pi)
            for c in sent[-10:]
            if c.path_course_rad is not None
        ]
        assert leads == pytest.approx([c.course_rate_rad_s / k for c in sent[-10:]], abs=0.05)
    base = plan.config.link.altitude_m
    assert altitudes == [base + i * stack_m for i in range(plan.count)]


async def test_the_status_says_the_height_the_climb_and_the_level_it_is_sent_to() -> None:
    """What the teammates' separation guards predict a climb on: the vehicle's height about the
    origin, its climb rate, and its place in the stack about the origin (home 10 m above it)."""
    plan = build_plan(load_config("hil", MissionConfig))
    link = QueueLink()
    async with agent_and_ground("agent-2") as (agent_bus, _ground, statuses, tg):
        agent = vehicle_agent(plan, 1, link, agent_bus, Events(), builtin=True)
        running = tg.create_task(agent.run())
        for k in range(30):
            height = 50.0 + 0.3 * k
            link.put(frame(0.1 * (k + 1), -1000.0, 150.0, relative_altitude_m=height,
                           up_m=10.0 + height, climb_rate_m_s=3.0))  # fmt: skip
            await asyncio.sleep(0.002)
        await until(lambda: len(statuses) >= 5)
        running.cancel()
    last = statuses[-1]
    assert last.up_m is not None
    assert last.up_m == pytest.approx(10.0 + last.alt_m)
    assert last.climb_m_s == pytest.approx(3.0)
    level = bring_up(plan, 1).altitude_m
    assert level is not None
    assert last.level_up_m == pytest.approx(10.0 + level)


class ClimbingLink(QueueLink):
    """A vehicle that takes off from a runway: ``take_off`` returns once it is rolling, and
    frames then come from ``profile`` (height m, airspeed m/s), 0.5 s apart."""

    def __init__(self, profile: list[tuple[float, float]]) -> None:
        super().__init__()
        self.profile = profile

    async def wait_ready(self, timeout_s: float) -> Any:
        ground = frame(0.0, 0.0, 0.0, relative_altitude_m=0.0, ground_speed_m_s=0.0, in_air=False)
        self.put(ground)
        return ground

    async def take_off(self, timeout_s: float, altitude_m: float | None = None) -> None:
        asyncio.get_running_loop().call_soon(lambda: asyncio.ensure_future(self._climb()))

    async def _climb(self) -> None:
        for k, (height, airspeed) in enumerate(self.profile):
            await asyncio.sleep(0.005)
            self.put(
                frame(
                    0.5 * (k + 1),
                    0.0,
                    0.0,
                    relative_altitude_m=height,
                    airspeed_m_s=airspeed,
                    ground_speed_m_s=airspeed,
                    in_air=height > 0.0 or airspeed > 9.0,
                    flight_mode="TAKEOFF",
                )
            )


def bring(**changes: float) -> BringUp:
    fields: dict[str, Any] = {
        "connect_timeout_s": 1.0,
        "take_off_timeout_s": 1.0,
        "altitude_m": 100.0,
        "cruise_speed_m_s": 18.0,
        "origin_lat_deg": 0.0,
        "origin_lon_deg": 0.0,
        "handover_min_height_m": 30.0,
        "handover_min_airspeed_m_s": 12.0,
        "handover_timeout_s": 2.0,
    }
    fields.update(changes)
    return BringUp(**fields)


async def test_the_hand_over_waits_for_height_and_airspeed_never_the_runway() -> None:
    # a ground roll at 10 m/s reported as in the air (as PX4 does), a climb, a slow stretch
    profile = [(0.0, 10.0), (0.0, 12.5), (8.0, 13.0), (31.0, 11.0), (36.0, 14.5), (45.0, 15.0)]
    link = ClimbingLink(profile)
    events = Events()
    await prepare_vehicle(link, bring(), events)
    assert link.offboard_starts == 1
    [handover] = events.of("handover")
    assert handover["height_m"] == 36.0
    assert handover["airspeed_m_s"] == 14.5
    assert handover["speed_source"] == "airspeed"
    assert [k for k, _t, _f in events.seen] == ["handover", "offboard"]


@pytest.mark.parametrize(
    ("changes", "named"),
    [
        ({"handover_min_height_m": 80.0}, "height 45.0 m < 80.0 m"),
        ({"handover_min_airspeed_m_s": 20.0}, "airspeed 15.0 m/s < 20.0 m/s"),
    ],
)
async def test_a_hand_over_that_never_comes_names_what_was_not_reached(
    changes: dict[str, float], named: str
) -> None:
    link = ClimbingLink([(10.0, 13.0), (45.0, 15.0)])
    events = Events()
    with pytest.raises(HandoverTimeout, match=named):
        await prepare_vehicle(link, bring(handover_timeout_s=0.2, **changes), events)
    assert link.offboard_starts == 0
    [timeout] = events.of("handover_timeout")
    assert named in timeout["reason"]


@pytest.mark.parametrize(
    ("configured", "honours_speed", "actuator"),
    [("auto", True, "speed"), ("auto", False, "radius"), ("speed", False, "speed")],
)
async def test_the_phase_actuator_is_resolved_against_what_the_autopilot_honours(
    configured: str, honours_speed: bool, actuator: str
) -> None:
    plan = build_plan(load_config("hil", MissionConfig))
    link = QueueLink()
    link.honours_speed = honours_speed
    events = Events()
    async with InProcessBus(InProcessBroker(), client_id="agent-1") as agent_bus:
        runtime = AgentRuntimeParams(phase_actuator=configured)  # type: ignore[arg-type]
        agent = VehicleAgent(plan.agents[0], link, agent_bus, events, runtime)
    assert agent.actuator == actuator
    assert agent.params.agent.phase.actuator == actuator
    assert agent.params.standby.phase.actuator == actuator
    [event] = events.of("phase_actuator")
    assert event["actuator"] == actuator
    assert event["honours_speed"] is honours_speed
    assert event["configured"] == configured


@pytest.mark.parametrize("limit", [None, 0.2])
async def test_the_course_identification_is_told_where_the_autopilots_command_saturates(
    limit: float | None,
) -> None:
    plan = build_plan(load_config("ardupilot-sitl", MissionConfig))
    assert plan.agents[0].course_id is not None
    link = QueueLink()
    link.course_error_limit_rad = limit
    async with InProcessBus(InProcessBroker(), client_id="agent-1") as agent_bus:
        agent = VehicleAgent(plan.agents[0], link, agent_bus, Events())
    assert agent.params.course_id is not None
    assert agent.params.course_id.command_limit_rad == limit


@pytest.mark.parametrize(
    ("line", "command", "vehicles"),
    # vehicles numbered from 1 as the live view prints them; the command carries the indices
    [("resume 2\n", "resume", (1,)), ("  RESUME  ", "resume", None), ("hold 1 3", "hold", (0, 2))],
)
def test_an_operators_line_is_a_bus_command(
    line: str, command: str, vehicles: tuple[int, ...] | None
) -> None:
    parsed = parse_operator_line(line, 3)
    assert parsed is not None
    assert (parsed.command, parsed.vehicles) == (command, vehicles)


@pytest.mark.parametrize(
    ("line", "why"),
    [
        ("takeoff", "unknown command 'takeoff'"),
        ("resume 4", "1..3"),
        ("resume 0", "1..3"),
        ("resume x", "numbers"),
    ],
)
def test_a_bad_operator_line_is_refused_with_the_reason(line: str, why: str) -> None:
    assert parse_operator_line("   \n", 3) is None
    with pytest.raises(ValueError, match=why):
        parse_operator_line(line, 3)


async def test_typed_lines_reach_the_agents_as_commands_and_bad_ones_are_skipped() -> None:
    broker = InProcessBroker()

    async def typed() -> AsyncIterator[str]:
        for line in ("resume 7\n", "resume 2\n"):
            yield line

    events = Events()
    async with (
        InProcessBus(broker, client_id="operator") as operator,
        InProcessBus(broker, client_id="agent-2") as agent_bus,
        agent_bus.subscribe(topics.ALL_COMMANDS) as commands,
    ):
        await relay_operator(typed(), operator, events, 3, lambda: 42.0)
        async with asyncio.timeout(WAIT_S):
            _topic, message = await anext(aiter(commands))
    assert isinstance(message, bus.Command)
    assert (message.command, message.vehicles, message.t_s) == ("resume", (1,), 42.0)
    assert events.of("operator_command") == [{"command": "resume", "vehicles": (1,)}]


async def test_a_refused_setpoint_before_the_new_mode_is_seen_is_reported_unknown_then_named():
    # MAVSDK can refuse a setpoint (offboard lost) before any frame shows the new mode: the
    # newest frame still says OFFBOARD, which must not be reported as the mode it was put in
    plan = build_plan(load_config("hil", MissionConfig))
    broker = InProcessBroker()
    link = QueueLink()
    events = Events()
    async with (
        InProcessBus(broker, client_id="agent-1") as agent_bus,
        InProcessBus(broker, client_id="ground") as ground,
        asyncio.TaskGroup() as tg,
    ):
        agent = VehicleAgent(plan.agents[0], link, agent_bus, events)
        running = tg.create_task(agent.run())
        fly = Flyer(link)
        await fly.frames(20)
        await until(lambda: link.sent >= 10)
        link.mode = "RTL"  # a failsafe: sends are refused, the frames do not show it yet
        fly.t += 0.1
        link.put(frame(fly.t, -850.0, 0.0, flight_mode="OFFBOARD"))
        await until(lambda: bool(events.of("pilot_took_over")))
        assert events.of("pilot_took_over") == [{"vehicle": 0, "flight_mode": "UNKNOWN"}]
        assert agent.pilot_has_control
        link.leave_offboard("RTL", fly.t + 0.1)  # the link names the mode
        await until(lambda: bool(events.of("pilot_mode")))
        assert events.of("pilot_mode") == [{"vehicle": 0, "flight_mode": "RTL"}]
        assert len(events.of("pilot_took_over")) == 1  # one take-over, not two
        await ground.publish(
            topics.command(), bus.Command(sender="ground", t_s=0.0, command="resume")
        )
        await until(lambda: link.offboard_starts == 1)
        assert events.of("resumed") == [{"vehicle": 0, "from_mode": "RTL"}]
        running.cancel()
