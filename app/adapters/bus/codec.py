"""Bytes <-> bus messages: compact UTF-8 JSON out, strict validation in."""

from __future__ import annotations

import json

from pydantic import TypeAdapter, ValidationError

from app.errors import InputError
from app.runtime.ports.messages import SCHEMA_VERSION, AnyMessage, Message

_ADAPTER: TypeAdapter[AnyMessage] = TypeAdapter(AnyMessage)
MAX_PAYLOAD_BYTES = 256 * 1024


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
    try:
        message: Message = _ADAPTER.validate_json(payload, strict=True)
    except ValidationError as exc:
        version = _version_of(payload)
        if version is not _ABSENT and version != SCHEMA_VERSION:
            raise UnsupportedVersion(
                f"schema version {version!r}, this build speaks {SCHEMA_VERSION}"
            ) from exc
        first = exc.errors()[0]
        where = ".".join(str(part) for part in first["loc"]) or "(payload)"
        raise MalformedMessage(f"{where}: {first['msg']}") from exc
    if "v" not in message.model_fields_set:  # the model's default is for senders, not the wire
        raise MalformedMessage("v: the schema version is missing")
    return message


_ABSENT = object()


def _version_of(payload: bytes | bytearray | str) -> object:
    """The ``v`` of a JSON object payload, or ``_ABSENT`` when there is no such thing to read."""
    try:
        obj = json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        return _ABSENT
    return obj.get("v", _ABSENT) if isinstance(obj, dict) else _ABSENT
