"""Finding free UDP ports, so simulators and tests running side by side do not collide."""

import random
import socket

_LOW, _HIGH = 20000, 60000


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
    wide range to make that unlikely. Raises ``OSError`` if no free run is found.
    """
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    pick = rng or random.SystemRandom()
    for _ in range(attempts):
        base = pick.randrange(_LOW, _HIGH - count)
        if udp_ports_free(base, count, host):
            return base
    raise OSError(f"no run of {count} free UDP ports found in {_LOW}..{_HIGH}")
