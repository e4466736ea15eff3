"""Identity bound to topics: the rule (``topics.refusal``), both buses applying it on receipt,
a client with an identity publishing only as itself, and the shipped mosquitto configuration
(logins, per-client ACL) making a real broker refuse what a login may not publish."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import logging
import math
import subprocess
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from pathlib import Path

import aiomqtt
import pytest

from app.adapters.bus import (
    DROP_REASONS,
    Bus,
    InProcessBroker,
    Login,
    MalformedMessage,
    MissionKey,
    MissionKeyError,
    MqttBus,
    decode,
    encode,
    open_bus,
    tls_context,
)
from app.adapters.bus.broker_setup import (
    DEFAULT_DIR,
    acl_text,
    conf_text,
    password_hash,
    writable,
    write_team,
)
from app.adapters.bus.signing import Sealer
from app.config.mission import MissionConfig
from app.errors import BusError, ConfigError
from app.runtime.ports import topics
from app.runtime.ports.messages import (
    Command,
    GlobalEstimate,
    LinkState,
    LocalEstimate,
    Message,
    MissionEpoch,
    MissionState,
    TargetObservation,
    VehicleStatus,
)
from app.runtime.ports.topics import Topic
from tests.support.mosquitto import Mosquitto

WAIT_S = 5.0
EYE = tuple(tuple(float(i == j) for j in range(6)) for i in range(6))
SHIPPED = Path(__file__).resolve().parents[2] / "configs" / "mosquitto"


def status(sender: str, vehicle: int, t_s: float = 1.0) -> VehicleStatus:
    return VehicleStatus(
        sender=sender,
        t_s=t_s,
        vehicle=vehicle,
        east_m=10.0,
        north_m=-20.0,
        alt_m=100.0,
        course_rad=1.0,
        speed_m_s=14.0,
        phase_rad=0.5,
        stage="track",
        link="ok",
        healthy=True,
    )


def observation(sender: str, vehicle: int | None) -> TargetObservation:
    return TargetObservation(
        sender=sender, t_s=1.0, sensor="cam", vehicle=vehicle, east_m=500.0, north_m=0.0, sigma_m=1
    )


def local(sender: str, vehicle: int) -> LocalEstimate:
    return LocalEstimate(sender=sender, t_s=1.0, vehicle=vehicle, x=(500.0,) * 6, P=EYE)


def fused(sender: str) -> GlobalEstimate:
    return GlobalEstimate(sender=sender, t_s=1.0, x=(500.0,) * 6, P=EYE, beta={})


def mission(sender: str) -> MissionState:
    return MissionState(sender=sender, t_s=1.0, stage="track", active=(0,), spacing_rad=math.pi)


def command(sender: str, vehicles: tuple[int, ...] | None = None) -> Command:
    return Command(sender=sender, t_s=1.0, command="shutdown", vehicles=vehicles)


def presence(sender: str, vehicle: int | None) -> LinkState:
    return LinkState(sender=sender, t_s=1.0, online=False, vehicle=vehicle)


def epoch(sender: str) -> MissionEpoch:
    return MissionEpoch(sender=sender, t_s=0.0, epoch_s=1.0e9)


# (topic, message, why it is refused or None)
RULE_CASES: list[tuple[Topic | str, Message, str | None]] = [
    (topics.status(0), status("agent-1", 0), None),
    (
        topics.status(0),
        status("agent-2", 0),
        "wrong_sender",
    ),  # agent-2 speaking for agent-1's vehicle
    (topics.status(1), status("agent-2", 0), "wrong_vehicle"),  # a status about another vehicle
    (topics.status(0), status("ground", 0), "wrong_sender"),
    (topics.status(0), mission("ground"), "wrong_kind"),
    (topics.local_estimate(2), local("agent-3", 2), None),
    (topics.local_estimate(2), local("agent-1", 0), "wrong_sender"),
    (topics.local_estimate(2), local("agent-3", 0), "wrong_vehicle"),
    (topics.local_estimate(0), local("ground", 0), "wrong_sender"),
    (topics.observation(2), observation("ground", 2), None),
    (topics.observation(2), observation("agent-3", 2), None),
    (topics.observation(2), observation("agent-2", 2), "wrong_sender"),
    (topics.observation(2), observation("ground", 1), "wrong_vehicle"),
    (topics.observation(2), observation("ground", None), "wrong_vehicle"),
    (topics.observation(0), observation("tracker", 0), "wrong_sender"),
    (topics.GLOBAL_ESTIMATE, fused("ground"), None),
    (topics.GLOBAL_ESTIMATE, fused("agent-1"), "wrong_sender"),
    (topics.MISSION, mission("ground"), None),
    (topics.MISSION, mission("agent-2"), "wrong_sender"),
    (topics.MISSION_EPOCH, epoch("ground"), None),
    (topics.MISSION_EPOCH, epoch("agent-2"), "wrong_sender"),
    (topics.command(), command("ground"), None),
    (topics.command(), command("operator"), None),  # standoff fly's operator console
    (topics.command(), command("agent-2"), "wrong_sender"),
    (topics.command(1), command("ground", (1,)), None),
    (topics.command(1), command("ground"), "wrong_vehicle"),  # on command/1, for everyone
    (topics.command(1), command("ground", (0,)), "wrong_vehicle"),
    (topics.command(1), command("agent-2", (1,)), "wrong_sender"),
    (topics.link(1), presence("agent-2", 1), None),
    (topics.link(1), presence("agent-2", None), "wrong_vehicle"),
    (topics.link(1), presence("agent-1", 1), "wrong_sender"),
    (topics.link("ground"), presence("ground", None), None),
    (topics.link("ground"), presence("agent-1", None), "wrong_sender"),
    ("standoff/v1/status/01", status("agent-2", 1), "unknown_topic"),  # not canonical
    ("standoff/v1/status/255", status("agent-2", 1), "unknown_topic"),  # no such vehicle
    ("standoff/v1/status/ground", status("agent-2", 1), "unknown_topic"),
    ("standoff/v1/elsewhere", mission("ground"), "unknown_topic"),
    ("standoff/v1", mission("ground"), "unknown_topic"),
    ("tracker/fixes", observation("tracker", None), None),  # another program's topic
    ("standoff/v2/mission", mission("agent-2"), None),  # another layout: not this mission's
]


@pytest.mark.parametrize(("topic", "message", "reason"), RULE_CASES)
def test_the_rule_binds_sender_kind_and_vehicle_to_the_topic(
    topic: Topic | str, message: Message, reason: str | None
) -> None:
    assert topics.refusal(topic, message) == reason


def test_identities_and_their_vehicles() -> None:
    # numbered as users read them (the MAVLink system id): index i flies as agent-{i+1}
    assert topics.agent(0) == "agent-1"
    assert topics.agent(topics.MAX_VEHICLE) == "agent-255"
    assert topics.vehicle_of("agent-1") == 0
    assert topics.vehicle_of("agent-18") == 17
    assert topics.vehicle_of("agent-255") == topics.MAX_VEHICLE
    for i in range(topics.MAX_VEHICLE + 1):
        assert topics.vehicle_of(topics.agent(i)) == i
    bad = (
        "ground",
        "agent-",
        "agent-0",
        "agent-01",
        "agent-256",
        "agent-x",
        "agent-+1",
        "agent-1.0",
    )
    for name in bad:
        assert topics.vehicle_of(name) is None, name
    for index in (-1, 255, True):
        with pytest.raises(topics.TopicError):
            topics.agent(index)
    assert topics.may_publish("agent-2", topics.status(1))
    assert not topics.may_publish("agent-2", topics.status(0))
    assert not topics.may_publish("agent-2", topics.command())
    assert topics.may_publish("ground", topics.command())
    assert topics.may_publish("agent-2", "tracker/fixes")


# --- both buses ------------------------------------------------------------------------------


@pytest.fixture(params=["inproc", "mqtt"])
async def pair(request: pytest.FixtureRequest) -> AsyncIterator[tuple[Bus, Bus]]:
    """A publisher with no identity (it can forge) and a receiver, on one bus kind."""
    if request.param == "inproc":
        broker = InProcessBroker()
        async with (
            open_bus(None, broker=broker, client_id="forger") as pub,
            open_bus(None, broker=broker, client_id="receiver") as sub,
        ):
            yield pub, sub
        return
    mosquitto: Mosquitto = request.getfixturevalue("mosquitto")
    async with (
        open_bus(mosquitto.url, client_id="forger", connect_timeout_s=WAIT_S) as pub,
        open_bus(mosquitto.url, client_id="receiver", connect_timeout_s=WAIT_S) as sub,
    ):
        yield pub, sub


async def test_both_buses_drop_what_the_topic_does_not_permit_and_count_why(
    pair: tuple[Bus, Bus], caplog: pytest.LogCaptureFixture
) -> None:
    pub, receiver = pair
    forged = [(t, m, r) for t, m, r in RULE_CASES if r is not None and str(t).startswith("stand")]
    good = [(Topic(str(t)), m) for t, m, r in RULE_CASES if r is None]
    caplog.set_level(logging.WARNING, logger="app.adapters.bus.base")
    async with receiver.subscribe("#") as everything:
        for topic, message, _ in forged:
            await pub.publish(topic, message)
        for topic, message in good:
            await pub.publish(topic, message)
        got: list[tuple[Topic, Message]] = []
        async with asyncio.timeout(WAIT_S):
            while len(got) < len(good):
                got.append(await anext(everything))
        await asyncio.sleep(0.05)
        assert everything.pending() == 0
    assert got == good  # every forged one dropped, every good one delivered in order
    expected = dict.fromkeys(DROP_REASONS, 0)
    for _, _, reason in forged:
        expected[str(reason)] += 1
    assert receiver.drops == expected
    assert receiver.stats.refused == len(forged)
    assert receiver.stats.malformed == 0
    assert pub.drops == dict.fromkeys(DROP_REASONS, 0)  # it subscribed to nothing
    # one line per (reason, sender, topic) so far
    keys = {(r, m.sender, str(t)) for t, m, r in forged}
    assert len([r for r in caplog.records if "not believed" in r.getMessage()]) == len(keys)


async def test_a_flood_of_forgeries_is_counted_in_full_and_logged_rarely(
    pair: tuple[Bus, Bus], caplog: pytest.LogCaptureFixture
) -> None:
    pub, receiver = pair
    caplog.set_level(logging.WARNING, logger="app.adapters.bus.base")
    async with receiver.subscribe(topics.ALL_COMMANDS) as commands:
        for _ in range(120):
            await pub.publish(topics.command(), command("agent-2"))  # shutdown, "from" agent-2
        await pub.publish(topics.command(), command("ground"))
        async with asyncio.timeout(WAIT_S):
            _, message = await anext(commands)
    assert message == command("ground")
    assert receiver.drops["wrong_sender"] == 120
    lines = [r.getMessage() for r in caplog.records if "not believed" in r.getMessage()]
    assert len(lines) == 3  # the 1st, 10th and 100th
    assert "100 so far" in lines[-1]
    assert "'agent-2'" in lines[-1]
    assert "standoff/v1/command/all" in lines[-1]


async def test_a_client_with_an_identity_publishes_only_as_itself_on_its_topics() -> None:
    broker = InProcessBroker()
    async with (
        open_bus(None, broker=broker, client_id="agent-2", identity="agent-2") as agent2,
        open_bus(None, broker=broker, client_id="ground") as ground,
        ground.subscribe(topics.ALL) as sub,
    ):
        await agent2.publish(topics.status(1), status("agent-2", 1))
        refused = [
            (topics.status(0), status("agent-1", 0)),  # as another agent
            (topics.status(0), status("agent-2", 0)),  # on another's topic
            (topics.status(1), status("agent-2", 0)),  # about another vehicle
            (topics.command(), command("ground")),  # as the ground
            (topics.command(), command("agent-2")),  # on the ground's topic
        ]
        for topic, message in refused:
            with pytest.raises(BusError, match="agent-2"):
                await agent2.publish(topic, message)
        async with asyncio.timeout(WAIT_S):
            assert await anext(sub) == (topics.status(1), status("agent-2", 1))
        assert sub.pending() == 0
        assert agent2.stats.published == 1


def test_an_mqtt_bus_logs_in_as_its_identity() -> None:
    bus = MqttBus("mqtt://127.0.0.1:1883", client_id="agent-2", login=Login("agent-2", "pw"))
    assert bus.identity == "agent-2"
    assert bus.url.username == "agent-2"
    assert "pw" not in repr(bus)
    assert "pw" not in str(bus.url)
    with pytest.raises(BusError, match="names user 'ground'"):
        MqttBus("mqtt://ground:x@127.0.0.1:1883", login=Login("agent-2", "pw"))


def test_a_login_reads_its_password_from_a_file_or_the_environment(tmp_path: Path) -> None:
    secret = tmp_path / "agent-2.password"
    secret.write_text("s3cret\n", encoding="utf-8")
    assert Login.load("agent-2", password_file=secret).password == "s3cret"
    env = {"STANDOFF_BUS_PASSWORD": "from-env"}
    login = Login.load("agent-2", password_env="STANDOFF_BUS_PASSWORD", environ=env)
    assert login.password == "from-env"
    assert "from-env" not in repr(login)
    (tmp_path / "empty").write_text("\n", encoding="utf-8")
    for kwargs, reason in [
        ({"password_file": tmp_path / "missing"}, "cannot read"),
        ({"password_file": tmp_path / "empty"}, "is empty"),
        ({"password_env": "NOT_SET_ANYWHERE"}, "NOT_SET_ANYWHERE"),
        ({"password_file": secret, "password_env": "X"}, "not both"),
    ]:
        with pytest.raises(BusError, match=reason):
            Login.load("agent-2", environ={}, **kwargs)  # type: ignore[arg-type]


# --- the shipped mosquitto configuration ----------------------------------------------------


def test_the_shipped_files_are_what_standoff_broker_writes_for_three() -> None:
    assert (SHIPPED / "acl").read_text(encoding="utf-8") == acl_text(3)
    assert (SHIPPED / "mosquitto.conf").read_text(encoding="utf-8") == conf_text(DEFAULT_DIR)
    conf = (SHIPPED / "mosquitto.conf").read_text(encoding="utf-8")
    assert "allow_anonymous false" in conf
    assert "acl_file" in conf


def test_the_acl_grants_each_login_what_the_rule_permits() -> None:
    """Every topic the ACL lets a login write, the app's rule lets it send on (and back)."""
    team = ["ground", "agent-1", "agent-2", "agent-3", "observer"]
    samples = [topics.status(v) for v in range(3)]
    samples += [topics.link(v) for v in range(3)] + [topics.link("ground")]
    samples += [topics.local_estimate(v) for v in range(3)]
    samples += [topics.observation(v) for v in range(3)] + [topics.command(v) for v in range(3)]
    samples += [topics.command(), topics.GLOBAL_ESTIMATE, topics.MISSION, topics.MISSION_EPOCH]
    for who in team:
        grants = [topics.TopicFilter(f) for f in writable(who)]
        for topic in samples:
            assert any(g.matches(topic) for g in grants) == (
                who != "observer" and topics.may_publish(who, topic)
            ), (who, topic)


def test_the_password_file_uses_mosquittos_hash() -> None:
    line = password_hash("s3cret", salt=bytes(12))
    assert line.startswith("$7$101$AAAAAAAAAAAAAAAA$")
    assert password_hash("s3cret") != password_hash("s3cret")  # salted


@pytest.fixture
def team_broker(tmp_path: Path) -> Iterator[Mosquitto]:
    """mosquitto on the shipped configuration, for a team of three."""
    broker = Mosquitto(tmp_path, team=3)
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()


def raw_client(broker: Mosquitto, identity: str, **kwargs: object) -> aiomqtt.Client:
    login = broker.login(identity)
    return aiomqtt.Client(
        "127.0.0.1",
        broker.port,
        identifier=f"raw-{identity}",
        username=login.username,
        password=login.password,
        protocol=aiomqtt.ProtocolVersion.V5,
        **kwargs,  # type: ignore[arg-type]
    )


def attacks_of_agent_2() -> list[tuple[Topic, Message]]:
    """A well-formed message on every topic of another vehicle and of the ground, each
    claiming to come from the topic's owner."""
    out: list[tuple[Topic, Message]] = []
    for v in (0, 2):
        owner = f"agent-{v + 1}"
        out += [
            (topics.status(v), status(owner, v, t_s=10_000.0)),
            (topics.link(v), presence(owner, v)),
            (topics.local_estimate(v), local(owner, v)),
            (topics.observation(v), observation(owner, v)),
            (topics.command(v), command("ground", (v,))),
        ]
    out += [
        (topics.GLOBAL_ESTIMATE, fused("ground")),
        (topics.MISSION, mission("ground")),
        (topics.MISSION_EPOCH, epoch("ground")),
        (topics.command(), command("ground")),
        (topics.link("ground"), presence("ground", None)),
    ]
    return out


def own_of_agent_2() -> list[tuple[Topic, Message]]:
    return [
        (topics.status(1), status("agent-2", 1)),
        (topics.link(1), presence("agent-2", 1)),
        (topics.local_estimate(1), local("agent-2", 1)),
        (topics.observation(1), observation("agent-2", 1)),
    ]


async def test_the_shipped_broker_refuses_agent_1_anything_but_its_own_topics(
    team_broker: Mosquitto,
) -> None:
    """Logged in as agent-2, a client publishes (QoS 0 and 1, retained too) on every topic of
    vehicles 0 and 2 and of the ground: a subscriber to everything (a raw MQTT client, so that
    the app's own rule cannot hide what the broker let through) receives none of it, nor any
    retained copy later; what agent-2 publishes on its own topics arrives."""
    attacks, own = attacks_of_agent_2(), own_of_agent_2()
    received: list[str] = []
    own_arrived = asyncio.Event()
    async with raw_client(team_broker, "observer") as observer:
        await observer.subscribe(f"{topics.ROOT}/#", qos=1)

        async def listen() -> None:
            async for message in observer.messages:
                received.append(str(message.topic))
                if len(received) >= len(own):
                    own_arrived.set()

        async with asyncio.TaskGroup() as tg:
            listener = tg.create_task(listen())
            async with raw_client(team_broker, "agent-2") as agent2:
                for qos in (0, 1):
                    for topic, message in attacks:
                        await agent2.publish(topic.value, encode(message), qos=qos, retain=True)
                for topic, message in own:
                    await agent2.publish(topic.value, encode(message), qos=1)
            async with asyncio.timeout(WAIT_S):
                await own_arrived.wait()
            await asyncio.sleep(0.3)  # anything the broker let through would be here by now
            listener.cancel()
    print("\nagent-2 on the shipped broker (topic: what a subscriber to everything got):")
    for topic, _ in attacks:
        print(f"  {topic.value:38} refused: {received.count(topic.value)} of 2 delivered")
    for topic, _ in own:
        print(f"  {topic.value:38} own:     {received.count(topic.value)} of 1 delivered")
    assert sorted(received) == sorted(t.value for t, _ in own)
    # nothing of it was retained either: a later subscriber gets no retained message
    later: list[str] = []
    async with raw_client(team_broker, "ground") as ground:
        await ground.subscribe(f"{topics.ROOT}/#", qos=1)
        try:
            async with asyncio.timeout(0.5):
                async for packet in ground.messages:
                    later.append(str(packet.topic))
        except TimeoutError:
            pass
    assert later == []


async def test_a_refused_publish_is_counted_and_the_app_drops_forgeries_the_broker_passes(
    team_broker: Mosquitto,
) -> None:
    """The bus counts the broker's refusals of its QoS 1 publishes (MQTT 5 PUBACK 'not
    authorized'); and a login the ACL lets write a topic (the ground, on obs/0) still cannot
    make the agents believe a message it puts there under another's name."""
    async with (
        open_bus(
            team_broker.url,
            client_id="agent-2",
            login=team_broker.login("agent-2"),
            connect_timeout_s=WAIT_S,
        ) as agent2,
        open_bus(
            team_broker.url,
            client_id="agent-1",
            login=team_broker.login("agent-1"),
            connect_timeout_s=WAIT_S,
        ) as agent1,
        agent1.subscribe(topics.ALL_COMMANDS) as commands,
        agent1.subscribe(topics.observation(0)) as observations,
        raw_client(team_broker, "ground") as ground,
    ):
        assert isinstance(agent2, MqttBus)
        agent2.identity = None  # a buggy or hostile client: no check of its own
        await agent2.publish(topics.command(), command("ground"), qos=1)
        await agent2.publish(topics.status(0), status("agent-1", 0), qos=1)
        assert agent2.stats.denied == 2
        # the ground may write obs/0, but not as agent-2 (nor for index 1)
        await ground.publish(topics.observation(0).value, encode(observation("agent-2", 0)))
        await ground.publish(topics.observation(0).value, encode(observation("ground", 1)))
        await ground.publish(topics.observation(0).value, encode(observation("ground", 0)))
        await ground.publish(topics.command().value, encode(command("ground")), qos=1)
        async with asyncio.timeout(WAIT_S):
            assert (await anext(observations))[1] == observation("ground", 0)
            assert (await anext(commands))[1] == command("ground")
        assert commands.pending() == 0
        assert agent1.drops["wrong_sender"] == 1
        assert agent1.drops["wrong_vehicle"] == 1


async def test_the_shipped_broker_takes_logins_only(team_broker: Mosquitto) -> None:
    url = team_broker.url
    for login in (None, Login("agent-2", team_broker.login("agent-1").password), Login("x", "y")):
        bus = open_bus(url, login=login, connect_timeout_s=WAIT_S)
        async with asyncio.timeout(WAIT_S / 2):
            with pytest.raises(BusError, match="refused the connection"):
                await bus.__aenter__()
    async with open_bus(url, login=team_broker.login("ground"), connect_timeout_s=WAIT_S) as bus:
        assert isinstance(bus, MqttBus)
        assert bus.connected


def test_write_team_keeps_secrets_private(tmp_path: Path) -> None:
    files = write_team(tmp_path / "team", 2, passwords={"ground": "ground-secret-xyz"})
    assert files.password("ground") == "ground-secret-xyz"
    assert len({files.password(who) for who in ("agent-1", "agent-2", "observer")}) == 3
    assert files.password_files["agent-2"].stat().st_mode & 0o777 == 0o600
    assert (files.directory / "secrets").stat().st_mode & 0o777 == 0o700
    assert files.passwd.stat().st_mode & 0o777 == 0o640
    assert "ground-secret-xyz" not in files.passwd.read_text(encoding="utf-8")
    assert "user agent-2\n" in files.acl.read_text(encoding="utf-8")
    assert "user agent-3" not in files.acl.read_text(encoding="utf-8")
    assert files.mission_key.stat().st_mode & 0o777 == 0o600
    assert len(MissionKey.load(files.mission_key).secret) == 32


# --- the command line: standoff broker, and each process's login ----------------------------


def test_standoff_broker_writes_a_team_that_mosquitto_runs(tmp_path: Path) -> None:
    from app.cli import main

    assert main(["broker", "--vehicles", "2", "--out", str(tmp_path / "b"), "--port", "1"]) == 0
    assert (tmp_path / "b" / "acl").read_text(encoding="utf-8") == acl_text(2)
    for who in ("ground", "agent-1", "agent-2", "observer"):
        assert (tmp_path / "b" / "secrets" / f"{who}.password").read_text(encoding="utf-8")
    assert main(["broker", "--vehicles", "0", "--out", str(tmp_path / "c")]) == 2


def login_args(**options: str | None) -> argparse.Namespace:
    fields = "broker password_file password_env ca_file cert_file key_file mission_key_file"
    return argparse.Namespace(**{f: options.get(f) for f in fields.split()})


def mission_config(bus: object) -> MissionConfig:
    from app.config import load_config, validate_config

    raw = load_config("mqtt", MissionConfig).model_dump()
    raw["bus"] = bus
    raw.pop("bus_login")
    return validate_config(raw, MissionConfig, "test")


def test_each_process_logs_in_as_its_identity_from_the_config_or_the_options(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from app.cli._login import bus_options

    files = write_team(tmp_path, 2)
    table = {
        "url": "mqtt://127.0.0.1:1883",
        "password_file": f"{tmp_path}/secrets/{{client}}.password",
    }
    config = mission_config(table)
    for who in ("ground", "agent-2"):
        login = bus_options(login_args(), config, who)["login"]
        assert login == Login(who, files.password(who))
    monkeypatch.setenv("AGENT_PW", "from-env")
    options = bus_options(login_args(password_env="AGENT_PW"), config, "agent-1")
    assert options["login"] == Login("agent-1", "from-env")  # the option wins over the file
    keyed = mission_config({**table, "mission_key_file": str(files.mission_key)})
    assert bus_options(login_args(), keyed, "agent-2")["mission_key"] == MissionKey.load(
        files.mission_key
    )
    plain = mission_config("mqtt://127.0.0.1:1883")
    assert bus_options(login_args(), plain, "ground") == {}  # an anonymous broker
    assert bus_options(login_args(broker="mqtt://ground:pw@h:1"), plain, "ground") == {
        "login": Login("ground", "pw")
    }
    for args, config_, reason in [
        (login_args(broker="mqtt://ground:pw@h:1"), plain, "logs in as 'ground'"),
        (login_args(password_file=str(tmp_path / "nope")), plain, "cannot read"),
        (login_args(ca_file=str(tmp_path / "ca.crt")), plain, "use mqtts://"),
        (login_args(key_file="k"), plain, "without its certificate"),
    ]:
        with pytest.raises(ConfigError, match=reason):
            bus_options(args, config_, "agent-2")
    with pytest.raises(ConfigError, match="not both"):
        mission_config({"url": "mqtt://h:1", "password_file": "f", "password_env": "E"})


# --- sealed messages: a per-mission key, for a broker the operator does not control ---------


@pytest.fixture(params=["inproc", "mqtt"])
async def sealed(request: pytest.FixtureRequest) -> AsyncIterator[SealedHarness]:
    """Two clients holding the mission key, and a way to put raw bytes on the bus."""
    key = MissionKey.generate()
    if request.param == "inproc":
        broker = InProcessBroker()

        async def inject_inproc(topic: str, payload: bytes) -> None:
            broker.route(topic, payload)

        async with (
            open_bus(None, broker=broker, client_id="a", mission_key=key) as a,
            open_bus(None, broker=broker, client_id="b", mission_key=key) as b,
        ):
            yield SealedHarness(key, a, b, inject_inproc)
        return
    mosquitto: Mosquitto = request.getfixturevalue("mosquitto")
    async with (
        open_bus(mosquitto.url, client_id="a", mission_key=key, connect_timeout_s=WAIT_S) as a,
        open_bus(mosquitto.url, client_id="b", mission_key=key, connect_timeout_s=WAIT_S) as b,
        aiomqtt.Client("127.0.0.1", mosquitto.port, identifier="raw") as raw,
    ):

        async def inject_mqtt(topic: str, payload: bytes) -> None:
            await raw.publish(topic, payload, qos=1)

        yield SealedHarness(key, a, b, inject_mqtt)


@dataclasses.dataclass
class SealedHarness:
    key: MissionKey
    sender: Bus
    receiver: Bus
    inject: Callable[[str, bytes], Awaitable[None]]


async def test_with_a_mission_key_only_fresh_sealed_messages_are_taken(
    sealed: SealedHarness,
) -> None:
    h = sealed
    topic = topics.command()
    old = Sealer(h.key).seal(topic.value, encode(command("ground")))  # sealed before the rest
    async with h.receiver.subscribe(topics.ALL_COMMANDS) as commands:
        await h.sender.publish(topic, command("ground", (1,)))
        async with asyncio.timeout(WAIT_S):
            assert (await anext(commands))[1] == command("ground", (1,))
        await h.inject(topic.value, encode(command("ground")))  # not sealed: anyone's forgery
        await h.inject(topic.value, Sealer(MissionKey.generate()).seal(topic.value, b"{}"))
        moved = Sealer(h.key).seal(topics.command(2).value, encode(command("ground")))
        await h.inject(topic.value, moved)  # sealed for another topic
        tampered = bytearray(Sealer(h.key).seal(topic.value, encode(command("ground"))))
        tampered[-3] ^= 1
        await h.inject(topic.value, bytes(tampered))
        await h.inject(topic.value, old)  # a replay of something older than what was taken
        await h.sender.publish(topic, command("ground", (2,)))
        async with asyncio.timeout(WAIT_S):
            assert (await anext(commands))[1] == command("ground", (2,))
        assert commands.pending() == 0
    drops = h.receiver.drops
    assert (drops["unsigned"], drops["bad_signature"], drops["replayed"]) == (1, 3, 1)
    assert sum(drops.values()) == 5
    assert h.receiver.stats.refused == 5


async def test_a_sealed_presence_older_than_what_it_outlives_is_still_taken(
    sealed: SealedHarness,
) -> None:
    """A last will is sealed when its client connects; the broker sends it after the client's
    later messages on the same presence topic."""
    h = sealed
    will = Sealer(h.key).seal(topics.link(1).value, encode(presence("agent-2", 1)))
    online = LinkState(sender="agent-2", t_s=2.0, online=True, vehicle=1)
    async with h.receiver.subscribe(topics.ALL_LINKS) as links:
        await h.sender.publish(topics.link(1), online)
        await h.inject(topics.link(1).value, will)
        async with asyncio.timeout(WAIT_S):
            assert [(await anext(links))[1] for _ in range(2)] == [online, presence("agent-2", 1)]


def test_a_receiver_without_the_key_counts_sealed_payloads_as_malformed() -> None:
    payload = encode(mission("ground"))
    sealed_bytes = Sealer(MissionKey.generate()).seal(topics.MISSION.value, payload)
    assert sealed_bytes.endswith(payload)
    with pytest.raises(MalformedMessage):
        decode(sealed_bytes)


def test_mission_keys_load_from_their_files(tmp_path: Path) -> None:
    key = MissionKey.generate()
    path = tmp_path / "mission.key"
    path.write_text(key.hex() + "\n", encoding="ascii")
    assert MissionKey.load(path) == key
    assert key.hex() not in repr(key)
    for text, reason in [("zz", "non-hexadecimal"), ("abcd", "at least 16 bytes"), ("", "16")]:
        path.write_text(text, encoding="ascii")
        with pytest.raises(MissionKeyError, match=reason):
            MissionKey.load(path)
    with pytest.raises(MissionKeyError, match="cannot read"):
        MissionKey.load(tmp_path / "missing.key")


# --- TLS client certificates: the certificate's common name is the login --------------------


def openssl(*args: str) -> None:
    subprocess.run(["openssl", *args], check=True, capture_output=True, timeout=30)


def certificate(tmp_path: Path, name: str, ca: tuple[Path, Path] | None, *extra: str) -> Path:
    """An EC key and certificate for CN=``name``, signed by ``ca`` (self-signed without)."""
    key, cert = tmp_path / f"{name}.key", tmp_path / f"{name}.crt"
    openssl("ecparam", "-name", "prime256v1", "-genkey", "-noout", "-out", str(key))
    if ca is None:
        openssl("req", "-x509", "-new", "-key", str(key), "-days", "1", "-subj", f"/CN={name}",
                "-out", str(cert))  # fmt: skip
        return cert
    csr = tmp_path / f"{name}.csr"
    openssl("req", "-new", "-key", str(key), "-subj", f"/CN={name}", "-out", str(csr))
    openssl("x509", "-req", "-in", str(csr), "-CA", str(ca[0]), "-CAkey", str(ca[1]),
            "-CAcreateserial", "-days", "1", "-out", str(cert), *extra)  # fmt: skip
    return cert


@pytest.mark.slow
async def test_with_client_certificates_the_common_name_is_the_login(tmp_path: Path) -> None:
    """The shipped configuration with a TLS listener that requires a client certificate and
    takes its CN as the login (the commented lines of mosquitto.conf): agent-2's certificate
    gets it agent-2's topics, and only those; no certificate, no connection."""
    from app.cli._login import bus_options

    ca = (certificate(tmp_path, "standoff-ca", None), tmp_path / "standoff-ca.key")
    ext = tmp_path / "san.ext"
    ext.write_text("subjectAltName=IP:127.0.0.1\n", encoding="ascii")
    server = certificate(tmp_path, "127.0.0.1", ca, "-extfile", str(ext))
    client = certificate(tmp_path, "agent-2", ca)
    tls_lines = (
        f"cafile {ca[0]}\ncertfile {server}\nkeyfile {tmp_path / '127.0.0.1.key'}\n"
        "require_certificate true\nuse_identity_as_username true\n"
    )
    broker = Mosquitto(tmp_path, team=3, tls=True, extra_config=tls_lines)
    broker.start()
    try:
        args = login_args(
            broker=broker.url,
            ca_file=str(ca[0]),
            cert_file=str(client),
            key_file=str(tmp_path / "agent-2.key"),
        )
        options = bus_options(args, mission_config(broker.url), "agent-2")
        assert "login" not in options  # no password: the certificate is the login
        async with (
            open_bus(broker.url, client_id="agent-2", identity="agent-2", **options) as agent2,
            agent2.subscribe(topics.ALL) as everything,
        ):
            assert isinstance(agent2, MqttBus)
            agent2.identity = None  # let it try another vehicle's topic
            await agent2.publish(topics.status(0), status("agent-1", 0), qos=1)
            await agent2.publish(topics.status(1), status("agent-2", 1), qos=1)
            async with asyncio.timeout(WAIT_S):
                assert await anext(everything) == (topics.status(1), status("agent-2", 1))
            await asyncio.sleep(0.2)
            assert everything.pending() == 0
            assert agent2.stats.denied == 1
        with pytest.raises(BusError, match=r"cannot connect|refused"):
            async with open_bus(broker.url, connect_timeout_s=1.0, tls_context=tls_context(ca[0])):
                pass
    finally:
        broker.stop()
