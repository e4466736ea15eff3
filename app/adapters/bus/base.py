"""The publish/subscribe interface that both buses implement, and their shared receive path.

    async with open_bus(None) as bus:                      # or open_bus("mqtt://host:1883")
        async with bus.subscribe("standoff/v1/status/+") as statuses:
            await bus.publish(topics.status(0), VehicleStatus(...))
            async for topic, message in statuses:
                ...

Every payload goes through the codec on both buses; a payload that does not decode is logged,
counted in ``bus.stats`` and dropped, never raised into the consumer. So is a well-formed
message that its topic does not permit (``topics.refusal``: a sender, kind or vehicle other
than the topic's): the identity rule lives in one place and both buses apply it here. Each drop
is counted by reason in ``bus.drops`` and logged rate-limited (``DropLog``). Each subscription
has a bounded queue; when a slow consumer lets it fill, the oldest message is dropped and
counted (the freshest data is what a control loop wants).

A bus given an ``identity`` (the client's login on an authenticating broker) also refuses to
publish anything but its own messages on its own topics (``BusError``). A bus given a
``mission_key`` seals every payload it sends and takes only payloads sealed with that key,
fresh (``app.adapters.bus.signing``: for a broker the operator does not control).
"""

from __future__ import annotations

import abc
import asyncio
import collections
import dataclasses
import functools
import logging
from collections.abc import Iterable, Mapping
from types import TracebackType
from typing import Self

from app.adapters.bus import codec, signing
from app.errors import BusError
from app.runtime.ports import topics
from app.runtime.ports.messages import Message
from app.runtime.ports.topics import Topic, TopicFilter, as_filter, as_topic

log = logging.getLogger(__name__)

DEFAULT_QUEUE_SIZE = 256


@dataclasses.dataclass(frozen=True, slots=True)
class BusStats:
    """Counters of one bus client since it was opened."""

    published: int = 0  # messages this client sent
    received: int = 0  # payloads that arrived for at least one of its subscriptions
    delivered: int = 0  # (message, subscription) pairs queued for a consumer
    dropped: int = 0  # messages pushed out of a full subscription queue
    malformed: int = 0  # payloads that did not decode (garbled, bad schema, non-finite)
    wrong_version: int = 0  # well-formed payloads of another schema version
    unsent: int = 0  # QoS 0 messages not sent because the broker was out of reach (MQTT)
    reconnects: int = 0  # connections after the first one (MQTT: the broker came back)
    refused: int = 0  # messages not believed: the identity rule, a seal (``Bus.drops``: why)
    denied: int = 0  # QoS 1/2 publishes of this client the broker refused (its ACL; MQTT 5)


MALFORMED = "malformed"
WRONG_VERSION = "wrong_version"
DROP_REASONS = (MALFORMED, WRONG_VERSION, *topics.REFUSALS, *signing.REASONS)
"""Why a received payload is dropped before any consumer sees it (the keys of ``Bus.drops``)."""


class DropLog:
    """Logs dropped messages without letting a flood of them flood the log.

    Each (reason, sender, topic) is logged at its 1st, 10th, 100th, ... drop, with the count;
    at most ``max_keys`` such keys are remembered, the rest share one (a sender that varies its
    name or topic cannot grow the table or the log). No clock: rate-limited by count.
    """

    def __init__(self, client_id: str, max_keys: int = 256) -> None:
        self.client_id = client_id
        self.max_keys = max_keys
        self._seen: dict[tuple[str, str, str], int] = {}

    def dropped(self, reason: str, sender: str, topic: str, detail: object) -> None:
        key = (reason, sender, topic)
        if key not in self._seen and len(self._seen) >= self.max_keys:
            key = (reason, "*", "*")
        count = self._seen.get(key, 0) + 1
        self._seen[key] = count
        if count == 10 ** (len(str(count)) - 1):  # 1, 10, 100, ...
            log.warning(
                "bus %s: dropped a message on %r from %r (%s, %d so far): %s",
                self.client_id,
                topic[:120],
                sender[:64],
                reason,
                count,
                str(detail)[:300],
            )


@dataclasses.dataclass(frozen=True, slots=True)
class Will:
    """A message the bus publishes for a client that dies without closing (MQTT last will)."""

    topic: Topic
    message: Message
    qos: int = 1
    retain: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "topic", as_topic(self.topic))
        if self.qos not in (0, 1, 2):
            raise ValueError(f"qos must be 0, 1 or 2, got {self.qos!r}")


Birth = Will
"""A message the MQTT bus publishes itself each time it connects (``MqttBus(birth=...)``): the
fields of a last will, for the opposite moment. With ``retain=True`` (and a retained will on
the same topic) the broker always holds whether the client is there, for whoever subscribes
later."""


class BusClosed(BusError):
    """The bus is not open (not entered yet, or already closed)."""


@functools.lru_cache(maxsize=4096)  # a mission has a few dozen topics; any flood is bounded
def _topic(name: str) -> Topic:
    """``Topic(name)``, checked once per name (a Topic is frozen: one is shared)."""
    return Topic(name)


def _decode(
    payload: bytes, decoded: dict[bytes, Message | codec.MalformedMessage] | None
) -> Message:
    """``codec.decode``, through ``decoded`` (see ``Bus._ingest``) where given: a payload met
    before gives the same message, or raises the same error, without validating it again."""
    if decoded is None:
        return codec.decode(payload)
    known = decoded.get(payload)
    if known is None:
        try:
            known = codec.decode(payload)
        except codec.MalformedMessage as exc:  # UnsupportedVersion is one too
            known = exc
        decoded[payload] = known
    if isinstance(known, codec.MalformedMessage):
        raise known
    return known


class Subscription:
    """The messages on one topic filter: enter it, then ``async for topic, message in it``.

    Iteration ends when the subscription or its bus is closed. Not for sharing between tasks.
    """

    def __init__(self, bus: Bus, topic_filter: TopicFilter, queue_size: int) -> None:
        if queue_size < 1:
            raise ValueError(f"queue_size must be at least 1, got {queue_size}")
        self.topic_filter = topic_filter
        self.queue_size = queue_size
        self.dropped = 0
        self._bus = bus
        self._queue: collections.deque[tuple[Topic, Message]] = collections.deque()
        self._wakeup = asyncio.Event()
        self._state = "new"  # new -> open -> closed

    def __repr__(self) -> str:
        return f"Subscription({self.topic_filter.value!r}, {self._state})"

    async def __aenter__(self) -> Self:
        if self._state != "new":
            raise BusError(f"{self!r} cannot be entered twice")
        self._state = "open"
        try:
            await self._bus._attach(self)
        except BaseException:
            self._end()
            raise
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()

    async def close(self) -> None:
        """Unsubscribe; messages already queued can still be read, then iteration ends."""
        if self._state == "open":
            self._end()
            await self._bus._detach(self)

    def __aiter__(self) -> Self:
        return self

    async def __anext__(self) -> tuple[Topic, Message]:
        if self._state == "new":
            raise BusError(f"enter {self!r} with 'async with' before reading it")
        while not self._queue:
            if self._state == "closed":
                raise StopAsyncIteration
            self._wakeup.clear()
            await self._wakeup.wait()
        return self._queue.popleft()

    def pending(self) -> int:
        """How many messages are queued, unread."""
        return len(self._queue)

    def drain(self) -> list[tuple[Topic, Message]]:
        """Every message queued, oldest first, without waiting: for a reader that takes a
        topic's messages at its own pace (an agent takes its teammates' statuses once per
        control tick) instead of waking for each."""
        if self._state == "new":
            raise BusError(f"enter {self!r} with 'async with' before reading it")
        taken = list(self._queue)
        self._queue.clear()
        return taken

    # called by the bus
    def _offer(self, topic: Topic, message: Message) -> bool:
        """Queue a message; return False when it pushed out the oldest one."""
        kept = True
        if len(self._queue) >= self.queue_size:
            self._queue.popleft()
            self.dropped += 1
            kept = False
        self._queue.append((topic, message))
        self._wakeup.set()
        return kept

    def _end(self) -> None:
        self._state = "closed"
        self._wakeup.set()


class Bus(abc.ABC):
    """One client of a publish/subscribe bus with MQTT topic semantics; an async context manager."""

    def __init__(
        self,
        *,
        client_id: str,
        queue_size: int = DEFAULT_QUEUE_SIZE,
        identity: str | None = None,
        mission_key: signing.MissionKey | None = None,
    ) -> None:
        if queue_size < 1:
            raise ValueError(f"queue_size must be at least 1, got {queue_size}")
        self.client_id = client_id
        self.identity = identity
        self.mission_key = mission_key
        self._sealer = signing.Sealer(mission_key) if mission_key is not None else None
        self._counters: dict[tuple[str, str], int] = {}  # (topic, sender) -> last seal taken
        self._default_queue_size = queue_size
        self._subscriptions: dict[TopicFilter, list[Subscription]] = {}
        self._counts: collections.Counter[str] = collections.Counter()
        self._drops: collections.Counter[str] = collections.Counter()
        self._drop_log = DropLog(client_id)
        self._open = False

    @property
    def stats(self) -> BusStats:
        return BusStats(**{f.name: self._counts[f.name] for f in dataclasses.fields(BusStats)})

    @property
    def drops(self) -> Mapping[str, int]:
        """Received payloads dropped before any consumer saw them, by reason (``DROP_REASONS``:
        ``malformed``, ``wrong_version``, the identity rule's ``wrong_sender``,
        ``wrong_vehicle``, ``wrong_kind``, ``unknown_topic``, and with a mission key
        ``unsigned``, ``bad_signature``, ``replayed``); a copy, every reason present."""
        return {reason: self._drops[reason] for reason in DROP_REASONS}

    @property
    def is_open(self) -> bool:
        return self._open

    @property
    def topic_filters(self) -> tuple[TopicFilter, ...]:
        """The filters this client has subscriptions on, now."""
        return tuple(self._subscriptions)

    async def __aenter__(self) -> Self:
        if self._open:
            raise BusError(f"bus {self.client_id!r} is already open")
        await self._start()
        self._open = True
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if not self._open:
            return
        self._open = False
        for subs in self._subscriptions.values():
            for sub in subs:
                sub._end()
        self._subscriptions.clear()
        await self._stop(crashed=exc is not None and not isinstance(exc, asyncio.CancelledError))

    async def aclose(self) -> None:
        """Close the bus (as leaving ``async with`` cleanly does); closing twice is harmless."""
        await self.__aexit__(None, None, None)

    async def publish(
        self,
        topic: Topic | str,
        message: Message,
        *,
        qos: int | None = None,
        retain: bool = False,
    ) -> None:
        """Send ``message`` on ``topic`` (a name, no wildcards). Raises BusError on failure.

        A publish is a suspension point on both buses (it yields to the event loop). At QoS 0
        (at most once) a message the transport cannot send now is dropped and counted in
        ``stats.unsent``, not waited for (see ``MqttBus``). ``retain``: the broker keeps the
        topic's last retained message and hands it to every later subscriber (for a state,
        such as a client's presence, rather than an event).
        """
        if not isinstance(message, Message):
            raise TypeError(f"publish takes a bus Message, got {type(message).__name__}")
        topic = as_topic(topic)
        if not self._open:
            raise BusClosed(f"bus {self.client_id!r} is not open; cannot publish on {topic}")
        if self.identity is not None:
            self._check_own(topic, message)
        sent = await self._send(topic, self._wire(topic, message), qos, retain)
        self._counts["published" if sent else "unsent"] += 1

    def subscribe(
        self, topic_filter: TopicFilter | Topic | str, *, queue_size: int | None = None
    ) -> Subscription:
        """A subscription to ``topic_filter`` (``+`` and ``#`` wildcards); enter it to start it.

        Once ``async with bus.subscribe(f)`` has entered, every message published after that
        and matching ``f`` is delivered to it (subject to its queue bound).
        """
        size = self._default_queue_size if queue_size is None else queue_size
        return Subscription(self, as_filter(topic_filter), size)

    def _wire(self, topic: Topic, message: Message) -> bytes:
        """``message`` as the bytes to send on ``topic``: encoded, and sealed with a key."""
        payload = codec.encode(message)
        return payload if self._sealer is None else self._sealer.seal(topic.value, payload)

    def _check_own(self, topic: Topic, message: Message) -> None:
        """A client with an identity publishes only as itself, only on its own topics."""
        identity, kind = self.identity, topics.kind_of(message)
        if message.sender != identity:
            raise BusError(
                f"bus {self.client_id!r} is {identity!r}: it cannot publish a {kind}"
                f" from {message.sender!r} (on {topic})"
            )
        reason = topics.refusal(topic, message)
        if reason is not None:
            raise BusError(
                f"bus {self.client_id!r}: {identity!r} may not publish a {kind} on {topic}"
                f" ({reason}); receivers would drop it"
            )

    # shared machinery
    async def _attach(self, sub: Subscription) -> None:
        if not self._open:
            raise BusClosed(f"bus {self.client_id!r} is not open; cannot subscribe")
        subs = self._subscriptions.setdefault(sub.topic_filter, [])
        subs.append(sub)
        if len(subs) == 1:
            try:
                await self._add_filter(sub.topic_filter)
            except BaseException:
                self._remove(sub)
                raise

    async def _detach(self, sub: Subscription) -> None:
        if self._remove(sub) and self._open:
            await self._remove_filter(sub.topic_filter)

    def _remove(self, sub: Subscription) -> bool:
        """Forget ``sub``; True when it was the last one on its filter."""
        subs = self._subscriptions.get(sub.topic_filter, [])
        if sub in subs:
            subs.remove(sub)
            if not subs:
                del self._subscriptions[sub.topic_filter]
                return True
        return False

    def _ingest(
        self,
        topic_name: str,
        payload: bytes,
        filters: Iterable[TopicFilter] | None = None,
        decoded: dict[bytes, Message | codec.MalformedMessage] | None = None,
    ) -> None:
        """Decode a received payload and queue it for the matching subscriptions.

        ``filters``, when the transport knows them, are the filters the payload arrived for;
        otherwise the topic is matched against every subscription. ``decoded``: what the codec
        made of payloads already decoded for other clients of one delivery (the in-process
        broker's), looked up by the payload's bytes after unsealing and filled in here: every
        client still unseals, refuses and checks freshness for itself, but one payload is
        validated once, not once per client (messages are frozen). Never raises on bad input.
        """
        if filters is None:
            targets = [f for f in self._subscriptions if f.matches(topic_name)]
        else:
            targets = [f for f in set(filters) if f in self._subscriptions]
        if not targets:
            return
        self._counts["received"] += 1
        counter = None
        if self.mission_key is not None:
            opened = signing.unseal(self.mission_key, topic_name, payload)
            if isinstance(opened, str):
                self._drop(opened, "?", topic_name, "not sealed with the mission key")
                return
            payload, counter = opened.payload, opened.counter
        try:
            topic = _topic(topic_name)
            message = _decode(payload, decoded)
        except codec.UnsupportedVersion as exc:
            self._drop(WRONG_VERSION, "?", topic_name, exc)
            return
        except (codec.MalformedMessage, BusError) as exc:
            self._drop(MALFORMED, "?", topic_name, exc)
            return
        reason = topics.refusal(topic, message)
        if reason is not None:
            self._drop(
                reason, message.sender, topic_name, f"a {topics.kind_of(message)} not believed"
            )
            return
        if counter is not None and not self._fresh(topic, message, counter):
            self._drop(signing.REPLAYED, message.sender, topic_name, "older than one taken")
            return
        for topic_filter in targets:
            for sub in self._subscriptions[topic_filter]:
                self._counts["delivered"] += 1
                if not sub._offer(topic, message):
                    self._counts["dropped"] += 1
                    log.debug("bus %s: %r full, dropped its oldest", self.client_id, sub)

    def _fresh(self, topic: Topic, message: Message, counter: int) -> bool:
        """Whether a sealed message is no older than the last one taken from its sender on its
        topic (the same one again is: a retained copy, or one per overlapping filter). Not on
        presence topics: a last will is sealed as its client connects, before what it outlives."""
        bound = topics.binding(topic)
        if bound is not None and bound.kind == "link":
            return True
        key = (topic.value, message.sender)
        if counter < self._counters.get(key, 0):
            return False
        self._counters[key] = counter
        return True

    def _drop(self, reason: str, sender: str, topic_name: str, detail: object) -> None:
        self._counts[reason if reason in (MALFORMED, WRONG_VERSION) else "refused"] += 1
        self._drops[reason] += 1
        self._drop_log.dropped(reason, sender, topic_name, detail)

    # transport
    @abc.abstractmethod
    async def _start(self) -> None:
        """Connect; raise BusError when that is impossible."""

    @abc.abstractmethod
    async def _stop(self, *, crashed: bool) -> None:
        """Disconnect; ``crashed`` when the context exits on an error (the last will applies)."""

    @abc.abstractmethod
    async def _send(self, topic: Topic, payload: bytes, qos: int | None, retain: bool) -> bool:
        """Put a payload on the wire; False when a QoS 0 payload was dropped (no connection)."""

    @abc.abstractmethod
    async def _add_filter(self, topic_filter: TopicFilter) -> None:
        """Start receiving ``topic_filter`` (and its retained messages); return once messages
        published after it arrive."""

    @abc.abstractmethod
    async def _remove_filter(self, topic_filter: TopicFilter) -> None:
        """Stop receiving ``topic_filter``."""
