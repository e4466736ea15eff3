"""Bytes <-> bus messages: compact UTF-8 JSON out, strict validation in.

A received payload is bounded before it is parsed (``MAX_PAYLOAD_BYTES``, ``MAX_DEPTH`` of
nested arrays and objects) and parsed once, by the validator; whatever is wrong with it ends as
``MalformedMessage`` (a ``[`` x 5000 payload once raised ``RecursionError`` from a second parse
that probed its version, escaped the codec and made every MQTT client drop its connection).
"""

from __future__ import annotations

import re
from typing import Any

from pydantic import TypeAdapter, ValidationError

from app.errors import InputError
from app.runtime.ports.messages import SCHEMA_VERSION, AnyMessage, Message

_ADAPTER: TypeAdapter[AnyMessage] = TypeAdapter(AnyMessage)
# The largest message of the schema is a fused estimate: three models' moments and a share per
# vehicle, about 13 KB for 254 vehicles. A flood of 100 KB garbage (issue #14) parsed at 256 KiB
# cost the agents of a one-process mission a fifth of their frames (track RMS 2.8x a clean run).
MAX_PAYLOAD_BYTES = 64 * 1024
MAX_DEPTH = 8
"""Nesting of arrays and objects a payload may have: the deepest message, an estimate's
per-model covariances inside the object, is 4 deep."""

_STRUCTURE = re.compile(rb'\\.|["\[\]{}]', re.DOTALL)
# what is not structure: a string (to its end if unterminated) and a backslash escape
_NOT_STRUCTURE = re.compile(rb'"(?:[^"\\]|\\.)*"?|\\.', re.DOTALL)
_NOT_BRACKETS = bytes(c for c in range(256) if c not in b"[]{}")
_INNERMOST = re.compile(rb"\[\]|\{\}")


class MalformedMessage(InputError):
    """A payload that is not a valid bus message (garbled, wrong schema, non-finite number)."""


class UnsupportedVersion(MalformedMessage):
    """A well-formed payload of a schema version this build does not speak."""


def encode(message: Message) -> bytes:
    """The wire form of a message (it validated when it was built, so this cannot fail)."""
    return message.model_dump_json().encode("utf-8")


def decode(payload: bytes | bytearray | str) -> Message:
    """Validate a received payload strictly (no string-to-number coercion, no NaN or inf).

    Raises
    ------
    UnsupportedVersion
        The payload is a JSON object whose ``v`` is not this build's schema version.
    MalformedMessage
        Anything else wrong; the message says what, briefly.
    """
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise MalformedMessage(f"payload of {len(payload)} bytes is over {MAX_PAYLOAD_BYTES}")
    raw = payload.encode("utf-8", "surrogatepass") if isinstance(payload, str) else bytes(payload)
    depth = nesting_depth(raw, MAX_DEPTH)
    if depth > MAX_DEPTH:
        raise MalformedMessage(f"(payload): nested more than {MAX_DEPTH} deep")
    try:
        message: Message = _ADAPTER.validate_json(raw, strict=True)
    except ValidationError as exc:
        errors = exc.errors(include_url=False)
        version = _version_in(errors)
        if version is not _ABSENT and version != SCHEMA_VERSION:
            raise UnsupportedVersion(
                f"schema version {version!r}, this build speaks {SCHEMA_VERSION}"
            ) from None
        first = errors[0]
        where = ".".join(str(part) for part in first["loc"]) or "(payload)"
        raise MalformedMessage(f"{where}: {first['msg']}") from None
    except (ValueError, RecursionError, MemoryError) as exc:  # defensive: never escape
        raise MalformedMessage(f"unparseable payload ({type(exc).__name__})") from None
    if "v" not in message.model_fields_set:  # the model's default is for senders, not the wire
        raise MalformedMessage("v: the schema version is missing")
    return message


def nesting_depth(payload: bytes, limit: int) -> int:
    """How deep arrays and objects nest in ``payload`` (brackets inside strings do not count),
    up to ``limit + 1``: the scan stops as soon as the limit is passed. A payload with at most
    ``limit`` opening brackets cannot pass it and is not scanned."""
    if payload.count(b"[") + payload.count(b"{") <= limit:
        return 0
    # the brackets alone (C-speed: an estimate's hundreds of them are no Python loop), then
    # one nesting level taken off per pass while they pair up; anything else (over the
    # limit, or brackets that do not pair up: not JSON anyway) is scanned bracket by bracket
    if b"\\" in payload:
        outside = _NOT_STRUCTURE.sub(b"", payload)
    else:  # no escapes: every other piece between quotes is a string
        outside = b"".join(payload.split(b'"')[0::2])
    brackets = outside.translate(None, _NOT_BRACKETS)
    depth = 0
    while brackets:
        inner = _INNERMOST.sub(b"", brackets)
        if depth >= limit or len(inner) == len(brackets):
            return _scanned_depth(payload, limit)
        brackets = inner
        depth += 1
    return depth


def _scanned_depth(payload: bytes, limit: int) -> int:
    """``nesting_depth`` bracket by bracket (where they do not pair up: not JSON anyway)."""
    depth = deepest = 0
    in_string = False
    for token in _STRUCTURE.finditer(payload):
        ch = token.group()
        if ch[0] == 0x5C:  # a backslash escape: skips the character it escapes
            continue
        if ch == b'"':
            in_string = not in_string
        elif in_string:
            continue
        elif ch in (b"[", b"{"):
            depth += 1
            if depth > deepest:
                deepest = depth
                if deepest > limit:
                    return deepest
        else:
            depth -= 1
    return deepest


_ABSENT = object()


def _version_in(errors: list[Any]) -> object:
    """The ``v`` of a JSON object payload, read from the validator's errors (the parsed input
    travels with them: no second parse), or ``_ABSENT`` when there is no such thing to read."""
    for error in errors:
        loc, value = error.get("loc", ()), error.get("input")
        if len(loc) == 2 and loc[1] == "v":
            return value
        if isinstance(value, dict) and not loc:
            return value.get("v", _ABSENT)
    for error in errors:
        value = error.get("input")
        if isinstance(value, dict) and len(error.get("loc", ())) == 1:
            return value.get("v", _ABSENT)
    return _ABSENT
