"""MQTT-only behaviour on a real mosquitto: restarts, last will, URLs, auth, TLS, back-off."""

from __future__ import annotations

import asyncio
import ssl
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import aiomqtt
import paho.mqtt.publish
import pytest

from app.adapters.bus import Backoff, Birth, BrokerUrl, BusUrlError, MqttBus, Will, codec, open_bus
from app.adapters.bus.mqtt import READ_BURST, CancelSafeClient
from app.errors import BusError, ConfigError
from app.runtime.ports import topics
from app.runtime.ports.messages import LinkState
from tests.adapters.test_bus_conformance import WAIT_S, observation, take
from tests.support.mosquitto import Mosquitto, free_port, refused_port

REPO = Path(__file__).resolve().parents[2]


async def test_broker_restart_is_survived_by_subscriber_and_publisher(
    mosquitto: Mosquitto,
) -> None:
    fast = Backoff(initial_s=0.05, max_s=0.5)
    async with (
        MqttBus(mosquitto.url, client_id="sub", backoff=fast) as sub_bus,
        MqttBus(mosquitto.url, client_id="pub", backoff=fast) as pub,
        sub_bus.subscribe(topics.ALL_OBSERVATIONS) as sub,
    ):
        await pub.publish(topics.observation(0), observation(1.0))
        assert [m.t_s for _, m in await take(sub, 1)] == [1.0]

        mosquitto.restart()
        async with asyncio.timeout(WAIT_S):
            await sub_bus.wait_for_connection(2)  # reconnected and re-subscribed
        # the publisher has not necessarily reconnected yet: a QoS 1 publish waits for it
        await pub.publish(topics.observation(0), observation(2.0), qos=1)
        assert [m.t_s for _, m in await take(sub, 1)] == [2.0]
        assert pub.connections == 2
        assert (pub.stats.reconnects, pub.losses) == (1, 1)
        assert sub_bus.connected
        assert sub_bus.stats.malformed == 0


async def test_a_subscriber_that_fell_behind_reads_its_backlog_at_once(
    mosquitto: Mosquitto,
) -> None:
    """Messages that arrived while the subscriber's loop was busy are all read at its next turn
    and meet the subscription's bounded queue there (the newest kept, the rest counted as
    dropped), instead of one message per event-loop iteration, every one in turn, ever later.
    """
    backlog = READ_BURST + 16  # more than one burst
    async with (
        MqttBus(mosquitto.url, client_id="slow") as slow,
        slow.subscribe(topics.ALL_OBSERVATIONS, queue_size=4) as sub,
    ):
        # published from outside the loop while it is blocked, as a loaded process is
        paho.mqtt.publish.multiple(
            [
                (str(topics.observation(0)), codec.encode(observation(float(k))), 0, False)
                for k in range(backlog)
            ],
            hostname="127.0.0.1",
            port=mosquitto.port,
        )
        time.sleep(0.3)  # noqa: ASYNC251  # the broker passes them on meanwhile
        for _ in range(4):  # four turns of the event loop
            await asyncio.sleep(0)
        assert slow.stats.received == backlog
        assert (slow.stats.dropped, sub.dropped) == (backlog - 4, backlog - 4)
        newest = [float(k) for k in range(backlog - 4, backlog)]
        assert [m.t_s for _, m in await take(sub, 4)] == newest


async def test_publish_fails_with_bus_error_when_the_broker_stays_away(
    mosquitto: Mosquitto,
) -> None:
    async with MqttBus(mosquitto.url, op_timeout_s=0.5, backoff=Backoff(0.05, 2, 0.1)) as bus:
        mosquitto.stop()
        error: BusError | None = None
        # the first publishes may still see the dying connection; a later one must fail
        for i in range(50):
            try:
                await bus.publish(topics.observation(0), observation(float(i)), qos=1)
            except BusError as exc:
                error = exc
                break
        assert error is not None
        assert "not connected to the broker" in str(error) or "publish on" in str(error)


async def test_a_qos_0_publish_with_the_broker_away_is_dropped_at_once(
    mosquitto: Mosquitto,
) -> None:
    # a loop that publishes as it controls (an agent's status at every tick) must not stall
    # for as long as the broker is away: at most once means it may be lost, and it is counted
    async with MqttBus(mosquitto.url, op_timeout_s=30.0, backoff=Backoff(0.05, 2, 0.1)) as bus:
        mosquitto.stop()
        async with asyncio.timeout(WAIT_S):
            while bus.connected:  # the loss seen by the bus
                await bus.wait_for_change()
        async with asyncio.timeout(1.0):  # far below op_timeout_s
            for i in range(20):
                await bus.publish(topics.observation(0), observation(float(i)))
        assert bus.stats.unsent == 20
        assert bus.stats.published == 0
        assert bus.losses == 1


async def test_a_retained_birth_is_heard_after_a_broker_restart(mosquitto: Mosquitto) -> None:
    # A broker going down may publish its clients' wills ("offline"); the birth, published on
    # every connection and retained, says "online" again to a subscriber that comes back
    # before the client (live) or after it (the retained copy).
    fast = Backoff(initial_s=0.05, max_s=0.5)
    birth = Birth(
        topics.link(3), LinkState(sender="agent-4", t_s=0.0, online=True, vehicle=3), retain=True
    )
    async with (
        MqttBus(mosquitto.url, client_id="watcher", backoff=fast) as watcher,
        watcher.subscribe(topics.ALL_LINKS) as links,
        MqttBus(mosquitto.url, client_id="agent-4", birth=birth, backoff=fast) as bus,
    ):
        assert await take(links, 1) == [(birth.topic, birth.message)]
        mosquitto.restart()
        async with asyncio.timeout(WAIT_S):
            await watcher.wait_for_connection(2)
            await bus.wait_for_connection(2)
        assert await take(links, 1) == [(birth.topic, birth.message)]
        assert bus.stats.published == 2  # the birth, once per connection
        assert bus.stats.reconnects == 1


WILL_CLIENT = textwrap.dedent(
    """
    import asyncio, sys
    from app.adapters.bus import MqttBus, Will
    from app.runtime.ports import topics
    from app.runtime.ports.messages import LinkState

    async def main(url):
        will = Will(topics.link(5), LinkState(sender="agent-6", t_s=0.0, online=False, vehicle=5))
        async with MqttBus(url, client_id="agent-6", will=will) as bus:
            online = LinkState(sender="agent-6", t_s=0.0, online=True, vehicle=5)
            await bus.publish(topics.link(5), online)
            print("ready", flush=True)
            await asyncio.Event().wait()

    asyncio.run(main(sys.argv[1]))
    """
)


async def test_last_will_is_delivered_when_a_client_process_dies(mosquitto: Mosquitto) -> None:
    async with (
        MqttBus(mosquitto.url, client_id="ground") as ground,
        ground.subscribe(topics.ALL_LINKS) as links,
    ):
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            WILL_CLIENT,
            mosquitto.url,
            cwd=REPO,
            stdout=subprocess.PIPE,
        )
        try:
            assert proc.stdout is not None
            async with asyncio.timeout(20):
                assert (await proc.stdout.readline()).strip() == b"ready"
            [(_, hello)] = await take(links, 1)
            assert isinstance(hello, LinkState)
            assert hello.online
            proc.kill()  # SIGKILL: no DISCONNECT packet, the broker must publish the will
            await proc.wait()
            [(topic, will)] = await take(links, 1)
        finally:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()
    assert topic == topics.link(5)
    assert will == LinkState(sender="agent-6", t_s=0.0, online=False, vehicle=5)


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("mqtt://localhost", BrokerUrl("localhost", 1883)),
        ("mqtt://127.0.0.1:1884", BrokerUrl("127.0.0.1", 1884)),
        ("mqtts://broker.example", BrokerUrl("broker.example", 8883, tls=True)),
        (
            "mqtt://ground:s3cret@10.0.0.2:1883",
            BrokerUrl("10.0.0.2", 1883, False, "ground", "s3cret"),
        ),
        ("mqtt://us%40er:p%3Ass%2Fw@host:1", BrokerUrl("host", 1, False, "us@er", "p:ss/w")),
        ("mqtt://user@host", BrokerUrl("host", 1883, False, "user", None)),
        ("mqtt://user:@host", BrokerUrl("host", 1883, False, "user", "")),
        ("mqtt://[::1]:1883/", BrokerUrl("::1", 1883)),
    ],
)
def test_broker_urls_are_parsed(url: str, expected: BrokerUrl) -> None:
    assert BrokerUrl.parse(url) == expected


def test_the_password_is_never_shown() -> None:
    url = BrokerUrl.parse("mqtt://ground:s3cret@host:1883")
    assert "s3cret" not in str(url)
    assert "s3cret" not in repr(url)
    with pytest.raises(BusUrlError) as info:
        BrokerUrl.parse("http://ground:s3cret@host:1883")
    assert "s3cret" not in str(info.value)


@pytest.mark.parametrize(
    ("url", "reason"),
    [
        ("http://host:1883", "scheme must be mqtt:// or mqtts://"),
        ("host:1883", "scheme must be"),
        ("mqtt://", "no host"),
        ("mqtt://:1883", "no host"),
        ("mqtt://host:99999", "out of range"),
        ("mqtt://host:abc", "bad broker URL"),
        ("mqtt://host:0", "port 0"),
        ("mqtt://host:1883/topic", "only mqtt"),
        ("mqtt://host:1883?qos=1", "only mqtt"),
        ("mqtt://:pw@host", "password without a user"),
    ],
)
def test_bad_urls_are_refused_with_the_reason(url: str, reason: str) -> None:
    with pytest.raises(BusUrlError, match=reason) as info:
        open_bus(url)
    assert isinstance(info.value, ConfigError)
    assert isinstance(info.value, BusError)


async def test_an_unreachable_broker_is_a_bus_error_naming_it() -> None:
    with refused_port() as port:
        bus = open_bus(f"mqtt://127.0.0.1:{port}", connect_timeout_s=0.5)
        with pytest.raises(
            BusError, match=f"cannot connect to the broker at mqtt://127.0.0.1:{port}"
        ):
            async with bus:
                pass
    assert not bus.is_open


async def test_reconnect_back_off_grows_to_its_cap_on_the_injected_clock() -> None:
    waits: list[float] = []

    async def fake_sleep(seconds: float) -> None:
        waits.append(seconds)
        await asyncio.sleep(0)

    with refused_port() as port:
        bus = MqttBus(
            f"mqtt://127.0.0.1:{port}",
            backoff=Backoff(initial_s=1.0, factor=2.0, max_s=8.0),
            connect_timeout_s=0.3,
            sleep=fake_sleep,
        )
        with pytest.raises(BusError):
            async with bus:
                pass
    assert len(waits) >= 6
    assert waits[:6] == [1.0, 2.0, 4.0, 8.0, 8.0, 8.0]


@pytest.mark.parametrize(
    "client_class",
    [
        CancelSafeClient,
        pytest.param(
            aiomqtt.Client,
            marks=pytest.mark.xfail(
                sys.version_info < (3, 12),
                reason="asyncio.wait_for swallows the cancellation (CPython gh-86296)",
                strict=True,
            ),
        ),
    ],
)
async def test_a_wait_for_an_acknowledgement_lets_a_cancellation_through(
    client_class: type[aiomqtt.Client],
) -> None:
    # The acknowledgement arrives and the waiting task is cancelled in the same moment (each
    # interleaving of the two within a few loop turns): once cancel() is accepted, the task
    # must end cancelled, not carry on with its loop as if nothing had happened.
    client = client_class("127.0.0.1", free_port())  # never connected: only its wait is used
    for turns in range(4):
        acked = asyncio.Event()
        carried_on = asyncio.Event()

        async def publisher(acked: asyncio.Event, carried_on: asyncio.Event) -> None:
            await client._wait_for(acked.wait(), timeout=5.0)
            carried_on.set()

        task = asyncio.create_task(publisher(acked, carried_on))
        await asyncio.sleep(0)  # it now waits for the acknowledgement
        acked.set()
        for _ in range(turns):
            await asyncio.sleep(0)
        if task.cancel():
            with pytest.raises(asyncio.CancelledError):
                await task
            assert not carried_on.is_set(), f"cancellation swallowed after {turns} turns"
        else:  # it had already finished: too late to cancel
            await task
            assert carried_on.is_set()


async def test_a_wait_for_an_acknowledgement_ends_when_the_connection_is_lost() -> None:
    # an acknowledgement never comes on a lost connection: a publish waiting for one (a QoS 0
    # write, a PUBACK) gives up at once rather than sit out its timeout in a control loop
    client = CancelSafeClient("127.0.0.1", free_port())  # never connected: only its wait is used
    acked = asyncio.Event()
    waiting = asyncio.create_task(client._wait_for(acked.wait(), timeout=30.0))
    await asyncio.sleep(0)
    client._disconnected.set_result(None)  # what aiomqtt does when paho reports the loss
    async with asyncio.timeout(1.0):
        with pytest.raises(aiomqtt.MqttError, match="Connection lost"):
            await waiting


async def test_a_wait_for_an_acknowledgement_still_times_out() -> None:
    client = CancelSafeClient("127.0.0.1", free_port(), timeout=0.05)
    with pytest.raises(aiomqtt.MqttError, match="timed out"):
        await client._wait_for(asyncio.Event().wait(), timeout=None)


def test_backoff_rejects_nonsense() -> None:
    with pytest.raises(ValueError, match="initial_s"):
        Backoff(initial_s=0.0)
    with pytest.raises(ValueError, match="initial_s"):
        Backoff(initial_s=2.0, max_s=1.0)


@pytest.fixture
def password_broker(tmp_path: Path) -> Iterator[Mosquitto]:
    """A broker that only lets in ``ground`` with password ``s3cret``."""
    passwords = tmp_path / "passwd"
    passwords.write_text("", encoding="utf-8")
    subprocess.run(
        ["mosquitto_passwd", "-b", str(passwords), "ground", "s3cret"], check=True, timeout=10
    )
    broker = Mosquitto(tmp_path, anonymous=False, extra_config=f"password_file {passwords}\n")
    broker.start()
    yield broker
    broker.stop()


async def test_user_and_password_from_the_url_are_used(password_broker: Mosquitto) -> None:
    port = password_broker.port
    async with (
        open_bus(f"mqtt://ground:s3cret@127.0.0.1:{port}") as bus,
        bus.subscribe(topics.ALL_OBSERVATIONS) as sub,
    ):
        await bus.publish(topics.observation(0), observation(1.0))
        assert [m.t_s for _, m in await take(sub, 1)] == [1.0]
    for bad in ("ground:wrong@", "", "nobody:x@"):
        bus = open_bus(f"mqtt://{bad}127.0.0.1:{port}", connect_timeout_s=WAIT_S)
        # refused at once with the broker's reason, not retried until the timeout
        async with asyncio.timeout(WAIT_S / 2):
            with pytest.raises(BusError, match=r"refused the connection: .*(user name|authori)"):
                await bus.__aenter__()
        assert not bus.is_open


@pytest.fixture
def tls_broker(tmp_path: Path) -> Iterator[tuple[Mosquitto, Path]]:
    """A broker on TLS only, with a fresh self-signed certificate for 127.0.0.1."""
    cert, key = tmp_path / "broker.crt", tmp_path / "broker.key"
    subprocess.run(
        [
            "openssl",
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "1",
            "-subj",
            "/CN=127.0.0.1",
            "-addext",
            "subjectAltName=IP:127.0.0.1",
            "-keyout",
            str(key),
            "-out",
            str(cert),
        ],
        check=True,
        capture_output=True,
        timeout=30,
    )
    broker = Mosquitto(tmp_path, tls=True, extra_config=f"certfile {cert}\nkeyfile {key}\n")
    broker.start()
    yield broker, cert
    broker.stop()


@pytest.mark.slow
async def test_mqtts_connects_over_tls_and_checks_the_certificate(
    tls_broker: tuple[Mosquitto, Path],
) -> None:
    broker, cert = tls_broker
    trusting = ssl.create_default_context(cafile=str(cert))
    async with (
        open_bus(broker.url, tls_context=trusting) as bus,
        bus.subscribe(topics.ALL_OBSERVATIONS) as sub,
    ):
        await bus.publish(topics.observation(0), observation(1.0))
        assert [m.t_s for _, m in await take(sub, 1)] == [1.0]
    # the system's CAs do not know this self-signed broker: refused
    with pytest.raises(BusError, match="cannot connect"):
        async with open_bus(broker.url, connect_timeout_s=1.0):
            pass
    # and plain MQTT on the TLS port does not get through either
    with pytest.raises(BusError, match="cannot connect"):
        async with open_bus(f"mqtt://127.0.0.1:{broker.port}", connect_timeout_s=1.0):
            pass


def test_a_tls_context_needs_mqtts() -> None:
    with pytest.raises(BusUrlError, match="mqtts"):
        MqttBus("mqtt://host", tls_context=ssl.create_default_context())


def test_will_values_are_checked() -> None:
    with pytest.raises(ValueError, match="qos"):
        Will(topics.link(0), LinkState(sender="a", t_s=0.0, online=False), qos=3)
