"""Finding free UDP ports, so simulators and tests running side by side do not collide."""

import random
import socket
from pathlib import Path

_LOW, _HIGH = 20000, 60000
_EPHEMERAL = Path("/proc/sys/net/ipv4/ip_local_port_range")
_MIN_SPAN = 2000  # the least range worth picking from below the ephemeral ports


def ephemeral_ports(path: Path = _EPHEMERAL) -> range | None:
    """The ports the kernel hands out to sockets bound to port 0 (Linux), None where unknown."""
    try:
        low, high = (int(v) for v in path.read_text().split())
    except (OSError, ValueError):
        return None
    return range(low, high + 1)


def pick_range(ephemeral: range | None) -> tuple[int, int]:
    """Where to look for free ports: below the ephemeral ports where there is room. A run
    found free among them can be taken by any socket the run itself opens on port 0 (the
    MAVLink relays' and MAVSDK's) before the simulator binds it: seen once in twenty."""
    if ephemeral is not None and ephemeral.start - _LOW >= _MIN_SPAN:
        return _LOW, min(_HIGH, ephemeral.start)
    return _LOW, _HIGH


def udp_ports_free(base_port: int, count: int, host: str = "0.0.0.0") -> bool:
    """Whether ``base_port .. base_port + count - 1`` can all be bound on ``host`` right now."""
    sockets: list[socket.socket] = []
    try:
        for port in range(base_port, base_port + count):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sockets.append(sock)
            sock.bind((host, port))
    except OSError:
        return False
    finally:
        for sock in sockets:
            sock.close()
    return True


def find_free_udp_base_port(
    count: int, host: str = "0.0.0.0", rng: random.Random | None = None, attempts: int = 200
) -> int:
    """A base port with ``count`` consecutive free UDP ports (checked by binding them).

    Another process may still take one between the check and its use; pick at random from a
    wide range below the kernel's ephemeral ports (``pick_range``) to make that unlikely.
    Raises ``OSError`` if no free run is found.
    """
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    pick = rng or random.SystemRandom()
    low, high = pick_range(ephemeral_ports())
    for _ in range(attempts):
        base = pick.randrange(low, high - count)
        if udp_ports_free(base, count, host):
            return base
    raise OSError(f"no run of {count} free UDP ports found in {low}..{high}")
