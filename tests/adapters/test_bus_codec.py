"""Codec and topic values: round trips of every message type (Hypothesis), strict rejection."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from app.adapters.bus import MalformedMessage, UnsupportedVersion, codec, decode, encode
from app.runtime.ports import topics
from app.runtime.ports.messages import (
    MESSAGE_TYPES,
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
from app.runtime.ports.topics import Topic, TopicError, TopicFilter

finite = st.floats(allow_nan=False, allow_infinity=False)
names = st.from_regex(r"[A-Za-z0-9_.:-]{1,20}", fullmatch=True)
vehicles = st.integers(min_value=0, max_value=254)
stages = st.sampled_from(["gather", "adjust", "track"])
states = st.tuples(*[finite] * 6)


@st.composite
def covariances(draw: st.DrawFn) -> tuple[tuple[float, ...], ...]:
    """Symmetric 6x6 with a non-negative diagonal (what a filter's P looks like on the wire)."""
    small = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)
    p = [[0.0] * 6 for _ in range(6)]
    for i in range(6):
        p[i][i] = draw(st.floats(min_value=0.0, max_value=1e6))
        for j in range(i):
            p[i][j] = p[j][i] = draw(small)
    return tuple(tuple(row) for row in p)


@st.composite
def betas(draw: st.DrawFn) -> dict[int, float]:
    ids = draw(st.lists(vehicles, max_size=8, unique=True))
    return {i: 1.0 / (len(ids) + 1) * draw(st.floats(0.01, 1.0)) for i in ids}


STRATEGIES: dict[type[Message], st.SearchStrategy[Message]] = {
    TargetObservation: st.builds(
        TargetObservation,
        sender=names, t_s=finite, sensor=names, vehicle=st.none() | vehicles,
        east_m=finite, north_m=finite, sigma_m=st.floats(min_value=1e-9, max_value=1e9),
    ),
    LocalEstimate: st.builds(
        LocalEstimate, sender=names, t_s=finite, vehicle=vehicles, x=states, P=covariances(),
        alloc_t_s=st.none() | finite,
    ),
    GlobalEstimate: st.builds(
        GlobalEstimate, sender=names, t_s=finite, x=states, P=covariances(), beta=betas(),
        included_t_s=st.none() | st.dictionaries(vehicles, finite, max_size=5),
    ),
    MissionState: st.builds(
        MissionState,
        sender=names, t_s=finite, stage=stages,
        active=st.lists(vehicles, unique=True, max_size=10).map(tuple),
        spacing_rad=st.floats(min_value=1e-6, max_value=2 * math.pi),
    ),
    VehicleStatus: st.builds(
        VehicleStatus,
        sender=names, t_s=finite, vehicle=vehicles, east_m=finite, north_m=finite, alt_m=finite,
        course_rad=finite, speed_m_s=st.floats(min_value=0.0, max_value=1e3), phase_rad=finite,
        stage=stages, link=st.sampled_from(["ok", "degraded", "lost"]), healthy=st.booleans(),
        detail=st.text(max_size=50), control=st.sampled_from(["mission", "pilot", "hold"]),
        flight_mode=st.text(max_size=40),
    ),
    MissionEpoch: st.builds(
        MissionEpoch, sender=names, t_s=finite, epoch_s=finite,
        rate=st.floats(min_value=1e-3, max_value=1e3), ended=st.booleans(),
    ),
    LinkState: st.builds(
        LinkState, sender=names, t_s=finite, online=st.booleans(),
        vehicle=st.none() | vehicles, reason=st.text(max_size=50),
    ),
    Command: st.builds(
        Command, sender=names, t_s=finite, command=st.sampled_from(["hold", "resume", "shutdown"]),
        vehicles=st.none() | st.lists(vehicles, max_size=5).map(tuple),
    ),
}  # fmt: skip
MESSAGES = st.one_of(*STRATEGIES.values())


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(MESSAGES)
def test_every_message_round_trips_exactly(message: Message) -> None:
    payload = encode(message)
    back = decode(payload)
    assert back == message
    assert type(back) is type(message)
    assert encode(back) == payload
    wire = json.loads(payload)
    assert wire["v"] == 2
    assert wire["kind"] == message.kind  # type: ignore[attr-defined]


def test_the_strategy_covers_every_message_type() -> None:
    assert set(STRATEGIES) == set(MESSAGE_TYPES)


OK = VehicleStatus(
    sender="agent-1", t_s=1.0, vehicle=0, east_m=1.0, north_m=2.0, alt_m=3.0, course_rad=0.0,
    speed_m_s=14.0, phase_rad=0.0, stage="track", link="ok", healthy=True,
)  # fmt: skip


def _with(**changes: object) -> bytes:
    wire = json.loads(encode(OK))
    wire.update(changes)
    return json.dumps(wire).encode()


@pytest.mark.parametrize(
    ("payload", "where"),
    [
        (b"\xff\xfe", "payload"),
        (b"null", "payload"),
        (_with(east_m="1.0"), "east_m"),
        (_with(vehicle=1.5), "vehicle"),
        (_with(healthy=1), "healthy"),
        (_with(speed_m_s=-1.0), "speed_m_s"),
        (_with(stage="loiter"), "stage"),
        (_with(sender=""), "sender"),
        (_with(sender="a/b"), "sender"),
        (_with(extra=1), "extra"),
        (_with(kind="nope"), "kind"),
        (encode(OK).replace(b'"t_s":1.0', b'"t_s":Infinity'), "t_s"),
        (encode(OK).replace(b'"t_s":1.0', b'"t_s":-1e400'), "t_s"),
        (b"{" * 10 + b"}" * 10, "payload"),
        (b"x" * 300_000, "bytes"),
    ],
)
def test_malformed_payloads_are_refused_naming_the_field(payload: bytes, where: str) -> None:
    with pytest.raises(MalformedMessage, match=where) as info:
        decode(payload)
    assert not isinstance(info.value, UnsupportedVersion)


@pytest.mark.parametrize("version", [0, 1, 3, "2", None])
def test_other_schema_versions_are_told_apart(version: object) -> None:
    with pytest.raises(UnsupportedVersion, match="schema version"):
        decode(_with(v=version))


def test_a_missing_version_is_malformed() -> None:
    wire = json.loads(encode(OK))
    del wire["v"]
    # a payload with no "v" at all is not "another version": it is not one of ours
    with pytest.raises(MalformedMessage, match="version is missing") as info:
        decode(json.dumps(wire).encode())
    assert not isinstance(info.value, UnsupportedVersion)


EYE = tuple(tuple(float(i == j) for j in range(6)) for i in range(6))


def test_covariances_must_be_symmetric_with_non_negative_variances() -> None:
    skew = [list(row) for row in EYE]
    skew[0][1] = 0.5
    with pytest.raises(ValidationError, match="not symmetric"):
        LocalEstimate.from_arrays(sender="a", t_s=0.0, vehicle=0, x=[0.0] * 6, P=skew)
    negative = [list(row) for row in EYE]
    negative[2][2] = -1.0
    with pytest.raises(ValidationError, match="negative variance"):
        LocalEstimate.from_arrays(sender="a", t_s=0.0, vehicle=0, x=[0.0] * 6, P=negative)
    with pytest.raises(ValidationError):
        LocalEstimate(sender="a", t_s=0.0, vehicle=0, x=(0.0,) * 5, P=EYE)
    with pytest.raises(ValueError, match="shape"):
        LocalEstimate.from_arrays(sender="a", t_s=0.0, vehicle=0, x=[0.0] * 6, P=[[1.0]])


def test_estimates_are_built_from_numpy_arrays() -> None:
    import numpy as np

    x = np.arange(6.0)
    p = np.diag(np.arange(1.0, 7.0)) + 1e-12 * np.ones((6, 6))
    local = LocalEstimate.from_arrays(sender="agent-1", t_s=0.5, vehicle=0, x=x, P=p)
    assert local.x == (0.0, 1.0, 2.0, 3.0, 4.0, 5.0)
    np.testing.assert_array_equal(np.array(local.P), p)
    fused = GlobalEstimate.from_arrays(
        sender="ground", t_s=0.5, x=x, P=p, beta={np.int64(0): np.float64(0.5)}
    )
    assert fused.beta == {0: 0.5}


def test_beta_factors_are_shares_of_one() -> None:
    with pytest.raises(ValidationError, match="sum to"):
        GlobalEstimate(sender="g", t_s=0.0, x=(0.0,) * 6, P=EYE, beta={0: 0.6, 1: 0.6})
    with pytest.raises(ValidationError):
        GlobalEstimate(sender="g", t_s=0.0, x=(0.0,) * 6, P=EYE, beta={0: 0.0})


def test_mission_active_vehicles_are_unique() -> None:
    with pytest.raises(ValidationError, match="unique"):
        MissionState(sender="g", t_s=0.0, stage="track", active=(0, 0), spacing_rad=1.0)


def test_messages_are_frozen() -> None:
    with pytest.raises(ValidationError):
        OK.east_m = 5.0  # type: ignore[misc]


# topics
@pytest.mark.parametrize(
    ("topic_filter", "topic", "expected"),
    [
        ("a/b", "a/b", True),
        ("a/b", "a/b/c", False),
        ("a/+", "a/b", True),
        ("a/+", "a", False),
        ("a/+", "a/", True),
        ("a/+/c", "a/b/c", True),
        ("+/+", "a/b", True),
        ("+", "/a", False),
        ("+/+", "/a", True),
        ("a/#", "a", True),
        ("a/#", "a/b/c", True),
        ("#", "a/b", True),
        ("#", "$SYS/x", False),
        ("+/x", "$SYS/x", False),
        ("$SYS/#", "$SYS/x", True),
        ("a/b", "A/b", False),
    ],
)
def test_filters_match_like_mqtt(topic_filter: str, topic: str, expected: bool) -> None:
    assert TopicFilter(topic_filter).matches(topic) is expected


@given(st.lists(st.from_regex(r"[a-z0-9 _-]{0,5}", fullmatch=True), min_size=1, max_size=6))
def test_a_topic_matches_itself_and_its_wildcard_generalisations(levels: list[str]) -> None:
    name = "/".join(levels)
    if not name:
        return
    topic = Topic(name)
    assert TopicFilter(name).matches(topic)
    assert TopicFilter("#").matches(topic)
    assert TopicFilter("/".join("+" for _ in levels)).matches(topic)
    assert TopicFilter("/".join([*levels[:-1], "#"])).matches(topic)
    assert not TopicFilter("/".join([*levels, "x"])).matches(topic)


@pytest.mark.parametrize("bad", ["", "a/+", "a/#", "#", "a\x00", "$SYS/x", "x" * 70000])
def test_bad_topics_are_refused_with_the_value(bad: str) -> None:
    with pytest.raises(TopicError, match="topic"):
        Topic(bad)


@pytest.mark.parametrize("bad", ["", "a/#/b", "a#", "a/b+", "++", "a\x00"])
def test_bad_filters_are_refused_with_the_value(bad: str) -> None:
    with pytest.raises(TopicError, match="filter"):
        TopicFilter(bad)


def test_topic_layout() -> None:
    assert topics.observation(2).value == "standoff/v1/obs/2"
    assert topics.local_estimate(0).value == "standoff/v1/estimate/local/0"
    assert topics.GLOBAL_ESTIMATE.value == "standoff/v1/estimate/global"
    assert topics.MISSION.value == "standoff/v1/mission"
    assert topics.status(1).value == "standoff/v1/status/1"
    assert topics.link("ground").value == "standoff/v1/status/ground/link"
    assert topics.command().value == "standoff/v1/command/all"
    assert topics.command(3).value == "standoff/v1/command/3"
    assert topics.ALL_STATUS.matches(topics.status(4))
    assert not topics.ALL_STATUS.matches(topics.link(4))
    assert topics.ALL_LINKS.matches(topics.link(4))
    for bad in ("a/b", "+", "#", "", True):
        with pytest.raises(TopicError):
            topics.status(bad)


# --- bounded before parsing, parsed once (issue #14) ----------------------------------------


@pytest.mark.parametrize(
    "payload",
    [
        b"[" * 5000 + b"]" * 5000,
        b"{" * 5000,
        b'{"v":2,"kind":"status","x":' + b"[" * 100_000 + b"]" * 100_000 + b"}",
        b"[" * 9 + b"]" * 9,
    ],
)
def test_a_nesting_bomb_is_malformed_not_a_recursion_error(payload: bytes) -> None:
    with pytest.raises(MalformedMessage, match=r"nested more than 8 deep|bytes is over"):
        decode(payload)


def test_brackets_inside_strings_do_not_count_as_nesting() -> None:
    status = OK.model_copy(update={"detail": '[[[[[[[[[[[[ {{{{{{{{{{ \\" [[[[[[[['})
    assert decode(encode(status)) == status


@settings(max_examples=3000, deadline=None)
@given(
    st.lists(st.sampled_from([b"[", b"]", b"{", b"}", b'"', b"\\", b"a", b",", b"1"]), max_size=60),
    st.sampled_from([0, 1, 2, 3, 8]),
)
def test_the_depth_of_the_brackets_alone_is_the_depth_scanned_one_by_one(
    pieces: list[bytes], limit: int
) -> None:
    # nesting_depth takes the strings out and the brackets' levels off in C; where they do not
    # pair up it scans them one by one: either way the answer is the scan's
    payload = b"".join(pieces)
    scanned = (
        codec._scanned_depth(payload, limit)
        if payload.count(b"[") + payload.count(b"{") > limit
        else 0
    )
    assert codec.nesting_depth(payload, limit) == scanned


def test_the_deepest_message_passes_the_depth_bound() -> None:
    eye = tuple(tuple(1.0 if i == j else 0.0 for j in range(6)) for i in range(6))
    message = LocalEstimate(
        sender="agent-1", t_s=1.0, vehicle=0, x=(0.0,) * 6, P=eye,
        mu=(0.5, 0.5), model_x=((0.0,) * 6, (0.0,) * 6), model_P=(eye, eye),
    )  # fmt: skip
    assert decode(encode(message)) == message


def test_a_wrong_version_is_told_apart_without_a_second_parse() -> None:
    with pytest.raises(UnsupportedVersion, match="3"):
        decode(_with(v=3))
    with pytest.raises(UnsupportedVersion, match="3"):
        decode(_with(v=3, kind="future-kind"))
    with pytest.raises(MalformedMessage) as info:
        decode(_with(kind="future-kind"))
    assert not isinstance(info.value, UnsupportedVersion)
