"""Message authentication on the bus itself, for a broker the operator does not control: every
payload sealed with an HMAC-SHA256 under one per-mission key that the team's processes share.

A sealed payload is ``MAGIC | counter (8 bytes, big-endian) | tag (32 bytes) | payload``; the tag
covers the topic, the counter and the payload, so a sealed message can be neither altered nor
moved to another topic. The counter is the sealing process's wall clock in nanoseconds, made
strictly increasing: a receiver drops a message whose counter is not above the last one it took
from the same sender on the same topic (a replay), except on presence topics (a last will is
sealed when its client connects, before the messages it outlives).

What it protects against: anyone without the key (the broker's operator, its other users, a
network in between) can neither inject nor alter nor replay a message. What it does not: every
holder of the key can seal anything, so inside the team the broker's logins and ACL
(``configs/mosquitto/``) are what bind a client to its topics.
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
import secrets
import time
from pathlib import Path

from app.errors import ConfigError

MAGIC = b"\x00smk1"  # a NUL first: no JSON payload starts so, and a receiver without the key
# counts a sealed payload as malformed
_COUNTER_BYTES = 8
_TAG_BYTES = 32
HEADER_BYTES = len(MAGIC) + _COUNTER_BYTES + _TAG_BYTES
KEY_BYTES = 32

UNSIGNED = "unsigned"  # no seal, or one too short to be one
BAD_SIGNATURE = "bad_signature"  # a seal that does not match (another key, altered, moved)
REPLAYED = "replayed"  # a counter at or below the last one taken from this sender and topic
REASONS = (UNSIGNED, BAD_SIGNATURE, REPLAYED)


class MissionKeyError(ConfigError):
    """A mission key file that cannot be used; the message names the file."""


@dataclasses.dataclass(frozen=True, slots=True)
class MissionKey:
    """The team's shared secret for one mission (32 random bytes). Never shown in ``repr``."""

    secret: bytes = dataclasses.field(repr=False)

    def __post_init__(self) -> None:
        if len(self.secret) < 16:
            raise MissionKeyError(f"a mission key has at least 16 bytes, got {len(self.secret)}")

    @classmethod
    def generate(cls) -> MissionKey:
        return cls(secrets.token_bytes(KEY_BYTES))

    @classmethod
    def load(cls, path: Path | str) -> MissionKey:
        """A key file's first line: hex (as ``write`` makes it)."""
        try:
            text = Path(path).read_text(encoding="ascii").strip()
            return cls(bytes.fromhex(text.splitlines()[0] if text else ""))
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise MissionKeyError(f"cannot read the mission key {path}: {exc}") from exc

    def hex(self) -> str:
        return self.secret.hex()

    def tag(self, topic: str, counter: bytes, payload: bytes) -> bytes:
        mac = hmac.new(self.secret, MAGIC + topic.encode("utf-8"), hashlib.sha256)
        mac.update(b"\x00" + counter)
        mac.update(payload)
        return mac.digest()


class Sealer:
    """Seals one client's payloads: a strictly increasing counter from its wall clock."""

    def __init__(self, key: MissionKey) -> None:
        self.key = key
        self._last = 0

    def seal(self, topic: str, payload: bytes) -> bytes:
        self._last = max(self._last + 1, time.time_ns())
        counter = self._last.to_bytes(_COUNTER_BYTES, "big")
        return MAGIC + counter + self.key.tag(topic, counter, payload) + payload


@dataclasses.dataclass(frozen=True, slots=True)
class Opened:
    """A payload whose seal checked out, and its counter (for the replay check)."""

    payload: bytes
    counter: int


def unseal(key: MissionKey, topic: str, data: bytes) -> Opened | str:
    """The sealed payload, or why it is refused (``UNSIGNED`` or ``BAD_SIGNATURE``)."""
    if len(data) < HEADER_BYTES or not data.startswith(MAGIC):
        return UNSIGNED
    counter = data[len(MAGIC) : len(MAGIC) + _COUNTER_BYTES]
    tag = data[len(MAGIC) + _COUNTER_BYTES : HEADER_BYTES]
    payload = data[HEADER_BYTES:]
    if not hmac.compare_digest(tag, key.tag(topic, counter, payload)):
        return BAD_SIGNATURE
    return Opened(payload, int.from_bytes(counter, "big"))
