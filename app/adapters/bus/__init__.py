"""The message bus: the bus port (``app.runtime.ports.bus``) in-process (default) or over MQTT
(docs/bus.md)."""

from __future__ import annotations

from typing import Any

from app.adapters.bus.base import (
    DEFAULT_QUEUE_SIZE,
    DROP_REASONS,
    Birth,
    Bus,
    BusClosed,
    BusStats,
    Subscription,
    Will,
)
from app.adapters.bus.codec import MalformedMessage, UnsupportedVersion, decode, encode
from app.adapters.bus.inproc import InProcessBroker, InProcessBus
from app.adapters.bus.mqtt import Backoff, BrokerUrl, BusUrlError, Login, MqttBus, tls_context
from app.adapters.bus.signing import MissionKey, MissionKeyError

__all__ = [
    "DEFAULT_QUEUE_SIZE",
    "DROP_REASONS",
    "Backoff",
    "Birth",
    "BrokerUrl",
    "Bus",
    "BusClosed",
    "BusStats",
    "BusUrlError",
    "InProcessBroker",
    "InProcessBus",
    "Login",
    "MalformedMessage",
    "MissionKey",
    "MissionKeyError",
    "MqttBus",
    "Subscription",
    "UnsupportedVersion",
    "Will",
    "decode",
    "encode",
    "open_bus",
    "tls_context",
]


def open_bus(
    url: str | None = None,
    *,
    client_id: str | None = None,
    will: Will | None = None,
    birth: Birth | None = None,
    queue_size: int = DEFAULT_QUEUE_SIZE,
    broker: InProcessBroker | None = None,
    identity: str | None = None,
    mission_key: MissionKey | None = None,
    **mqtt_options: Any,
) -> Bus:
    """A bus client to enter with ``async with``: in-process when ``url`` is None, else MQTT.

    ``will`` is published for the client if it vanishes, ``birth`` each time it connects.
    ``identity``: the client publishes only as this identity, on its topics (MQTT: default the
    ``login``'s user name). ``mission_key``: seal what it sends, take only what is sealed.

    ``broker`` shares one in-process broker between clients (in-process only); ``mqtt_options``
    are ``MqttBus`` keywords (qos, backoff, connect_timeout_s, op_timeout_s, tls_context, ...).
    A bad URL raises ``BusUrlError`` (both a ConfigError and a BusError) here, before any I/O.
    """
    if url is None:
        if mqtt_options:
            raise TypeError(f"options for MQTT given to the in-process bus: {sorted(mqtt_options)}")
        return InProcessBus(
            broker,
            client_id=client_id,
            will=will,
            birth=birth,
            queue_size=queue_size,
            identity=identity,
            mission_key=mission_key,
        )
    if broker is not None:
        raise TypeError("an in-process broker was given with an MQTT URL")
    return MqttBus(
        url,
        client_id=client_id,
        will=will,
        birth=birth,
        queue_size=queue_size,
        identity=identity,
        mission_key=mission_key,
        **mqtt_options,
    )
