"""A retained nesting bomb on a real mosquitto: every client drops it, counts it and stays on
the bus (issue #14: it made every MQTT client drop its connection and reconnect in a loop)."""

from __future__ import annotations

import asyncio

import paho.mqtt.publish
import pytest

from app.adapters.bus import MqttBus
from app.runtime.ports import topics
from tests.adapters.test_bus_conformance import observation, take
from tests.support.mosquitto import Mosquitto

BOMB = b"[" * 5000 + b"]" * 5000


@pytest.mark.slow
async def test_a_retained_nesting_bomb_on_every_topic_keeps_every_client_on_the_bus(
    mosquitto: Mosquitto,
) -> None:
    bomb_topics = [
        topics.MISSION,
        topics.GLOBAL_ESTIMATE,
        topics.observation(0),
        topics.status(1),
        topics.local_estimate(2),
        topics.command(),
    ]
    for topic in bomb_topics:
        paho.mqtt.publish.single(
            str(topic), BOMB, retain=True, hostname="127.0.0.1", port=mosquitto.port
        )
    async with (
        MqttBus(mosquitto.url, client_id="agent-1") as agent,
        MqttBus(mosquitto.url, client_id="ground") as ground,
        agent.subscribe(topics.ALL) as heard,
    ):
        await ground.publish(topics.observation(0), observation(1.0))
        assert [m.t_s for _, m in await take(heard, 1)] == [1.0]
        await asyncio.sleep(0.3)
        await ground.publish(topics.observation(0), observation(2.0))
        assert [m.t_s for _, m in await take(heard, 1)] == [2.0]
        assert agent.stats.malformed == len(bomb_topics)
        assert (agent.connections, agent.losses, agent.stats.reconnects) == (1, 0, 0)
        assert agent.connected
