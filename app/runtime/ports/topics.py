"""MQTT topic names and filters as validated values, and the project's topic layout."""

from __future__ import annotations

import dataclasses

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
        name = topic.value if isinstance(topic, Topic) else topic
        names = name.split("/")
        pattern = self.value.split("/")
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
