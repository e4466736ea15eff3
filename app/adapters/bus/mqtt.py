"""The MQTT bus: one aiomqtt 2.x client kept connected (back-off, re-subscribe) for its lifetime.

MQTT 5 is used so that each filter carries a subscription identifier: a message is handed to
exactly the subscriptions it arrived for, even when filters overlap (a broker may send one copy
per matching filter). Vendor errors become ``BusError`` with the cause chained. Every wait inside
aiomqtt is bounded with ``asyncio.timeout`` instead of its ``asyncio.wait_for`` (see
``CancelSafeClient``): on Python 3.11 the latter can swallow a cancellation.

Received messages go from the socket straight into the subscriptions' bounded queues, every
packet already in the socket at once (``CancelSafeClient``): a process that falls behind then
drops its oldest messages there instead of reading every one, ever later.

On a broker that authenticates, the client logs in as its identity (``Login``: user name and
password, from a file or an environment variable; optionally a TLS client certificate,
``tls_context``). A publish the broker refuses (its ACL; MQTT 5 tells a QoS 1/2 publisher so)
is counted in ``stats.denied`` and logged.
"""

from __future__ import annotations

import asyncio
import dataclasses
import itertools
import logging
import math
import os
import secrets
import select
import ssl
import urllib.parse
from collections.abc import Awaitable, Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar

import aiomqtt
import paho.mqtt.client as paho
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties
from paho.mqtt.reasoncodes import ReasonCode

from app.adapters.bus.base import DEFAULT_QUEUE_SIZE, Birth, Bus, BusClosed, Will
from app.adapters.bus.signing import MissionKey
from app.errors import BusError, ConfigError
from app.runtime.ports.topics import Topic, TopicFilter

log = logging.getLogger(__name__)

Sleep = Callable[[float], Awaitable[None]]
QoS = Literal[0, 1, 2]
T = TypeVar("T")
Deliver = Callable[[str, bytes, Properties | None], None]
"""Where a received message goes: its topic, payload and MQTT 5 properties."""

READ_BURST = 64
"""At most this many MQTT packets are read each time the socket is readable (the event loop
then runs its other callbacks before the next burst)."""


class BusUrlError(ConfigError, BusError):
    """A broker URL that cannot be used; the message shows the URL (without its password)."""


@dataclasses.dataclass(frozen=True, slots=True)
class BrokerUrl:
    """``mqtt://[user[:password]@]host[:port]`` (port 1883) or ``mqtts://`` (TLS, port 8883)."""

    host: str
    port: int
    tls: bool = False
    username: str | None = None
    password: str | None = dataclasses.field(default=None, repr=False)

    @classmethod
    def parse(cls, url: str) -> BrokerUrl:
        shown = _redact(url)
        try:
            parts = urllib.parse.urlsplit(url)
            port = parts.port
        except ValueError as exc:
            raise BusUrlError(f"bad broker URL {shown!r}: {exc}") from exc
        if parts.scheme not in ("mqtt", "mqtts"):
            raise BusUrlError(
                f"bad broker URL {shown!r}: the scheme must be mqtt:// or mqtts://"
                " (e.g. mqtt://localhost:1883)"
            )
        if not parts.hostname:
            raise BusUrlError(f"bad broker URL {shown!r}: no host")
        if parts.path not in ("", "/") or parts.query or parts.fragment:
            raise BusUrlError(
                f"bad broker URL {shown!r}: only mqtt[s]://[user:password@]host[:port] is accepted"
            )
        if port == 0:
            raise BusUrlError(f"bad broker URL {shown!r}: port 0")
        if parts.password is not None and not parts.username:
            raise BusUrlError(f"bad broker URL {shown!r}: a password without a user name")
        tls = parts.scheme == "mqtts"
        return cls(
            host=parts.hostname,
            port=port if port is not None else (8883 if tls else 1883),
            tls=tls,
            username=urllib.parse.unquote(parts.username) if parts.username else None,
            password=urllib.parse.unquote(parts.password) if parts.password is not None else None,
        )

    def __str__(self) -> str:
        user = f"{self.username}:***@" if self.username else ""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'mqtts' if self.tls else 'mqtt'}://{user}{host}:{self.port}"


def _redact(url: str) -> str:
    head, at, tail = url.rpartition("@")
    if not at or "://" not in head:
        return url
    scheme, _, userinfo = head.partition("://")
    user, colon, _ = userinfo.partition(":")
    return f"{scheme}://{user}{':***' if colon else ''}@{tail}"


@dataclasses.dataclass(frozen=True, slots=True)
class Login:
    """A client's credentials on a broker that authenticates: its user name (the client's
    identity, e.g. ``ground`` or ``agent-1``) and password. Never shown in ``repr``."""

    username: str
    password: str | None = dataclasses.field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not self.username or any(c in self.username for c in "\x00/+#"):
            raise BusUrlError(f"bad broker user name {self.username!r}")

    @classmethod
    def load(
        cls,
        username: str,
        *,
        password_file: Path | str | None = None,
        password_env: str | None = None,
        environ: Mapping[str, str] | None = None,
    ) -> Login:
        """The login of ``username`` with its password read from ``password_file`` (its first
        line) or the environment variable ``password_env`` (not both); ``BusUrlError`` (a
        ConfigError) naming the file or variable when it cannot be read or is empty."""
        if password_file is not None and password_env is not None:
            raise BusUrlError(
                "give the broker password by a file or an environment variable, not both"
            )
        password: str | None = None
        if password_file is not None:
            try:
                text = Path(password_file).read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as exc:
                raise BusUrlError(
                    f"cannot read the broker password file {password_file}: {exc}"
                ) from exc
            password = text.splitlines()[0] if text.strip() else ""
            if not password:
                raise BusUrlError(f"the broker password file {password_file} is empty")
        elif password_env is not None:
            password = (os.environ if environ is None else environ).get(password_env)
            if not password:
                raise BusUrlError(
                    f"the environment variable {password_env} (broker password) is not set"
                )
        return cls(username, password)


def tls_context(
    ca_file: Path | str | None = None,
    cert_file: Path | str | None = None,
    key_file: Path | str | None = None,
) -> ssl.SSLContext:
    """A TLS context that trusts ``ca_file`` (default: the system's CAs) and, with
    ``cert_file`` (and ``key_file``, unless the key is in the certificate file), shows the
    broker this client certificate (mosquitto ``require_certificate``; with
    ``use_identity_as_username`` its common name is then the login). ``BusUrlError`` on a file
    that cannot be loaded."""
    if key_file is not None and cert_file is None:
        raise BusUrlError("a TLS client key was given without its certificate")
    try:
        context = ssl.create_default_context(cafile=None if ca_file is None else str(ca_file))
        if cert_file is not None:
            context.load_cert_chain(str(cert_file), None if key_file is None else str(key_file))
    except (OSError, ssl.SSLError) as exc:
        raise BusUrlError(
            f"cannot load the TLS files ({ca_file}, {cert_file}, {key_file}): {exc}"
        ) from exc
    return context


@dataclasses.dataclass(frozen=True, slots=True)
class Backoff:
    """Reconnect delays: ``initial_s``, times ``factor`` after each failure, at most ``max_s``."""

    initial_s: float = 0.1
    factor: float = 2.0
    max_s: float = 5.0

    def __post_init__(self) -> None:
        if not (0.0 < self.initial_s <= self.max_s) or self.factor < 1.0:
            raise ValueError(f"need 0 < initial_s <= max_s and factor >= 1, got {self}")

    def delays(self) -> Iterator[float]:
        delay = self.initial_s
        while True:
            yield delay
            delay = min(delay * self.factor, self.max_s)


# CONNACK reasons that retrying cannot fix: MQTT 3.1.1 return codes and MQTT 5 reason codes
_REFUSALS = {1, 2, 4, 5, 0x84, 0x85, 0x86, 0x87, 0x8C}


def _is_refusal(exc: BaseException) -> bool:
    rc = getattr(exc, "rc", None)
    return isinstance(exc, aiomqtt.MqttCodeError) and getattr(rc, "value", rc) in _REFUSALS


class CancelSafeClient(aiomqtt.Client):
    """aiomqtt's client with its one waiting primitive made safe to cancel, and given up when
    the connection is lost.

    aiomqtt waits for every acknowledgement (CONNACK, SUBACK, UNSUBACK, PUBACK, the write of a
    QoS 0 publish that could not go out at once, the end of a disconnect) in ``_wait_for``, with
    ``asyncio.wait_for``. On Python 3.11 ``wait_for`` swallows a cancellation that arrives in the
    loop iteration in which the awaited acknowledgement completes (CPython gh-86296, fixed in
    3.12 by building ``wait_for`` on ``asyncio.timeout``): it returns the result, and the task
    carries on as if it had never been cancelled. A task group cancels each child once, so such
    a child (an agent loop that publishes at every tick) then runs for ever and the process
    never stops. ``asyncio.timeout`` runs the wait inside the caller's task and lets the
    cancellation through; a timeout is still aiomqtt's ``MqttError``.

    aiomqtt also leaves a wait for an acknowledgement pending when the connection drops (it
    never comes, on a clean session): the caller, a control loop's publish, would sit out the
    whole timeout. Here the wait ends, with ``MqttError``, as soon as the client has seen the
    connection go.

    And aiomqtt reads one MQTT packet each time the socket is readable (paho's ``loop_read``
    reads one unless QoS 1/2 messages are in flight), i.e. one per event-loop iteration, then
    queues it in an unbounded queue that its message iterator empties one message per few
    iterations. A process that cannot keep up (an agent on a loaded machine: measured 18-41 s
    behind the broker) leaves its backlog in the socket and the broker, out of reach of the
    subscriptions' bounded queues, and reads every old message in order. With ``deliver``, each
    readable event reads every packet already there (at most ``READ_BURST``) and hands each
    message to ``deliver`` at once, without aiomqtt's queue; ``messages`` then only ends, with
    ``MqttError``, when the connection is lost.
    """

    def __init__(
        self,
        *args: Any,
        deliver: Deliver | None = None,
        on_denied: Callable[[ReasonCode], None] | None = None,
        **kwargs: Any,
    ) -> None:
        self._deliver = deliver
        self._on_denied = on_denied
        super().__init__(*args, **kwargs)

    def _on_publish(
        self,
        client: paho.Client,
        userdata: Any,
        mid: int,
        reason_code: ReasonCode,
        properties: Properties,
    ) -> None:
        # aiomqtt ignores the reason code: a QoS 1/2 publish the broker refused (MQTT 5 PUBACK
        # "not authorized", mosquitto's ACL) would look delivered
        if self._on_denied is not None and getattr(reason_code, "is_failure", False):
            self._on_denied(reason_code)
        super()._on_publish(client, userdata, mid, reason_code, properties)

    def _on_message(self, client: paho.Client, userdata: Any, message: paho.MQTTMessage) -> None:
        if self._deliver is None:
            super()._on_message(client, userdata, message)
            return
        try:
            topic = message.topic
        except UnicodeDecodeError:
            log.warning("dropped a message whose topic is not UTF-8")
            return
        self._deliver(topic, bytes(message.payload), getattr(message, "properties", None))

    def _on_socket_open(self, client: paho.Client, userdata: Any, sock: Any) -> None:
        if self._deliver is None:
            super()._on_socket_open(client, userdata, sock)
            return

        def read() -> None:
            try:
                for _ in range(READ_BURST):
                    if client.loop_read() != paho.MQTT_ERR_SUCCESS or not _readable(client):
                        break
            except Exception as exc:  # as aiomqtt's reader: a broken socket ends the connection
                if not self._disconnected.done():
                    self._disconnected.set_exception(exc)

        def create_misc_task() -> None:
            self._misc_task = self._loop.create_task(self._misc_loop())

        # paho calls this from the thread that connects (aiomqtt's executor)
        self._loop.call_soon_threadsafe(self._loop.add_reader, sock.fileno(), read)
        self._loop.call_soon_threadsafe(create_misc_task)

    # the signature is aiomqtt's (it passes ``timeout=``)
    async def _wait_for(self, fut: Awaitable[T], timeout: float | None) -> T:  # noqa: ASYNC109
        limit_s = self.timeout if timeout is None else timeout
        lost = self._disconnected
        ack = fut is not lost and fut is not self._connected  # not a connect or a disconnect
        try:
            async with asyncio.timeout(None if limit_s == math.inf else limit_s) as scope:
                if not ack:
                    return await fut
                waiting = True

                def give_up(_lost: asyncio.Future[None]) -> None:
                    if waiting and not scope.expired():
                        scope.reschedule(asyncio.get_running_loop().time())

                lost.add_done_callback(give_up)
                try:
                    return await fut
                finally:
                    waiting = False
                    lost.remove_done_callback(give_up)
        except TimeoutError:
            if ack and lost.done():
                raise aiomqtt.MqttError("Connection lost while waiting") from None
            raise aiomqtt.MqttError("Operation timed out") from None


def _readable(client: paho.Client) -> bool:
    """Whether the client's socket has more bytes to read now (decrypted ones too, for TLS)."""
    sock = client.socket()
    if sock is None:
        return False
    pending = getattr(sock, "pending", None)
    if pending is not None and pending() > 0:
        return True
    readable, _, _ = select.select([sock], [], [], 0.0)
    return bool(readable)


class MqttBus(Bus):
    """A client of an MQTT broker; open with ``async with``.

    Parameters
    ----------
    url
        ``mqtt://[user:password@]host[:port]`` or ``mqtts://...`` (TLS).
    client_id
        The MQTT client identifier (unique per broker; a second client with the same one
        pushes the first off). Generated when omitted.
    will
        Published by the broker when this client vanishes without closing (and by the bus
        itself when its context exits on an error).
    birth
        Published by the bus itself each time it connects, once its subscriptions are back
        (e.g. "online": a broker that went down may have published the will meanwhile).
    qos
        The QoS for publishes and subscriptions (0: at most once, 1: at least once).
    connect_timeout_s
        How long entering the bus waits for the first connection before raising BusError.
    op_timeout_s
        How long a subscribe or a QoS 1/2 publish waits, including for a lost connection to
        come back. A QoS 0 publish never waits for one: without a connection it is dropped
        and counted in ``stats.unsent`` (a loop that publishes as it controls must not stall
        for an outage; QoS 0 promises at most once).
    tls_context
        For ``mqtts://``: the SSL context (default: the system's trusted CAs; ``tls_context()``
        builds one with a CA file and a client certificate).
    login
        The user name and password to log in with (instead of the URL's; a URL naming another
        user is refused). On a broker that authenticates, the login is the client's identity.
    identity
        The identity the client publishes as (default: the login's user name): the bus then
        refuses to publish a message from anyone else or on a topic not its own.
    mission_key
        Seal every payload with this key and take only payloads sealed with it
        (``app.adapters.bus.signing``).
    sleep
        The clock's sleep, used for the reconnect back-off (injectable for tests).
    """

    def __init__(
        self,
        url: BrokerUrl | str,
        *,
        client_id: str | None = None,
        will: Will | None = None,
        birth: Birth | None = None,
        qos: QoS = 0,
        queue_size: int = DEFAULT_QUEUE_SIZE,
        backoff: Backoff = Backoff(),
        connect_timeout_s: float = 10.0,
        op_timeout_s: float = 5.0,
        keepalive_s: int = 10,
        tls_context: ssl.SSLContext | None = None,
        login: Login | None = None,
        identity: str | None = None,
        mission_key: MissionKey | None = None,
        sleep: Sleep = asyncio.sleep,
    ) -> None:
        super().__init__(
            client_id=client_id or f"standoff-{secrets.token_hex(4)}",
            queue_size=queue_size,
            identity=identity if identity is not None else (login.username if login else None),
            mission_key=mission_key,
        )
        self.url = url if isinstance(url, BrokerUrl) else BrokerUrl.parse(url)
        if login is not None:
            if self.url.username not in (None, login.username):
                raise BusUrlError(
                    f"the broker URL {self.url} names user {self.url.username!r}, but this"
                    f" client logs in as {login.username!r}"
                )
            password = login.password if login.password is not None else self.url.password
            self.url = dataclasses.replace(self.url, username=login.username, password=password)
        if qos not in (0, 1, 2):
            raise ValueError(f"qos must be 0, 1 or 2, got {qos!r}")
        if tls_context is not None and not self.url.tls:
            raise BusUrlError(f"a TLS context was given for {self.url}; use mqtts://")
        self.will = will
        self.birth = birth
        self.qos: QoS = qos
        self.backoff = backoff
        self.connect_timeout_s = connect_timeout_s
        self.op_timeout_s = op_timeout_s
        self.keepalive_s = keepalive_s
        self._tls_context = tls_context
        self._sleep = sleep
        self._client: aiomqtt.Client | None = None
        self._connected = asyncio.Event()
        self._changed = asyncio.Event()  # set (and replaced) whenever _client changes
        self._task_group: asyncio.TaskGroup | None = None
        self._runner: asyncio.Task[None] | None = None
        self._last_error: BaseException | None = None
        self._filter_ids: dict[TopicFilter, int] = {}
        self._next_id = itertools.count(1)
        self.connections = 0  # successful connections so far (reconnects = connections - 1)
        self.losses = 0  # established connections lost so far

    def __repr__(self) -> str:
        return f"MqttBus({str(self.url)!r}, client_id={self.client_id!r})"

    # lifecycle
    async def _start(self) -> None:
        self._task_group = asyncio.TaskGroup()
        await self._task_group.__aenter__()
        self._runner = self._task_group.create_task(self._run(), name=f"mqtt-bus-{self.client_id}")
        try:
            async with asyncio.timeout(self.connect_timeout_s):
                while self._client is None and not self._runner.done():
                    await self._changed.wait()
        except TimeoutError as exc:
            await self._shutdown()
            raise BusError(
                f"cannot connect to the broker at {self.url} within {self.connect_timeout_s} s:"
                f" {self._last_error or 'no answer'}"
            ) from (self._last_error or exc)
        except BaseException:
            await self._shutdown()
            raise
        if self._client is None:  # the runner gave up: the broker refused us for good
            await self._shutdown()
            raise BusError(
                f"the broker at {self.url} refused the connection: {self._last_error}"
            ) from self._last_error

    async def _stop(self, *, crashed: bool) -> None:
        if crashed and self.will is not None and self._client is not None:
            # A crash that unwinds through ``async with`` still closes the socket politely, so
            # the broker would not send the will: send it ourselves.
            try:
                async with asyncio.timeout(self.op_timeout_s):
                    await self._client.publish(
                        self.will.topic.value,
                        self._wire(self.will.topic, self.will.message),
                        qos=self.will.qos,
                        retain=self.will.retain,
                    )
            except (aiomqtt.MqttError, TimeoutError) as exc:
                log.warning("bus %s: could not publish its will: %s", self.client_id, exc)
        await self._shutdown()

    async def _shutdown(self) -> None:
        if self._runner is not None:
            self._runner.cancel()
        if self._task_group is not None:
            task_group, self._task_group = self._task_group, None
            await task_group.__aexit__(None, None, None)
        self._runner = None

    def _make_client(self) -> CancelSafeClient:
        will = None
        if self.will is not None:
            will = aiomqtt.Will(
                topic=self.will.topic.value,
                payload=self._wire(self.will.topic, self.will.message),
                qos=self.will.qos,
                retain=self.will.retain,
            )
        tls_context = None
        if self.url.tls:
            tls_context = self._tls_context or ssl.create_default_context()
        return CancelSafeClient(
            self.url.host,
            self.url.port,
            deliver=self._receive,
            on_denied=self._denied,
            username=self.url.username,
            password=self.url.password,
            identifier=self.client_id,
            protocol=aiomqtt.ProtocolVersion.V5,
            will=will,
            clean_start=True,
            keepalive=self.keepalive_s,
            timeout=self.op_timeout_s,
            tls_context=tls_context,
            logger=log,
        )

    async def _run(self) -> None:
        """Connect, re-subscribe, read; on loss, wait the back-off and do it again."""
        delays = self.backoff.delays()
        while True:
            up = False
            try:
                async with self._make_client() as client:
                    for topic_filter in list(self._subscriptions):
                        await self._subscribe(client, topic_filter)
                    if self.birth is not None:
                        await self._announce(client, self.birth)
                    self.connections += 1
                    up = True
                    self._set_client(client)
                    delays = self.backoff.delays()
                    if self.connections > 1:
                        self._counts["reconnects"] += 1
                        log.info("bus %s: reconnected to %s", self.client_id, self.url)
                    async for _never in client.messages:  # messages go to _receive
                        pass
            except (aiomqtt.MqttError, BusError) as exc:
                self._last_error = exc
                if up:
                    self.losses += 1
                if self.connections == 0 and _is_refusal(exc):
                    log.error(
                        "bus %s: %s refused the connection: %s", self.client_id, self.url, exc
                    )
                    self._set_client(None)
                    return  # bad credentials will not get better by retrying
                log.warning(
                    "bus %s: connection to %s lost or refused: %s", self.client_id, self.url, exc
                )
            finally:
                self._set_client(None)
            await self._sleep(next(delays))

    async def _announce(self, client: aiomqtt.Client, birth: Birth) -> None:
        await client.publish(
            birth.topic.value,
            self._wire(birth.topic, birth.message),
            qos=birth.qos,
            retain=birth.retain,
            timeout=self.op_timeout_s,
        )
        self._counts["published"] += 1

    @property
    def connected(self) -> bool:
        """Whether the client is connected now, with its subscriptions in place."""
        return self._client is not None

    async def wait_for_connection(self, number: int = 1) -> None:
        """Wait until the ``number``-th successful connection (2 = the first reconnect) is up.

        Bound it with ``asyncio.timeout``; the back-off keeps retrying meanwhile.
        """
        while self.connections < number or self._client is None:
            await self._changed.wait()

    async def wait_for_change(self) -> None:
        """Wait until the connection is next lost or made (read ``connected``, ``connections``
        and ``losses`` then: counters, so that a watcher misses none)."""
        await self._changed.wait()

    def _set_client(self, client: aiomqtt.Client | None) -> None:
        self._client = client
        if client is None:
            self._connected.clear()
        else:
            self._connected.set()
        changed, self._changed = self._changed, asyncio.Event()
        changed.set()

    async def _await_change(self, client: aiomqtt.Client, deadline: float) -> bool:
        """Wait until the runner replaces ``client`` (a lost connection); False at the deadline."""
        try:
            async with asyncio.timeout_at(deadline):
                while self._client is client:
                    await self._changed.wait()
        except TimeoutError:
            return False
        return True

    def _denied(self, reason: ReasonCode) -> None:
        self._counts["denied"] += 1
        count = self._counts["denied"]
        if count == 10 ** (len(str(count)) - 1):  # 1st, 10th, 100th, ...
            log.warning(
                "bus %s: the broker at %s refused a publish (%s; %d so far): not a topic of"
                " this login's?",
                self.client_id,
                self.url,
                reason,
                count,
            )

    def _receive(self, topic: str, payload: bytes, properties: Properties | None) -> None:
        filters = None
        ids = getattr(properties, "SubscriptionIdentifier", None)
        if ids:
            by_id = {i: f for f, i in self._filter_ids.items()}
            filters = [by_id[i] for i in ids if i in by_id]
        self._ingest(topic, payload, filters)

    async def _connected_client(self, deadline: float) -> aiomqtt.Client:
        if not self.is_open and self._runner is None:
            raise BusClosed(f"bus {self.client_id!r} is not open")
        try:
            async with asyncio.timeout_at(deadline):
                while self._client is None:
                    await self._connected.wait()
        except TimeoutError as exc:
            raise BusError(
                f"not connected to the broker at {self.url}: {self._last_error or 'timed out'}"
            ) from exc
        return self._client

    async def _subscribe(self, client: aiomqtt.Client, topic_filter: TopicFilter) -> None:
        if topic_filter not in self._filter_ids:
            self._filter_ids[topic_filter] = next(self._next_id)
        properties = Properties(PacketTypes.SUBSCRIBE)  # type: ignore[no-untyped-call]
        properties.SubscriptionIdentifier = self._filter_ids[topic_filter]
        granted = await client.subscribe(
            topic_filter.value, qos=self.qos, properties=properties, timeout=self.op_timeout_s
        )
        codes = [getattr(code, "value", code) for code in granted]
        if any(code >= 0x80 for code in codes):
            raise BusError(
                f"the broker at {self.url} refused the subscription {topic_filter}:"
                f" {[str(code) for code in granted]}"
            )

    # transport operations; QoS 0 publishes on the connection there is, the others are retried
    # across a reconnect until op_timeout_s
    async def _send(self, topic: Topic, payload: bytes, qos: int | None, retain: bool) -> bool:
        qos = self.qos if qos is None else qos
        if qos == 0:
            return await self._send_at_most_once(topic, payload, retain)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.op_timeout_s
        while True:
            client = await self._connected_client(deadline)
            try:
                await client.publish(
                    topic.value,
                    payload,
                    qos=qos,
                    retain=retain,
                    timeout=max(deadline - loop.time(), 0.01),
                )
                return True
            except aiomqtt.MqttError as exc:
                if not await self._await_change(client, deadline):
                    raise BusError(f"publish on {topic} to {self.url} failed: {exc}") from exc
                log.info("bus %s: publish on %s failed (%s); retrying", self.client_id, topic, exc)

    async def _send_at_most_once(self, topic: Topic, payload: bytes, retain: bool) -> bool:
        if not self.is_open and self._runner is None:
            raise BusClosed(f"bus {self.client_id!r} is not open")
        client = self._client
        if client is None:
            await asyncio.sleep(0)  # a suspension point all the same
            return False
        try:
            await client.publish(
                topic.value, payload, qos=0, retain=retain, timeout=self.op_timeout_s
            )
        except aiomqtt.MqttError as exc:
            log.debug("bus %s: dropped a QoS 0 message on %s: %s", self.client_id, topic, exc)
            return False
        return True

    async def _add_filter(self, topic_filter: TopicFilter) -> None:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.op_timeout_s
        while True:
            client = await self._connected_client(deadline)
            try:
                await self._subscribe(client, topic_filter)
                return
            except aiomqtt.MqttError as exc:
                if not await self._await_change(client, deadline):
                    raise BusError(
                        f"subscribe to {topic_filter} at {self.url} failed: {exc}"
                    ) from exc
                # the connection dropped under us: try again on the next one

    async def _remove_filter(self, topic_filter: TopicFilter) -> None:
        self._filter_ids.pop(topic_filter, None)
        client = self._client
        if client is None:
            return  # not connected: it will not be re-subscribed either
        try:
            await client.unsubscribe(topic_filter.value, timeout=self.op_timeout_s)
        except aiomqtt.MqttError as exc:
            log.info("bus %s: unsubscribe from %s failed: %s", self.client_id, topic_filter, exc)
