"""A real mosquitto broker on a free loopback port, for tests and benchmarks.

Tests get one from the ``mosquitto`` fixture (``tests/conftest.py``); ``Mosquitto.restart()``
brings it back on the same port. ``Mosquitto(workdir, team=n)`` runs the shipped configuration
instead (``app.adapters.bus.broker_setup``, as ``standoff broker`` writes it for a team of n:
no anonymous clients, one password per login, the per-client ACL); ``login(identity)`` is a
client's ``Login`` on it.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

from app.adapters.bus import Login
from app.adapters.bus.broker_setup import TeamFiles, conf_text, write_team

START_TIMEOUT_S = 10.0


def mosquitto_binary() -> str:
    found = shutil.which("mosquitto") or (
        "/usr/sbin/mosquitto" if os.access("/usr/sbin/mosquitto", os.X_OK) else None
    )
    if found is None:
        raise RuntimeError("mosquitto is not installed (apt-get install mosquitto)")
    return found


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


@contextlib.contextmanager
def refused_port() -> Iterator[int]:
    """A loopback TCP port that refuses every connection while the block runs: bound, never
    listening. A port that was merely free when it was picked can be taken before or while the
    test connects to it: by another test's server on a concurrent lane, or by the connecting
    client itself as its source port (TCP simultaneous open). A CI run saw the MQTT client read
    an unrecognised packet type 16 (a CONNECT) from such a port; which of the two it was is not
    known. Held bound, the port can be neither.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        yield int(sock.getsockname()[1])


class Mosquitto:
    """One mosquitto process with a generated config in ``workdir``."""

    def __init__(
        self,
        workdir: Path,
        *,
        extra_config: str = "",
        tls: bool = False,
        anonymous: bool = True,
        team: int | None = None,
    ) -> None:
        self.workdir = workdir
        self.anonymous = anonymous and team is None
        self.extra_config = extra_config
        self.tls = tls
        self.port = free_port()
        self.process: subprocess.Popen[bytes] | None = None
        self.log_path = workdir / "mosquitto.log"
        self.team: TeamFiles | None = None
        if team is not None:
            self.team = write_team(workdir / "broker", team, host="127.0.0.1")

    def login(self, identity: str) -> Login:
        """The login of ``identity`` on this broker's team (``team=`` only)."""
        if self.team is None:
            raise RuntimeError("this broker takes anonymous clients: start it with team=n")
        return Login(identity, self.team.password(identity))

    @property
    def url(self) -> str:
        return f"{'mqtts' if self.tls else 'mqtt'}://127.0.0.1:{self.port}"

    def config(self) -> str:
        if self.team is not None:
            head = conf_text(self.team.directory, port=self.port, host="127.0.0.1")
        else:
            head = (
                f"listener {self.port} 127.0.0.1\n"
                f"allow_anonymous {'true' if self.anonymous else 'false'}\n"
            )
        return (
            f"{head}"
            "persistence false\n"
            # as root, mosquitto would drop to the "mosquitto" user, who cannot read tmp_path
            f"{'user root' if os.geteuid() == 0 else ''}\n"
            "log_dest stderr\n"
            "log_type error\nlog_type warning\nlog_type notice\n"
            f"{self.extra_config}"
        )

    def start(self, *, keep_port: bool = False) -> None:
        """Start and return once it accepts TCP connections.

        A port lost to another process meanwhile is replaced by a new free one, unless
        ``keep_port`` (a restart: the clients know this port), which tries the same port again.
        """
        for attempt in range(3):
            conf = self.workdir / "mosquitto.conf"
            conf.write_text(self.config(), encoding="utf-8")
            with self.log_path.open("ab") as log:
                self.process = subprocess.Popen(
                    [mosquitto_binary(), "-c", str(conf)],
                    stdout=subprocess.DEVNULL,
                    stderr=log,
                )
            if self._wait_accepting():
                return
            self.stop()
            lost_the_port = self.process is not None and self.process.returncode != 0
            if attempt < 2 and lost_the_port and not keep_port:
                self.port = free_port()  # lost a race for the port with another process
        text = self.log_path.read_text(errors="replace") if self.log_path.exists() else ""
        raise RuntimeError(f"mosquitto did not start on port {self.port}:\n{text[-2000:]}")

    def _wait_accepting(self) -> bool:
        deadline = time.monotonic() + START_TIMEOUT_S
        assert self.process is not None
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                return False
            with (
                contextlib.suppress(OSError),
                socket.create_connection(("127.0.0.1", self.port), timeout=0.5),
            ):
                return True
            time.sleep(0.02)  # polling an external process: there is no event to await
        return False

    def stop(self) -> None:
        if self.process is None or self.process.poll() is not None:
            return
        self.process.terminate()
        try:
            self.process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=5)

    def restart(self) -> None:
        """Stop and start again on the same port (clients see a broker restart)."""
        self.stop()
        self.start(keep_port=True)
