"""MAVSDK connection URLs, checked before a hub opens them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Literal
from urllib.parse import urlsplit

from app.errors import ConfigError

URL_SCHEMES: Final = ("udpin", "udpout", "tcp", "tcpin", "tcpout", "serial")


def validate_url(url: str) -> str:
    """A MAVSDK connection URL, checked: ``udpin://host:port``, ``udpout://host:port``,
    ``tcp(in|out)://host:port`` (``tcp://`` is deprecated in 4.1 but works) or
    ``serial:///dev/tty...:baud``. Raises ``ConfigError`` with the bad URL otherwise."""
    try:
        parts = urlsplit(url)
    except ValueError as exc:  # e.g. an unclosed IPv6 bracket: one line, not a traceback
        raise ConfigError(f"vehicle URL {url!r}: {exc}") from None
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


@dataclass(frozen=True, slots=True)
class UdpEndpoint:
    """A MAVLink endpoint the relay opens: ``udpin`` listens on ``host:port`` and answers
    whoever sends to it; ``udpout`` sends to ``host:port`` (from a port of its own) and hears
    the answers; ``tcpout`` connects to a TCP server there (ArduPilot SITL's 5760), for the
    vehicle side only."""

    mode: Literal["udpin", "udpout", "tcpout"]
    host: str
    port: int

    def __post_init__(self) -> None:
        if self.mode not in ("udpin", "udpout", "tcpout"):
            raise ConfigError(f"endpoint mode must be udpin, udpout or tcpout, got {self.mode!r}")
        if not self.host:
            raise ConfigError("UDP endpoint needs a host")
        if not 1 <= self.port <= 65535:
            raise ConfigError(f"UDP endpoint port must be in 1..65535, got {self.port}")

    def shifted(self, by: int) -> UdpEndpoint:
        """The same endpoint ``by`` ports up (vehicle i's own port of a ``udpin`` base)."""
        return UdpEndpoint(self.mode, self.host, self.port + by)

    @property
    def url(self) -> str:
        """As MAVSDK writes it (``udpin://host:port``)."""
        return f"{self.mode}://{self.host}:{self.port}"

    @property
    def spec(self) -> str:
        """As MAVProxy and mavlink-router write it (``udpout:host:port``)."""
        return f"{self.mode}:{self.host}:{self.port}"


def udp_endpoint_of_url(url: str) -> UdpEndpoint | None:
    """The endpoint a relay opens for a MAVSDK URL (``validate_url``): UDP both ways, and TCP
    when it connects out (``tcpout://``, ``tcp://``); None for ``tcpin://`` and serial."""
    parts = urlsplit(validate_url(url))
    modes: dict[str, Literal["udpin", "udpout", "tcpout"]] = {
        "udpin": "udpin",
        "udpout": "udpout",
        "tcpout": "tcpout",
        "tcp": "tcpout",
    }
    mode = modes.get(parts.scheme)
    if mode is None:
        return None
    assert parts.hostname is not None
    assert parts.port is not None
    return UdpEndpoint(mode, parts.hostname, parts.port)


def parse_gcs_endpoint(spec: str) -> UdpEndpoint:
    """Where a ground station is served: ``udpout:HOST:PORT`` (sent to, as PX4 SITL sends to
    QGroundControl's 14550), ``udpin:HOST:PORT`` (listened on; vehicle i on PORT+i), a MAVSDK
    URL of either, or plain ``HOST:PORT`` (udpout). Raises ``ConfigError`` naming the value."""
    text = spec.strip()
    mode: Literal["udpin", "udpout"] = "udpout"
    for prefix in ("udpin://", "udpout://", "udpin:", "udpout:"):
        if text.startswith(prefix):
            mode = "udpin" if prefix.startswith("udpin") else "udpout"
            text = text[len(prefix) :]
            break
    host, sep, port = text.rpartition(":")
    bracketed = host.startswith("[") and host.endswith("]")  # an IPv6 address
    if not sep or not host or not port.isdigit() or (":" in host and not bracketed):
        raise ConfigError(
            f"ground station endpoint {spec!r}: expected HOST:PORT, udpout:HOST:PORT or "
            "udpin:HOST:PORT (e.g. udpout:127.0.0.1:14550)"
        )
    try:
        return UdpEndpoint(mode, host.strip("[]"), int(port))
    except ConfigError as exc:
        raise ConfigError(f"ground station endpoint {spec!r}: {exc}") from exc
