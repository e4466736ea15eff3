"""MQTT topic names and filters as validated values, and the project's topic layout."""

from __future__ import annotations

import dataclasses
import functools

from app.errors import BusError

MAX_TOPIC_BYTES = 65535  # MQTT 3.1.1 / 5.0 section 4.7.3: a UTF-8 string of at most 65535 bytes

ROOT = "standoff/v1"


class TopicError(BusError, ValueError):
    """A topic name or filter breaks the MQTT rules; the message names the bad value."""


def _check_common(value: object, what: str) -> str:
    if not isinstance(value, str):
        raise TopicError(f"{what} must be a str, got {type(value).__name__}: {value!r}")
    if not value:
        raise TopicError(f"{what} must not be empty")
    if len(value.encode("utf-8", errors="surrogatepass")) > MAX_TOPIC_BYTES:
        raise TopicError(f"{what} is longer than {MAX_TOPIC_BYTES} bytes: {value[:40]!r}...")
    if "\x00" in value:
        raise TopicError(f"{what} must not contain NUL: {value!r}")
    return value


@dataclasses.dataclass(frozen=True, slots=True)
class Topic:
    """A topic name one can publish to: no wildcards, not reserved for the broker (``$...``)."""

    value: str

    def __post_init__(self) -> None:
        _check_common(self.value, "topic")
        if "+" in self.value or "#" in self.value:
            raise TopicError(f"topic must not contain the wildcards + or #: {self.value!r}")
        if self.value.startswith("$"):
            raise TopicError(f"topics starting with $ are reserved for the broker: {self.value!r}")

    def __str__(self) -> str:
        return self.value

    @property
    def levels(self) -> tuple[str, ...]:
        return tuple(self.value.split("/"))


@dataclasses.dataclass(frozen=True, slots=True)
class TopicFilter:
    """A subscription filter: ``+`` matches one whole level, ``#`` (last level only) the rest."""

    value: str

    def __post_init__(self) -> None:
        _check_common(self.value, "topic filter")
        levels = self.value.split("/")
        for i, level in enumerate(levels):
            if "#" in level and (level != "#" or i != len(levels) - 1):
                raise TopicError(
                    f"# must be a whole level and the last one in a topic filter: {self.value!r}"
                )
            if "+" in level and level != "+":
                raise TopicError(f"+ must be a whole level in a topic filter: {self.value!r}")

    def __str__(self) -> str:
        return self.value

    def matches(self, topic: Topic | str) -> bool:
        """Whether a message published on ``topic`` is delivered to this filter (MQTT 4.7)."""
        return _matches(self.value, topic.value if isinstance(topic, Topic) else topic)


@functools.lru_cache(maxsize=4096)
def _matches(filter_value: str, name: str) -> bool:
    """``TopicFilter.matches``, remembered: every client matches every payload's topic against
    each of its filters, and a mission has a few hundred (filter, topic) pairs at most."""
    names = name.split("/")
    pattern = filter_value.split("/")
    # MQTT 4.7.2: a filter that starts with a wildcard does not match $-topics
    if name.startswith("$") and pattern[0] in ("+", "#"):
        return False
    for i, level in enumerate(pattern):
        if level == "#":
            return True  # also matches the parent level: "a/#" matches "a"
        if i >= len(names):
            return False
        if level not in ("+", names[i]):
            return False
    return len(names) == len(pattern)


def as_topic(topic: Topic | str) -> Topic:
    return topic if isinstance(topic, Topic) else Topic(topic)


def as_filter(topic_filter: TopicFilter | Topic | str) -> TopicFilter:
    if isinstance(topic_filter, TopicFilter):
        return topic_filter
    if isinstance(topic_filter, Topic):
        return TopicFilter(topic_filter.value)
    return TopicFilter(topic_filter)


def _level(name: int | str) -> str:
    text = str(name)
    if isinstance(name, bool) or not text or "/" in text or "+" in text or "#" in text:
        raise TopicError(f"not a valid single topic level: {name!r}")
    return text


# The project's topics (docs/bus.md). A vehicle is named by its 0-based index.
def observation(vehicle: int | str) -> Topic:
    """Target observations for (or made by) one vehicle: ``TargetObservation``."""
    return Topic(f"{ROOT}/obs/{_level(vehicle)}")


def local_estimate(vehicle: int | str) -> Topic:
    """One agent's local filter output: ``LocalEstimate``."""
    return Topic(f"{ROOT}/estimate/local/{_level(vehicle)}")


def status(vehicle: int | str) -> Topic:
    """One vehicle's pose, phase, stage and health: ``VehicleStatus``."""
    return Topic(f"{ROOT}/status/{_level(vehicle)}")


def link(client: int | str) -> Topic:
    """A client's presence, beside its status: ``LinkState`` (its last will when it dies)."""
    return Topic(f"{ROOT}/status/{_level(client)}/link")


def command(vehicle: int | str | None = None) -> Topic:
    """Ground -> agent commands: ``Command``; ``None`` addresses every vehicle."""
    return Topic(f"{ROOT}/command/{'all' if vehicle is None else _level(vehicle)}")


GLOBAL_ESTIMATE = Topic(f"{ROOT}/estimate/global")
MISSION = Topic(f"{ROOT}/mission")
MISSION_EPOCH = Topic(f"{ROOT}/epoch")  # ``MissionEpoch``, retained by the ground station

ALL = TopicFilter(f"{ROOT}/#")
ALL_OBSERVATIONS = TopicFilter(f"{ROOT}/obs/+")
ALL_LOCAL_ESTIMATES = TopicFilter(f"{ROOT}/estimate/local/+")
ALL_STATUS = TopicFilter(f"{ROOT}/status/+")
ALL_LINKS = TopicFilter(f"{ROOT}/status/+/link")
ALL_COMMANDS = TopicFilter(f"{ROOT}/command/+")


# --- who may publish what where: identity bound to topics (docs/bus.md, "Identity") -----------
#
# Every client of a mission is one identity: the ground station ``ground`` and one agent per
# vehicle, ``agent-{i+1}`` for the 0-based vehicle index i (the number users read: the MAVLink
# system id, ``vehicle-{i+1}.tlog``; the topics keep the 0-based index internally). With a
# broker that authenticates, the client's login is its identity. A message on one of the
# layout's topics is believed only when its ``sender`` is an identity the topic permits, its
# ``kind`` is the topic's and the vehicle it is about is the topic's vehicle; both buses check
# this on receipt (``Bus._ingest``) and drop anything else, counted by reason.

GROUND = "ground"
OPERATOR = "operator"  # the operator's console of ``standoff fly`` (in-process, beside the ground)
AGENT_PREFIX = "agent-"
MAX_VEHICLE = 254  # vehicle i flies as MAVLink system id i + 1 (1..255)
COMMANDERS = frozenset({GROUND, OPERATOR})


def agent(vehicle: int) -> str:
    """The identity (bus client name and broker login) of the agent of the vehicle with 0-based
    index ``vehicle``: ``agent-{vehicle + 1}``, numbered like its MAVLink system id."""
    if isinstance(vehicle, bool) or not isinstance(vehicle, int) or not 0 <= vehicle <= MAX_VEHICLE:
        raise TopicError(f"vehicle index must be an int in 0..{MAX_VEHICLE}, got {vehicle!r}")
    return f"{AGENT_PREFIX}{vehicle + 1}"


def _index(text: str) -> int | None:
    """A vehicle index written canonically (``0``, ``17``; not ``01``, ``+1`` or ``1.0``)."""
    if not text.isascii() or not text.isdigit() or (len(text) > 1 and text[0] == "0"):
        return None
    value = int(text)
    return value if value <= MAX_VEHICLE else None


def vehicle_of(identity: str) -> int | None:
    """The 0-based index of the vehicle an agent's identity flies (``agent-1`` -> 0); None for
    any other name (``agent-0``, ``agent-01``, ``ground``)."""
    if not identity.startswith(AGENT_PREFIX):
        return None
    text = identity[len(AGENT_PREFIX) :]
    if text == "0" or not text.isascii() or not text.isdigit() or text[0] == "0":
        return None
    number = int(text)
    return number - 1 if number <= MAX_VEHICLE + 1 else None


@dataclasses.dataclass(frozen=True, slots=True)
class Binding:
    """What one topic of the layout carries: its message kind, the identities that may
    publish on it, and the vehicle it is about (None: no vehicle, e.g. the mission state)."""

    kind: str
    senders: frozenset[str]
    vehicle: int | None = None


_VEHICLE_TOPICS = {  # topic levels after ROOT, with {v} the vehicle: kind, may the ground send
    ("obs",): ("observation", True),
    ("estimate", "local"): ("estimate.local", False),
    ("status",): ("status", False),
    ("command",): ("command", None),  # commands: the ground's alone, never the vehicle's
}
_GROUND_TOPICS = {
    ("estimate", "global"): "estimate.global",
    ("mission",): "mission",
    ("epoch",): "epoch",
}
_ROOT_LEVELS = tuple(ROOT.split("/"))


def binding(topic: Topic | str) -> Binding | None:
    """What ``topic`` may carry and from whom, when it is one of the layout's topics.

    None for a topic outside ``standoff/v1/`` (another program's, e.g. an external tracker's
    feed: not the mission's to police). A topic inside it that the layout does not have is
    bound to nobody (``senders`` empty): nothing published there is believed.
    """
    return _binding(topic.value if isinstance(topic, Topic) else topic)


@functools.lru_cache(maxsize=1024)  # a mission has a few dozen topics; any flood is bounded
def _binding(name: str) -> Binding | None:
    levels = tuple(name.split("/"))
    if levels[: len(_ROOT_LEVELS)] != _ROOT_LEVELS:
        return None
    rest = levels[len(_ROOT_LEVELS) :]
    if rest in _GROUND_TOPICS:
        return Binding(_GROUND_TOPICS[rest], frozenset({GROUND}))
    if rest == ("command", "all"):
        return Binding("command", COMMANDERS)
    if rest == ("status", GROUND, "link"):
        return Binding("link", frozenset({GROUND}))
    if len(rest) == 3 and rest[0] == "status" and rest[2] == "link":
        v = _index(rest[1])
        return _NOBODY if v is None else Binding("link", frozenset({agent(v)}), v)
    if rest and rest[:-1] in _VEHICLE_TOPICS:
        kind, ground_too = _VEHICLE_TOPICS[rest[:-1]]
        v = _index(rest[-1])
        if v is None:
            return _NOBODY
        if ground_too is None:
            return Binding(kind, COMMANDERS, v)
        senders = {agent(v), GROUND} if ground_too else {agent(v)}
        return Binding(kind, frozenset(senders), v)
    return _NOBODY


_NOBODY = Binding("", frozenset())

# why a received message was not believed (``Bus.drops`` counts each)
UNKNOWN_TOPIC = "unknown_topic"  # inside the layout's root, but not one of its topics
WRONG_KIND = "wrong_kind"  # e.g. a status on the mission topic
WRONG_SENDER = "wrong_sender"  # a sender the topic does not permit (agent-2 on status/0)
WRONG_VEHICLE = "wrong_vehicle"  # about another vehicle than the topic's (status/1 for vehicle 0)
REFUSALS = (UNKNOWN_TOPIC, WRONG_KIND, WRONG_SENDER, WRONG_VEHICLE)


def kind_of(message: object) -> str:
    """A bus message's ``kind`` (every concrete ``Message`` has one; ``?`` for anything else)."""
    kind = getattr(message, "kind", None)
    return kind if isinstance(kind, str) else "?"


def refusal(topic: Topic | str, message: object) -> str | None:
    """Why ``message`` on ``topic`` is not to be believed (one of ``REFUSALS``), or None.

    The message's sender must be one of the identities the topic permits, its kind the topic's,
    and the vehicle it is about the topic's: a ``vehicle`` field (status, estimate, observation,
    presence) equal to it, and a command on ``command/{v}`` addressed to vehicle v alone (one
    on ``command/all`` may name any). This is all a receiver can check from the message itself:
    that the sender is who it says is the broker's part (its login and ACL,
    ``configs/mosquitto/``), or a signature's.
    """
    bound = binding(topic)
    if bound is None:
        return None
    if not bound.senders:
        return UNKNOWN_TOPIC
    if kind_of(message) != bound.kind:
        return WRONG_KIND
    if getattr(message, "sender", None) not in bound.senders:
        return WRONG_SENDER
    if bound.kind == "command":
        vehicles = getattr(message, "vehicles", None)
        if bound.vehicle is not None and vehicles != (bound.vehicle,):
            return WRONG_VEHICLE
    elif getattr(message, "vehicle", None) != bound.vehicle:
        return WRONG_VEHICLE
    return None


def may_publish(identity: str, topic: Topic | str) -> bool:
    """Whether ``identity`` may publish on ``topic`` at all (what the broker's ACL grants it;
    a topic outside the layout is anyone's as far as the mission is concerned)."""
    bound = binding(topic)
    return bound is None or identity in bound.senders
