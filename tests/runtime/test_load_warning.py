"""An agent short of CPU says so: it counts the telemetry frames it steered past, warns with a
``falling_behind`` event, and ``standoff fly``'s report carries a warning line."""

from __future__ import annotations

import asyncio
import logging
import math
import random

import pytest

from app.adapters.bus import InProcessBroker, InProcessBus
from app.cli.fly import report
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.runtime.agent import AgentRuntimeParams, VehicleAgent
from app.runtime.events import LoggingSink
from tests.support.fake_link import QueueLink, frame


class BurstyLink(QueueLink):
    """Telemetry in bursts the agent cannot keep up with; the newest frame has waited 0.02 s
    of host time (``latest_age_s``)."""

    latest_age_s = 0.02


class Events:
    def __init__(self) -> None:
        self.seen: list[tuple[str, dict[str, object]]] = []

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        self.seen.append((kind, fields))


async def fly_bursts(
    burst: int, seconds: float, runtime: AgentRuntimeParams | None = None
) -> tuple[VehicleAgent, Events, BurstyLink]:
    plan = build_plan(load_config("hil", MissionConfig))
    link = BurstyLink()
    events = Events()
    async with (
        InProcessBus(InProcessBroker(), client_id="agent-1") as bus,
        asyncio.TaskGroup() as tg,
    ):
        agent = VehicleAgent(plan.agents[0], link, bus, events, runtime or AgentRuntimeParams())
        running = tg.create_task(agent.run())
        k = 0
        while k * 0.1 < seconds:
            for _ in range(burst):  # 10 Hz frames, `burst` of them between two turns
                t = 0.1 * k
                link.put(frame(t, -1000.0 + 14.0 * t, 150.0))
                k += 1
            await asyncio.sleep(0.002)
        running.cancel()
    return agent, events, link


async def test_an_agent_that_steers_past_most_frames_warns_once_per_period() -> None:
    # (only the first warning reaches the terminal; the repeats go to the event log)
    agent, events, link = await fly_bursts(burst=5, seconds=45.0)
    c = agent.counters
    assert c.frames_skipped > 3 * c.ticks  # 4 of every 5 frames steered past
    assert link.sent == c.ticks
    warnings = [f for kind, f in events.seen if kind == "falling_behind"]
    assert 1 <= len(warnings) <= 2  # over 45 s, at most one per 30 s
    assert float(warnings[0]["skipped_share"]) > 0.7  # type: ignore[arg-type]
    assert "short of CPU" in str(warnings[0]["detail"])
    assert [w["repeat"] for w in warnings] == [False, True][: len(warnings)]


async def test_an_agent_that_keeps_up_does_not_warn() -> None:
    agent, events, _ = await fly_bursts(burst=1, seconds=25.0)
    assert agent.counters.frames_skipped == 0
    assert not [kind for kind, _ in events.seen if kind == "falling_behind"]


def test_the_report_warns_when_an_agent_fell_behind() -> None:
    summary: dict[str, object] = {
        "wall_s": 150.0,
        "mission_t_s": 420.0,
        "agents": {
            "0": {"ticks": 4100, "frames_skipped": 80},
            "1": {"ticks": 2500, "frames_skipped": 1700},
        },
    }
    text = report(summary)
    assert "warning: the agents fell behind" in text
    assert "40%" in text
    summary["agents"] = {"0": {"ticks": 4100, "frames_skipped": 80}}
    assert "warning" not in report(summary)


def test_only_the_first_warning_of_a_kind_is_logged_as_a_warning(caplog) -> None:
    sink = LoggingSink()
    with caplog.at_level(logging.INFO, logger="standoff.events"):
        sink.emit("falling_behind", 1.0, vehicle=0, repeat=False)
        sink.emit("falling_behind", 31.0, vehicle=0, repeat=True)
        sink.emit("stage", 2.0, detail="track")
    levels = [(r.levelno, "repeat=True" in r.getMessage()) for r in caplog.records]
    assert levels == [(logging.WARNING, False), (logging.INFO, True), (logging.INFO, False)]


async def test_how_long_frames_waited_is_counted_in_vehicle_seconds() -> None:
    agent, _, _ = await fly_bursts(burst=1, seconds=3.0, runtime=AgentRuntimeParams(clock_rate=3.0))
    c = agent.counters
    assert c.ticks > 10
    assert c.frame_wait_max_s == pytest.approx(0.06)
    assert c.frame_wait_sum_s == pytest.approx(0.06 * c.ticks)


async def fly_stream(
    rate_hz: float, seconds: float, runtime: AgentRuntimeParams, jitter_s: float = 0.0
) -> tuple[VehicleAgent, Events, BurstyLink]:
    """One frame at a time at ``rate_hz`` (each stamped up to ``jitter_s`` off its slot), the
    agent given the time to steer on each."""
    plan = build_plan(load_config("hil", MissionConfig))
    link = BurstyLink()
    events = Events()
    rng = random.Random(1)
    async with (
        InProcessBus(InProcessBroker(), client_id="agent-1") as bus,
        asyncio.TaskGroup() as tg,
    ):
        agent = VehicleAgent(plan.agents[0], link, bus, events, runtime)
        running = tg.create_task(agent.run())
        for k in range(round(seconds * rate_hz)):
            t = k / rate_hz + rng.uniform(-jitter_s, jitter_s)
            link.put(frame(t, -1000.0 + 14.0 * t, 150.0))
            await asyncio.sleep(0.001)
        running.cancel()
    return agent, events, link


async def test_telemetry_faster_than_the_control_rate_is_coalesced_not_taken_for_load() -> None:
    # PX4 streams position at 50 Hz; the agents steer at 10 Hz on the newest frame
    agent, events, link = await fly_stream(50.0, 40.0, AgentRuntimeParams(control_period_s=0.1))
    c = agent.counters
    assert 395 <= c.ticks <= 401  # one a control period
    assert c.frames_coalesced == 2000 - c.ticks
    assert c.frames_skipped == 0
    assert link.sent == c.ticks
    assert not [kind for kind, _ in events.seen if kind == "falling_behind"]
    # with no control period every frame is steered on
    every, _, _ = await fly_stream(50.0, 10.0, AgentRuntimeParams())
    assert every.counters.ticks == 500
    assert every.counters.frames_coalesced == 0


async def test_telemetry_at_the_control_rate_is_steered_on_every_frame_despite_jitter() -> None:
    runtime = AgentRuntimeParams(control_period_s=0.1)
    agent, _, _ = await fly_stream(10.0, 30.0, runtime, jitter_s=0.02)
    assert (agent.counters.ticks, agent.counters.frames_coalesced) == (300, 0)
    slow, _, _ = await fly_stream(5.0, 30.0, runtime)
    assert (slow.counters.ticks, slow.counters.frames_coalesced) == (150, 0)


def test_a_bad_control_period_is_refused() -> None:
    with pytest.raises(ValueError, match="control_period_s"):
        AgentRuntimeParams(control_period_s=math.nan)
