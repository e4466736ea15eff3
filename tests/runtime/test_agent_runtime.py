"""The agent loop (``VehicleAgent``) around the mission logic: what it does with the bus's messages.

A fake vehicle link (``tests/support/fake_link.py``: its camera fed by the test, no
telemetry) and the in-process bus.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable

import numpy as np
import pytest

from app.adapters.bus import InProcessBroker, InProcessBus, codec
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.core.estimation.messages import GlobalEstimate
from app.core.mission import agent as agent_logic
from app.runtime.agent import VehicleAgent
from app.runtime.ports import messages as bus
from app.runtime.ports import topics
from app.runtime.ports.vehicle import TargetObservation
from app.runtime.wire import global_to_bus
from tests.support.fake_link import QueueLink, frame

WAIT_S = 5.0


class Events:
    def __init__(self) -> None:
        self.kinds: list[str] = []

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        self.kinds.append(kind)


async def until(predicate: Callable[[], bool]) -> None:
    """Wait for the agent's state to satisfy ``predicate`` (nothing signals it: poll)."""
    async with asyncio.timeout(WAIT_S):
        while not predicate():  # noqa: ASYNC110
            await asyncio.sleep(0.001)


@contextlib.asynccontextmanager
async def ticking(agent: VehicleAgent, link: QueueLink) -> AsyncIterator[None]:
    """``agent`` running, its first control tick taken (a frame at 1 s, 90 m east); stopped on
    the way out."""
    async with asyncio.TaskGroup() as tg:
        task = tg.create_task(agent.run())
        await asyncio.sleep(0.01)
        link.put(frame(1.0, 90.0, 0.0))
        await until(lambda: agent.counters.ticks == 1)
        yield
        task.cancel()


@pytest.mark.parametrize("queued", [1, 5])
async def test_only_the_newest_of_the_fused_estimates_waiting_is_applied(queued: int) -> None:
    """Fused estimates that queued up while the agent was busy are history once a newer one
    is there: the agent applies the newest alone (each application replays the local filter's
    recent observations; applying every stale one in turn is how a loaded agent fell behind)."""
    plan = build_plan(load_config("hil", MissionConfig))
    params = plan.agents[0]
    assert params.main is not None
    assert params.main.feedback == "modewise"
    broker = InProcessBroker()
    link = QueueLink()
    async with (
        InProcessBus(broker, client_id="agent-1") as agent_bus,
        InProcessBus(broker, client_id="ground") as ground,
        asyncio.TaskGroup() as tg,
    ):
        agent = VehicleAgent(params, link, agent_bus, Events())
        running = tg.create_task(agent.run())
        for k in range(3):  # the local filter starts on the camera's observations (0.5 s
            # apart: a backlog within merge_window_s would be merged into one)
            link.seen.put_nowait(TargetObservation(1, 0.5 * k, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0))
        await until(lambda: agent.state.local.counters.updated >= 2)
        local = agent.state.local.estimate()
        assert local is not None
        before = agent.state.local.counters.feedback
        for k in range(queued):  # all arrive at once: the agent has not had a turn meanwhile
            fused = GlobalEstimate(
                t_s=local.t_s + 0.01 * k,
                x=local.x + np.array([k, 0.0, 0.0, 0.0, 0.0, 0.0]),
                p=local.p,
                beta=((params.sensor, 1.0),),
                mu=local.mu,
                model_x=local.model_x,
                model_p=local.model_p,
            )
            payload = codec.encode(global_to_bus(fused, "ground"))
            ground.inject_raw(str(topics.GLOBAL_ESTIMATE), payload)
        newest = local.t_s + 0.01 * (queued - 1)
        await until(lambda: agent.state.fused is not None and agent.state.fused.t_s == newest)
        await asyncio.sleep(0.05)  # time enough for any older one to be applied after it
        assert agent.state.local.counters.feedback - before == 1
        assert agent_bus.stats.dropped == queued - 1
        running.cancel()


async def test_observations_that_queued_while_the_agent_was_busy_are_merged():
    """3 s of a camera's fixes arrive at once (the agent had no turn meanwhile): they reach the
    local filter as about one merged fix per merge_window_s, every one accounted for, and the
    estimate follows the target (7 m/s east)."""
    plan = build_plan(load_config("hil", MissionConfig))
    broker = InProcessBroker()
    link = QueueLink()
    for k in range(30):
        t = 0.1 * k
        link.seen.put_nowait(TargetObservation(1, t, 0.0, 0.0, 0.0, 7.0 * t, 0.0, 1.0))
    async with (
        InProcessBus(broker, client_id="agent-1") as agent_bus,
        asyncio.TaskGroup() as tg,
    ):
        agent = VehicleAgent(plan.agents[0], link, agent_bus, Events())
        running = tg.create_task(agent.run())
        c = agent.counters
        await until(lambda: c.observations_used + c.observations_merged >= 30)
        assert c.observations_dropped == 0
        assert c.observations_used <= 12  # 0.3 s windows over 2.9 s, not 30 updates
        assert c.observations_merged == 30 - c.observations_used
        estimate = agent.state.local.estimate()
        assert estimate is not None
        assert abs(estimate.x[0] - 7.0 * estimate.t_s) < 1.5
        running.cancel()


async def test_teammates_statuses_are_taken_once_per_control_tick_in_one_step(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Statuses wait on the bus until the agent's next control tick, which takes them all in one
    step, in the order they came (each teammate's newest kept): a team of n then costs each
    agent one step per tick instead of one per status, n^2 over the process."""
    plan = build_plan(load_config("test-short", MissionConfig))
    broker = InProcessBroker()
    link = QueueLink()
    batches: list[tuple[int, ...]] = []
    step = agent_logic.step

    def counted(
        state: agent_logic.MissionAgentState,
        event: agent_logic.AgentInput,
        params: agent_logic.MissionAgentParams,
    ) -> tuple[agent_logic.MissionAgentState, agent_logic.AgentOutbox]:
        if isinstance(event, agent_logic.HeardTeammates):
            batches.append(tuple(v for v, _ in event.fixes))
        return step(state, event, params)

    monkeypatch.setattr(agent_logic, "step", counted)

    def status(vehicle: int, t_s: float, east_m: float) -> bus.VehicleStatus:
        return bus.VehicleStatus(
            sender=f"agent-{vehicle + 1}", t_s=t_s, vehicle=vehicle, east_m=east_m,
            north_m=0.0, alt_m=100.0, course_rad=0.0, speed_m_s=14.0, phase_rad=0.0,
            stage="gather", link="ok", healthy=True,
        )  # fmt: skip

    async with (
        InProcessBus(broker, client_id="agent-1") as agent_bus,
        InProcessBus(broker, client_id="agent-2") as second,
        InProcessBus(broker, client_id="agent-3") as third,
    ):
        agent = VehicleAgent(plan.agents[0], link, agent_bus, Events())
        async with ticking(agent, link):
            await second.publish(topics.status(1), status(1, 0.9, 10.0))
            await third.publish(topics.status(2), status(2, 0.95, 20.0))
            await second.publish(topics.status(1), status(1, 1.0, 11.0))
            await agent_bus.publish(topics.status(0), status(0, 1.0, 90.0))  # its own: not kept
            await asyncio.sleep(0.05)
            assert agent.state.teammates == ()  # heard, waiting for the tick
            link.put(frame(1.1, 91.4, 0.0))
            await until(lambda: agent.counters.ticks == 2)
    assert batches == [(1, 2, 1)]
    held: dict[int, agent_logic.TeammateFix] = dict(agent.state.teammates)
    assert sorted(held) == [1, 2]
    assert (held[1].t_s, held[1].east_m) == (1.0, 11.0)
    assert held[2].east_m == 20.0
    assert agent.counters.messages_refused == 0
