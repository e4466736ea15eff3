"""A mosquitto set-up for one mission's team: logins, a password file and an ACL that lets each
client publish only on its own topics (docs/bus.md, "A broker that checks who publishes").

The ACL grants what ``topics.binding`` permits, one ``user`` block per identity: the ground
station (``ground``), one agent per vehicle (``agent-N``, N its MAVLink system id; its topics
name the vehicle by its 0-based index N - 1) and a read-only ``observer`` (a live view, a
recorder). Everyone may read the mission's topics. mosquitto's ``pattern`` lines cannot express
it: their ``%u`` is the whole login, and the topics name a vehicle by its bare index, so the
blocks are written out for a team of n.

The password file uses mosquitto 2's own hash (``$7$``: PBKDF2-HMAC-SHA512, 101 iterations,
12-byte salt), so ``mosquitto_passwd`` is not needed where the files are made.
"""

from __future__ import annotations

import base64
import dataclasses
import hashlib
import os
import secrets
from collections.abc import Mapping, Sequence
from pathlib import Path

from app.adapters.bus.signing import MissionKey
from app.runtime.ports import topics

OBSERVER = "observer"
DEFAULT_DIR = Path("/etc/mosquitto/standoff")
DEFAULT_PORT = 1883
PASSWD_FILE = "passwd"
ACL_FILE = "acl"
CONF_FILE = "mosquitto.conf"
SECRETS_DIR = "secrets"
MISSION_KEY_FILE = "mission.key"  # in SECRETS_DIR: the team's key for sealed messages

_ITERATIONS = 101  # mosquitto 2.0's mosquitto_passwd
_SALT_BYTES = 12
_R = topics.ROOT


def identities(vehicles: int) -> tuple[str, ...]:
    """Every login of a team of ``vehicles``: the ground, the agents, the observer."""
    if not 1 <= vehicles <= topics.MAX_VEHICLE + 1:
        raise ValueError(f"a team has 1..{topics.MAX_VEHICLE + 1} vehicles, got {vehicles}")
    return (topics.GROUND, *(topics.agent(i) for i in range(vehicles)), OBSERVER)


def writable(identity: str) -> tuple[str, ...]:
    """The topic filters ``identity`` may publish on (what ``topics.binding`` permits it)."""
    if identity == topics.GROUND:
        return (
            f"{_R}/obs/+",  # the ground's simulated observations and relayed external ones
            f"{_R}/estimate/global",
            f"{_R}/mission",
            f"{_R}/epoch",
            f"{_R}/command/+",
            f"{_R}/status/{topics.GROUND}/link",
        )
    vehicle = topics.vehicle_of(identity)
    if vehicle is None:
        return ()
    return (
        f"{_R}/status/{vehicle}",
        f"{_R}/status/{vehicle}/link",
        f"{_R}/estimate/local/{vehicle}",
        f"{_R}/obs/{vehicle}",  # its camera's observations
    )


def acl_text(vehicles: int) -> str:
    """A mosquitto ACL file for a team of ``vehicles``."""
    lines = [
        f"# mosquitto ACL for a standoff mission of {vehicles} vehicle(s): each login publishes",
        "# only on its own topics; every login reads the mission's (docs/bus.md).",
        f"# Written by 'standoff broker --vehicles {vehicles}'.",
    ]
    for identity in identities(vehicles):
        lines += ["", f"user {identity}", f"topic read {_R}/#"]
        lines += [f"topic write {topic}" for topic in writable(identity)]
    return "\n".join(lines) + "\n"


def conf_text(directory: Path, *, port: int = DEFAULT_PORT, host: str | None = None) -> str:
    """A mosquitto.conf that takes logins only, from ``directory``'s password file and ACL."""
    listener = f"listener {port}" + (f" {host}" if host else "")
    return (
        "# mosquitto for a standoff mission: no anonymous clients; each client logs in as its\n"
        "# identity (ground, agent-1, ...) and may publish only on its own topics (docs/bus.md).\n"
        "# Written by 'standoff broker'. For TLS add a listener such as:\n"
        "#   listener 8883\n"
        "#   cafile /etc/mosquitto/standoff/ca.crt\n"
        "#   certfile /etc/mosquitto/standoff/server.crt\n"
        "#   keyfile /etc/mosquitto/standoff/server.key\n"
        "#   require_certificate true        (clients show a certificate: --cert-file/--key-file)\n"
        "#   use_identity_as_username true   (its common name is then the login)\n"
        "per_listener_settings false\n"
        f"{listener}\n"
        "allow_anonymous false\n"
        f"password_file {directory / PASSWD_FILE}\n"
        f"acl_file {directory / ACL_FILE}\n"
    )


def password_hash(password: str, salt: bytes | None = None) -> str:
    """``password`` hashed as mosquitto 2 stores it (``$7$101$salt$hash``, base64)."""
    salt = secrets.token_bytes(_SALT_BYTES) if salt is None else salt
    digest = hashlib.pbkdf2_hmac("sha512", password.encode("utf-8"), salt, _ITERATIONS)
    b64 = base64.b64encode
    return f"$7${_ITERATIONS}${b64(salt).decode()}${b64(digest).decode()}"


def passwd_text(passwords: Mapping[str, str]) -> str:
    """A mosquitto password file: ``user:hash`` lines."""
    for user in passwords:
        if not user or ":" in user or "\n" in user:
            raise ValueError(f"bad login name {user!r}")
    return "".join(f"{user}:{password_hash(pw)}\n" for user, pw in passwords.items())


@dataclasses.dataclass(frozen=True, slots=True)
class TeamFiles:
    """What ``write_team`` wrote: the broker's files and one password file per login."""

    directory: Path
    conf: Path
    passwd: Path
    acl: Path
    password_files: Mapping[str, Path]
    mission_key: Path

    def password(self, identity: str) -> str:
        return self.password_files[identity].read_text(encoding="utf-8").strip()


def _write(path: Path, text: str, mode: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode)
    with os.fdopen(fd, "w", encoding="utf-8") as file:
        file.write(text)
    os.chmod(path, mode)  # also when the file was there before, with other bits


def write_team(
    directory: Path,
    vehicles: int,
    *,
    port: int = DEFAULT_PORT,
    host: str | None = None,
    passwords: Mapping[str, str] | None = None,
    extra: Sequence[str] = (),
) -> TeamFiles:
    """Write a team's broker files into ``directory``: ``mosquitto.conf``, ``acl``, ``passwd``
    (mode 0640: chgrp it to mosquitto's group), ``secrets/<login>.password`` (0600, one per
    process: its ``--password-file``) and ``secrets/mission.key`` (0600: the team's key for
    sealed messages, ``--mission-key-file``). New random passwords unless ``passwords`` gives them;
    ``extra`` logins are added with no topic to write (read-only, as the observer)."""
    directory = directory.resolve()
    logins = (*identities(vehicles), *extra)
    chosen = {who: (passwords or {}).get(who) or secrets.token_urlsafe(18) for who in logins}
    conf, passwd, acl = directory / CONF_FILE, directory / PASSWD_FILE, directory / ACL_FILE
    acl_lines = acl_text(vehicles)
    for who in extra:
        acl_lines += f"\nuser {who}\ntopic read {_R}/#\n"
    _write(conf, conf_text(directory, port=port, host=host), 0o644)
    _write(acl, acl_lines, 0o644)
    _write(passwd, passwd_text(chosen), 0o640)
    files = {}
    for who, password in chosen.items():
        files[who] = directory / SECRETS_DIR / f"{who}.password"
        _write(files[who], password + "\n", 0o600)
    mission_key = directory / SECRETS_DIR / MISSION_KEY_FILE
    _write(mission_key, MissionKey.generate().hex() + "\n", 0o600)
    os.chmod(directory / SECRETS_DIR, 0o700)
    return TeamFiles(directory, conf, passwd, acl, files, mission_key)
