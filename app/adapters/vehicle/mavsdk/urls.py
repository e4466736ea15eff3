"""MAVSDK connection URLs, checked before a hub opens them."""

from __future__ import annotations

from typing import Final
from urllib.parse import urlsplit

from app.errors import ConfigError

URL_SCHEMES: Final = ("udpin", "udpout", "tcp", "tcpin", "tcpout", "serial")


def validate_url(url: str) -> str:
    """A MAVSDK connection URL, checked: ``udpin://host:port``, ``udpout://host:port``,
    ``tcp(in|out)://host:port`` (``tcp://`` is deprecated in 4.1 but works) or
    ``serial:///dev/tty...:baud``. Raises ``ConfigError`` with the bad URL otherwise."""
    parts = urlsplit(url)
    if parts.scheme not in URL_SCHEMES:
        raise ConfigError(
            f"vehicle URL {url!r}: scheme must be one of {', '.join(URL_SCHEMES)} "
            "(e.g. udpin://0.0.0.0:14540, serial:///dev/ttyUSB0:57600)"
        )
    if parts.scheme == "serial":
        path, _, baud = parts.path.rpartition(":")
        if not path or not baud.isdigit():
            raise ConfigError(f"vehicle URL {url!r}: expected serial:///dev/<device>:<baud>")
        return url
    try:
        port = parts.port
    except ValueError as exc:
        raise ConfigError(f"vehicle URL {url!r}: bad port") from exc
    if port is None or parts.hostname is None:
        raise ConfigError(f"vehicle URL {url!r}: expected {parts.scheme}://<host>:<port>")
    if not 1 <= port <= 65535:
        raise ConfigError(f"vehicle URL {url!r}: port must be in 1..65535 (MAVSDK refuses 0)")
    return url
