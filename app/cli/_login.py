"""How ``standoff ground`` / ``standoff agent`` log in to the broker: options and the config's
``[bus]`` keys made into the bus's ``login`` and TLS context (docs/bus.md, "Logins").

The login is always the process's identity (``ground``, ``agent-N``): a URL naming another user
is refused. The password is read from a file or an environment variable, never taken from the
command line alone (a ``mqtt://user:password@`` URL still works, but shows in ``ps``)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from app.config.mission import MissionConfig


def add_login_options(p: argparse.ArgumentParser) -> None:
    """--password-file, --password-env, --ca-file, --cert-file, --key-file."""
    g = p.add_argument_group(
        "broker login",
        "the login is this process's identity (ground, agent-N); {client} in a path stands "
        "for it; default: the config's [bus] keys",
    )
    g.add_argument(
        "--password-file", metavar="PATH", help="the broker password: this file's first line"
    )
    g.add_argument(
        "--password-env", metavar="VAR", help="the broker password: this environment variable"
    )
    g.add_argument("--ca-file", metavar="PATH", help="TLS: the CA to trust (mqtts://)")
    g.add_argument("--cert-file", metavar="PATH", help="TLS: this client's certificate")
    g.add_argument("--key-file", metavar="PATH", help="TLS: this client's private key")
    g.add_argument(
        "--mission-key-file",
        metavar="PATH",
        help="seal every message with the team's key in this file and take only sealed ones "
        "(standoff broker writes one)",
    )


def bus_options(args: argparse.Namespace, config: MissionConfig, identity: str) -> dict[str, Any]:
    """``open_bus`` keywords for ``identity`` (``login``, ``tls_context``, ``mission_key``):
    the options, else
    the config's ``[bus]`` keys; ``ConfigError`` with the reason on a bad one, before any I/O."""
    from app.adapters.bus import BrokerUrl, Login, MissionKey, tls_context
    from app.errors import ConfigError

    keys = config.bus_login

    def filled(value: str | None) -> str | None:
        return None if value is None else value.replace("{client}", identity)

    def chosen(option: str) -> str | None:
        """The option, else the config's key, with {client} filled in."""
        return filled(getattr(args, option, None) or getattr(keys, option))

    # a password option replaces the config's way of giving it, whichever that was
    if args.password_file or args.password_env:
        password_file, password_env = filled(args.password_file), args.password_env
    else:
        password_file, password_env = filled(keys.password_file), keys.password_env
    url = BrokerUrl.parse(args.broker or config.bus or "")
    if url.username is not None and url.username != identity:
        raise ConfigError(
            f"the broker URL logs in as {url.username!r}; this process's login is its"
            f" identity, {identity!r}"
        )
    options: dict[str, Any] = {}
    if password_file is not None or password_env is not None:
        options["login"] = Login.load(
            identity, password_file=password_file, password_env=password_env
        )
    elif url.username is not None:
        options["login"] = Login(identity, url.password)
    ca_file, cert_file, key_file = chosen("ca_file"), chosen("cert_file"), chosen("key_file")
    if ca_file is not None or cert_file is not None:
        if not url.tls:
            raise ConfigError(f"TLS files were given for {url}: use mqtts://")
        options["tls_context"] = tls_context(ca_file, cert_file, key_file)
    elif key_file is not None:
        raise ConfigError("a TLS client key was given without its certificate (--cert-file)")
    if (mission_key_file := chosen("mission_key_file")) is not None:
        options["mission_key"] = MissionKey.load(mission_key_file)
    return options
