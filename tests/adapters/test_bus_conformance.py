"""One conformance suite, run over both buses: in-process and MQTT on a real mosquitto."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import aiomqtt
import pytest
from pydantic import ValidationError

from app.adapters.bus import (
    Birth,
    Bus,
    BusClosed,
    InProcessBroker,
    InProcessBus,
    Subscription,
    Will,
    encode,
    open_bus,
)
from app.runtime.ports import topics
from app.runtime.ports.messages import (
    Command,
    GlobalEstimate,
    LinkState,
    LocalEstimate,
    Message,
    MissionState,
    TargetObservation,
    VehicleStatus,
)
from app.runtime.ports.topics import Topic, TopicError
from tests.support.mosquitto import Mosquitto

WAIT_S = 5.0
EYE = tuple(tuple(float(i == j) for j in range(6)) for i in range(6))


@dataclasses.dataclass
class Harness:
    """How a test reaches one bus implementation: open clients, inject foreign raw bytes."""

    name: str
    open: Callable[..., Bus]
    inject_raw: Callable[[str, bytes], Awaitable[None]]


@pytest.fixture(params=["inproc", "mqtt"])
async def harness(request: pytest.FixtureRequest) -> AsyncIterator[Harness]:
    if request.param == "inproc":
        broker = InProcessBroker()

        async def inject_inproc(topic: str, payload: bytes) -> None:
            broker.route(topic, payload)

        yield Harness("inproc", lambda **kw: open_bus(None, broker=broker, **kw), inject_inproc)
        return
    mosquitto: Mosquitto = request.getfixturevalue("mosquitto")
    async with aiomqtt.Client("127.0.0.1", mosquitto.port, identifier="raw-injector") as raw:

        async def inject_mqtt(topic: str, payload: bytes) -> None:
            await raw.publish(topic, payload, qos=1)

        yield Harness(
            "mqtt",
            lambda **kw: open_bus(mosquitto.url, connect_timeout_s=WAIT_S, **kw),
            inject_mqtt,
        )


def status(vehicle: int = 0, t_s: float = 0.0) -> VehicleStatus:
    return VehicleStatus(
        sender=f"agent-{vehicle + 1}",
        t_s=t_s,
        vehicle=vehicle,
        east_m=10.0,
        north_m=-20.5,
        alt_m=100.0,
        course_rad=1.25,
        speed_m_s=14.0,
        phase_rad=-0.5,
        stage="adjust",
        link="ok",
        healthy=True,
    )


def observation(t_s: float, vehicle: int = 0) -> TargetObservation:
    return TargetObservation(
        sender="ground",
        t_s=t_s,
        sensor="sim",
        vehicle=vehicle,
        east_m=t_s,
        north_m=2.0,
        sigma_m=math.sqrt(10.0),
    )


EXAMPLES: list[tuple[Topic, Message]] = [
    (topics.observation(2), observation(3.5, vehicle=2)),
    (
        topics.local_estimate(1),
        LocalEstimate(sender="agent-2", t_s=4.0, vehicle=1, x=(1, 2, 3, 4, 5, 6), P=EYE),
    ),
    (
        topics.GLOBAL_ESTIMATE,
        GlobalEstimate(
            sender="ground", t_s=4.0, x=(0.0,) * 6, P=EYE, beta={0: 0.25, 1: 0.25, 2: 0.25}
        ),
    ),
    (
        topics.MISSION,
        MissionState(sender="ground", t_s=5.0, stage="track", active=(0, 2), spacing_rad=math.pi),
    ),
    (topics.status(0), status(0, 6.0)),
    (topics.link(1), LinkState(sender="agent-2", t_s=0.0, online=False, vehicle=1)),
    (topics.command(), Command(sender="ground", t_s=7.0, command="hold")),
]


async def take(sub: Subscription, n: int) -> list[tuple[Topic, Message]]:
    """The next ``n`` messages of ``sub``, failing after WAIT_S."""
    got = []
    async with asyncio.timeout(WAIT_S):
        for _ in range(n):
            got.append(await anext(sub))
    return got


class Fence:
    """A marker subscription: once a marker sent after some messages has come back, the
    receiving bus has dispatched those messages too (one publisher, in order)."""

    def __init__(self, receiver: Bus, sender: Bus) -> None:
        self.sender = sender
        self.sub = receiver.subscribe("fence/+")
        self.count = 0

    async def __aenter__(self) -> Fence:
        await self.sub.__aenter__()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.sub.close()

    async def settle(self) -> None:
        self.count += 1
        topic = Topic(f"fence/{self.count}")
        await self.sender.publish(topic, LinkState(sender="fence", t_s=self.count, online=True))
        async with asyncio.timeout(WAIT_S):
            async for got_topic, _ in self.sub:
                if got_topic == topic:
                    return


async def test_round_trip_of_every_message_type(harness: Harness) -> None:
    async with (
        harness.open(client_id="pub") as pub,
        harness.open(client_id="sub") as sub_bus,
        sub_bus.subscribe("standoff/v1/#") as sub,
    ):
        for topic, message in EXAMPLES:
            await pub.publish(topic, message)
        got = await take(sub, len(EXAMPLES))
    assert got == EXAMPLES
    assert [type(m) for _, m in got] == [type(m) for _, m in EXAMPLES]
    assert pub.stats.published == len(EXAMPLES)
    assert sub_bus.stats.delivered == len(EXAMPLES)
    assert sub_bus.stats.malformed == 0


async def test_a_client_receives_its_own_messages(harness: Harness) -> None:
    async with harness.open() as bus, bus.subscribe(topics.MISSION) as sub:
        await bus.publish(topics.MISSION, EXAMPLES[3][1])
        assert await take(sub, 1) == [(topics.MISSION, EXAMPLES[3][1])]


# on topics outside the mission's layout (standoff/v1/...), where the identity rule would
# refuse a status published on every one of them (tests/adapters/test_bus_identity.py)
WILDCARD_CASES: dict[str, list[str]] = {
    "plain/v1/status/+": ["plain/v1/status/0", "plain/v1/status/7"],
    "plain/v1/+/0": ["plain/v1/status/0", "plain/v1/obs/0"],
    "plain/v1/status/#": [
        "plain/v1/status",
        "plain/v1/status/0",
        "plain/v1/status/7",
        "plain/v1/status/0/link",
    ],
    "+/+/obs/+": ["plain/v1/obs/0"],
    "#": [
        "plain/v1/status",
        "plain/v1/status/0",
        "plain/v1/status/7",
        "plain/v1/status/0/link",
        "plain/v1/obs/0",
        "other/v1/status/0",
        "fence/1",  # the Fence's marker
    ],
    "plain/v1/status/0": ["plain/v1/status/0"],
}
PUBLISHED_TOPICS = [
    "plain/v1/status",
    "plain/v1/status/0",
    "plain/v1/status/7",
    "plain/v1/status/0/link",
    "plain/v1/obs/0",
    "other/v1/status/0",
]


async def test_wildcards_deliver_exactly_the_matching_topics(harness: Harness) -> None:
    async with (
        harness.open(client_id="pub") as pub,
        harness.open(client_id="sub") as sub_bus,
        Fence(sub_bus, pub) as fence,
    ):
        subs = {f: sub_bus.subscribe(f) for f in WILDCARD_CASES}
        for sub in subs.values():
            await sub.__aenter__()
        for i, name in enumerate(PUBLISHED_TOPICS):
            await pub.publish(name, status(0, float(i)))
        await fence.settle()
        for topic_filter, expected in WILDCARD_CASES.items():
            got = [topic.value for topic, _ in await take(subs[topic_filter], len(expected))]
            assert got == expected, topic_filter
            assert subs[topic_filter].pending() == 0, f"{topic_filter} got extra messages"
    assert sub_bus.stats.malformed == 0


async def test_overlapping_filters_each_get_one_copy(harness: Harness) -> None:
    async with (
        harness.open() as pub,
        harness.open() as sub_bus,
        Fence(sub_bus, pub) as fence,
        sub_bus.subscribe("standoff/v1/#") as a,
        sub_bus.subscribe("standoff/v1/status/+") as b,
    ):
        await pub.publish(topics.status(3), status(3))
        await fence.settle()
        assert a.pending() == 1
        assert b.pending() == 1


async def test_order_is_kept_per_topic(harness: Harness) -> None:
    n = 200
    async with (
        harness.open() as pub,
        harness.open() as sub_bus,
        sub_bus.subscribe(topics.observation(0), queue_size=n) as sub,
    ):
        for i in range(n):
            await pub.publish(topics.observation(0), observation(float(i)))
        got = await take(sub, n)
    assert [m.t_s for _, m in got] == [float(i) for i in range(n)]


async def test_many_subscribers_each_get_every_message(harness: Harness) -> None:
    n = 20
    async with harness.open() as pub, harness.open() as a, harness.open() as b:
        subs = [a.subscribe(topics.ALL_OBSERVATIONS) for _ in range(3)]
        subs += [b.subscribe("standoff/v1/obs/#") for _ in range(2)]
        subs.append(pub.subscribe(topics.observation(1)))
        for sub in subs:
            await sub.__aenter__()
        for i in range(n):
            await pub.publish(topics.observation(1), observation(float(i), vehicle=1))
        for sub in subs:
            assert [m.t_s for _, m in await take(sub, n)] == [float(i) for i in range(n)]
        for sub in subs:
            await sub.close()


async def test_who_gets_a_topic_follows_the_subscriptions_as_they_change(
    harness: Harness,
) -> None:
    # the in-process broker remembers each topic's receivers: a filter or a client that comes
    # or goes after a topic's first message must change who gets the next one
    async with harness.open() as pub, harness.open() as a, Fence(a, pub) as fence:
        async with a.subscribe(topics.observation(1)) as first:
            await pub.publish(topics.observation(1), observation(1.0, vehicle=1))
            await fence.settle()
            async with a.subscribe(topics.ALL_OBSERVATIONS) as wider:
                await pub.publish(topics.observation(1), observation(2.0, vehicle=1))
                await fence.settle()
                assert [m.t_s for _, m in await take(wider, 1)] == [2.0]
                async with harness.open() as b, b.subscribe(topics.observation(1)) as late:
                    await pub.publish(topics.observation(1), observation(3.0, vehicle=1))
                    await fence.settle()
                    assert [m.t_s for _, m in await take(late, 1)] == [3.0]
                assert b.stats.delivered == 1
            await pub.publish(topics.observation(1), observation(4.0, vehicle=1))
            await fence.settle()
            assert [m.t_s for _, m in await take(first, 4)] == [1.0, 2.0, 3.0, 4.0]
            assert [m.t_s async for _, m in wider] == [3.0]
        await pub.publish(topics.observation(1), observation(5.0, vehicle=1))
        await fence.settle()
        assert a.stats.delivered == 4 + 2 + fence.count  # first's, wider's and the fences'


async def test_closed_subscription_ends_and_gets_nothing_more(harness: Harness) -> None:
    async with harness.open() as pub, harness.open() as sub_bus, Fence(sub_bus, pub) as fence:
        keep = sub_bus.subscribe(topics.ALL_STATUS)
        async with keep, sub_bus.subscribe(topics.ALL_STATUS) as leaving:
            await pub.publish(topics.status(0), status(0, 1.0))
            await fence.settle()
            await leaving.close()
            await pub.publish(topics.status(0), status(0, 2.0))
            await fence.settle()
            # what was queued before the close is still readable; then the iteration ends
            assert [m.t_s async for _, m in leaving] == [1.0]
            assert [m.t_s for _, m in await take(keep, 2)] == [1.0, 2.0]


async def test_closing_the_bus_ends_every_subscription_and_refuses_publishing(
    harness: Harness,
) -> None:
    async with harness.open() as bus:
        sub = bus.subscribe(topics.ALL)
        await sub.__aenter__()
        reader_waiting = asyncio.Event()

        async def drain() -> list[Any]:
            reader_waiting.set()
            return [item async for item in sub]

        async with asyncio.TaskGroup() as tg:
            reader = tg.create_task(drain())
            await reader_waiting.wait()
            await bus.aclose()
        assert reader.result() == []
        assert not bus.is_open
        with pytest.raises(BusClosed):
            await bus.publish(topics.MISSION, EXAMPLES[3][1])
        with pytest.raises(BusClosed):
            await bus.subscribe(topics.ALL).__aenter__()


async def test_garbage_is_dropped_counted_and_the_loop_goes_on(harness: Harness) -> None:
    good = status(4, 1.0)
    bad_payloads = [
        b"\x00\xff\xfe garbage",
        b"{not json",
        b"[1, 2, 3]",
        b'{"v": 2, "kind": "status"}',  # fields missing
        b'{"v": 2, "kind": "teleport", "sender": "x", "t_s": 0}',  # unknown kind
        encode(good).replace(b'"east_m":10.0', b'"east_m":NaN'),
        encode(good).replace(b'"east_m":10.0', b'"east_m":1e999'),
        encode(good).replace(b'"east_m":10.0', b'"east_m":"10.0"'),
        encode(good).replace(b'"detail":""', b'"detail":"","extra":1'),
        b"",
    ]
    async with harness.open() as bus, bus.subscribe(topics.ALL_STATUS) as sub:
        for payload in bad_payloads:
            await harness.inject_raw("standoff/v1/status/4", payload)
        await harness.inject_raw("standoff/v1/status/4", encode(good).replace(b'"v":2', b'"v":1'))
        await harness.inject_raw("standoff/v1/status/4", encode(good))
        assert await take(sub, 1) == [(topics.status(4), good)]
        assert bus.stats.malformed == len(bad_payloads)
        assert bus.stats.wrong_version == 1
        assert bus.stats.delivered == 1
        assert sub.pending() == 0


def test_non_finite_numbers_never_make_a_message() -> None:
    for bad in (math.nan, math.inf, -math.inf):
        with pytest.raises(ValidationError):
            observation(bad)
        with pytest.raises(ValidationError):
            LocalEstimate(sender="a", t_s=0.0, vehicle=0, x=(0, 0, 0, 0, 0, bad), P=EYE)


async def test_a_full_queue_drops_the_oldest_and_counts_it(harness: Harness) -> None:
    async with (
        harness.open() as pub,
        harness.open() as sub_bus,
        Fence(sub_bus, pub) as fence,
        sub_bus.subscribe(topics.observation(0), queue_size=3) as sub,
    ):
        for i in range(10):
            await pub.publish(topics.observation(0), observation(float(i)))
        await fence.settle()
        assert sub.pending() == 3
        assert sub.dropped == 7
        assert sub_bus.stats.dropped == 7
        assert [m.t_s for _, m in await take(sub, 3)] == [7.0, 8.0, 9.0]


async def test_bad_topics_are_refused_before_anything_is_sent(harness: Harness) -> None:
    async with harness.open() as bus:
        for bad in ("a/+/b", "a/#", "", "$SYS/x", "a\x00b"):
            with pytest.raises(TopicError):
                await bus.publish(bad, EXAMPLES[3][1])
        for bad_filter in ("a/#/b", "a/b#", "a/+b", ""):
            with pytest.raises(TopicError, match="topic filter"):
                bus.subscribe(bad_filter)
        assert bus.stats.published == 0


async def test_will_is_published_when_a_client_exits_on_an_error(harness: Harness) -> None:
    will = Will(topics.link(2), LinkState(sender="agent-3", t_s=0.0, online=False, vehicle=2))
    async with harness.open() as watcher, watcher.subscribe(topics.ALL_LINKS) as links:
        with pytest.raises(RuntimeError, match="agent failed"):
            async with harness.open(client_id="agent-3", will=will):
                raise RuntimeError("agent failed")
        assert await take(links, 1) == [(will.topic, will.message)]


async def test_a_clean_close_does_not_publish_the_will(harness: Harness) -> None:
    will = Will(topics.link(2), LinkState(sender="agent-3", t_s=0.0, online=False, vehicle=2))
    async with harness.open() as watcher, watcher.subscribe(topics.ALL_LINKS) as links:
        async with harness.open(client_id="agent-3", will=will):
            pass
        marker = LinkState(sender="agent-4", t_s=1.0, online=True, vehicle=3)
        await watcher.publish(topics.link(3), marker)
        assert await take(links, 1) == [(topics.link(3), marker)]


async def test_a_retained_message_reaches_later_subscribers(harness: Harness) -> None:
    first = LinkState(sender="agent-2", t_s=0.0, online=True, vehicle=1)
    latest = LinkState(sender="agent-2", t_s=1.0, online=False, vehicle=1)
    event = LinkState(sender="agent-3", t_s=2.0, online=True, vehicle=2)
    async with harness.open() as pub:  # QoS 1: each is with the broker once publish returns
        await pub.publish(topics.link(1), first, qos=1, retain=True)
        await pub.publish(topics.link(1), latest, qos=1, retain=True)
        await pub.publish(topics.link(2), event, qos=1)  # not retained: gone for later ones
        async with harness.open() as late, late.subscribe(topics.ALL_LINKS) as links:
            assert await take(links, 1) == [(topics.link(1), latest)]
            marker = LinkState(sender="agent-4", t_s=3.0, online=True, vehicle=3)
            await pub.publish(topics.link(3), marker)
            assert await take(links, 1) == [(topics.link(3), marker)]


async def test_the_birth_is_published_as_the_client_opens(harness: Harness) -> None:
    birth = Birth(topics.link(2), LinkState(sender="agent-3", t_s=0.0, online=True, vehicle=2))
    async with (
        harness.open() as watcher,
        watcher.subscribe(topics.ALL_LINKS) as links,
        harness.open(client_id="agent-3", birth=birth) as agent,
    ):
        assert await take(links, 1) == [(birth.topic, birth.message)]
        assert agent.stats.published == 1


def test_in_process_is_the_default() -> None:
    assert isinstance(open_bus(None), InProcessBus)
    assert isinstance(open_bus(), InProcessBus)


async def test_the_in_process_broker_validates_a_payload_once_for_all_its_clients(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # every client of one broker gets the same (frozen) message, validated once; a garbled
    # payload is still dropped and counted by each client that subscribed to it
    from app.adapters.bus import codec

    calls: list[bytes] = []
    real = codec.decode

    def counted(payload: bytes) -> Message:
        calls.append(bytes(payload))
        return real(payload)

    monkeypatch.setattr(codec, "decode", counted)
    for share, decodes in ((True, 1), (False, 3)):
        calls.clear()
        broker = InProcessBroker(share_decoded=share)
        clients = [InProcessBus(broker, client_id=f"c{i}") for i in range(3)]
        async with contextlib.AsyncExitStack() as stack:
            subs = []
            for bus in clients:
                await stack.enter_async_context(bus)
                subs.append(await stack.enter_async_context(bus.subscribe(topics.ALL_STATUS)))
            good = status(2, 1.0)
            broker.route(topics.status(2).value, encode(good))
            got = [(await take(sub, 1))[0] for sub in subs]
            assert [message for _, message in got] == [good] * 3
            assert (got[0][1] is got[1][1] is got[2][1]) == share
            assert len(calls) == decodes
            broker.route(topics.status(2).value, b"{not json")
            assert [bus.stats.malformed for bus in clients] == [1, 1, 1]
            assert len(calls) == 2 * decodes
            assert all(sub.pending() == 0 for sub in subs)
