"""The in-process bus (the default): clients of one ``InProcessBroker`` in one event loop.

It keeps MQTT's semantics so that code moves between the buses unchanged: topic wildcards,
payloads encoded and validated by the codec on receipt, per-subscription bounded queues,
retained messages, a birth published as a client opens and a last will published for a client
whose context exits on an error.
"""

from __future__ import annotations

import asyncio
import itertools
import logging

from app.adapters.bus.base import DEFAULT_QUEUE_SIZE, Birth, Bus, Will
from app.adapters.bus.codec import MalformedMessage
from app.adapters.bus.signing import MissionKey
from app.runtime.ports.messages import Message
from app.runtime.ports.topics import Topic, TopicFilter

log = logging.getLogger(__name__)
_ids = itertools.count(1)
_MAX_ROUTES = 4096  # topic names whose receivers a broker remembers


class InProcessBroker:
    """Routes payloads between the in-process clients that share it."""

    def __init__(self, *, share_decoded: bool = True) -> None:
        """``share_decoded``: a payload routed to several clients is validated once and the
        (frozen) message shared (``Bus._ingest``); False validates it in every client, as a
        broker between processes must (kept for ``benchmarks.bench_bus`` to compare)."""
        self._clients: list[InProcessBus] = []
        self._retained: dict[str, bytes] = {}
        self._share_decoded = share_decoded
        # per topic name, the clients with filters that match it and those filters, worked
        # out on the first payload and forgotten whenever a client or a filter comes or goes
        self._routes: dict[str, list[tuple[InProcessBus, tuple[TopicFilter, ...]]]] = {}

    def _join(self, client: InProcessBus) -> None:
        self._clients.append(client)
        self._routes.clear()

    def _leave(self, client: InProcessBus) -> None:
        if client in self._clients:
            self._clients.remove(client)
        self._routes.clear()

    def _filters_changed(self) -> None:
        self._routes.clear()

    def _route_of(self, topic: str) -> list[tuple[InProcessBus, tuple[TopicFilter, ...]]]:
        route = self._routes.get(topic)
        if route is None:
            if len(self._routes) >= _MAX_ROUTES:  # a flood of topic names stays bounded
                self._routes.clear()
            route = []
            for client in self._clients:
                matched = tuple(f for f in client.topic_filters if f.matches(topic))
                if matched:
                    route.append((client, matched))
            self._routes[topic] = route
        return route

    def route(self, topic: str, payload: bytes, *, retain: bool = False) -> None:
        """Hand a payload to every client that has subscribed to its topic (the matching is
        done here, once per topic name, not by every client for every payload). A retained
        payload is also kept for later subscribers (an empty one clears the topic's)."""
        if retain:
            if payload:
                self._retained[topic] = payload
            else:
                self._retained.pop(topic, None)
        decoded: dict[bytes, Message | MalformedMessage] | None = (
            {} if self._share_decoded else None
        )
        for client, filters in self._route_of(topic):
            client._ingest(topic, payload, filters, decoded=decoded)

    def retained(self, topic_filter: TopicFilter) -> list[tuple[str, bytes]]:
        """The retained payloads on the topics ``topic_filter`` matches."""
        return [(t, p) for t, p in self._retained.items() if topic_filter.matches(t)]


class InProcessBus(Bus):
    """A client of an in-process broker (a private one unless ``broker`` is given)."""

    def __init__(
        self,
        broker: InProcessBroker | None = None,
        *,
        client_id: str | None = None,
        will: Will | None = None,
        birth: Birth | None = None,
        queue_size: int = DEFAULT_QUEUE_SIZE,
        identity: str | None = None,
        mission_key: MissionKey | None = None,
    ) -> None:
        super().__init__(
            client_id=client_id or f"inproc-{next(_ids)}",
            queue_size=queue_size,
            identity=identity,
            mission_key=mission_key,
        )
        self.broker = broker if broker is not None else InProcessBroker()
        self.will = will
        self.birth = birth

    async def _start(self) -> None:
        self.broker._join(self)
        if self.birth is not None:
            birth = self.birth
            self.broker.route(
                birth.topic.value, self._wire(birth.topic, birth.message), retain=birth.retain
            )
            self._counts["published"] += 1

    async def _stop(self, *, crashed: bool) -> None:
        self.broker._leave(self)
        if crashed and self.will is not None:
            log.info("bus %s exited on an error: publishing its will", self.client_id)
            self.broker.route(
                self.will.topic.value,
                self._wire(self.will.topic, self.will.message),
                retain=self.will.retain,
            )

    async def _send(self, topic: Topic, payload: bytes, qos: int | None, retain: bool) -> bool:
        self.broker.route(topic.value, payload, retain=retain)
        await asyncio.sleep(0)  # yield like a network publish, so a publishing loop cannot starve
        return True

    async def _add_filter(self, topic_filter: TopicFilter) -> None:
        self.broker._filters_changed()
        for topic, payload in self.broker.retained(topic_filter):
            self._ingest(topic, payload, [topic_filter])

    async def _remove_filter(self, topic_filter: TopicFilter) -> None:
        self.broker._filters_changed()

    def inject_raw(self, topic: str, payload: bytes) -> None:
        """Route raw bytes as if a foreign client had published them (fault injection)."""
        self.broker.route(topic, payload)
