"""How ``standoff fly`` on the built-in simulator ends when it is stopped from outside: a Ctrl-C in
its terminal holds every vehicle before the simulator stops, and a mission killed outright
leaves no simulator behind. Both run the real command in a process of its own."""

import contextlib
import os
import selectors
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

from sitl.ports import find_free_udp_base_port

pytestmark = pytest.mark.slow

VEHICLES = 3
START_TIMEOUT_S = 60.0
STOP_TIMEOUT_S = 30.0


def start_fly(out: Path) -> subprocess.Popen[str]:
    """``standoff fly`` in a session of its own, as a terminal's foreground job is (a Ctrl-C
    there signals its whole process group)."""
    return subprocess.Popen(
        [
            sys.executable, "-m", "app", "fly", "test-short", "--vehicles", str(VEHICLES),
            "--speedup", "4", "--no-gcs", "--out", str(out),
            "--base-port", str(find_free_udp_base_port(VEHICLES)),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )  # fmt: skip


def wait_for_line(proc: subprocess.Popen[str], words: str, timeout_s: float) -> list[str]:
    """Read the process's output until a line has ``words``; the lines read."""
    assert proc.stdout is not None
    lines: list[str] = []
    deadline = time.monotonic() + timeout_s
    with selectors.DefaultSelector() as sel:
        sel.register(proc.stdout, selectors.EVENT_READ)
        while time.monotonic() < deadline:
            if not sel.select(timeout=max(0.0, deadline - time.monotonic())):
                break
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if words in line:
                return lines
    raise AssertionError(f"no line with {words!r} within {timeout_s} s: {lines[-5:]}")


def simulator_of(proc: subprocess.Popen[str]) -> int:
    """The pid of the simulator process the mission started (its only child process)."""
    children = Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()
    assert len(children) == 1, children
    return int(children[0])


def gone(pid: int, timeout_s: float) -> bool:
    """Whether process ``pid`` ended (or became a zombie) within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except FileNotFoundError:
            return True
        if state == "Z":
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.1)


def stop_all(proc: subprocess.Popen[str], sim: int | None) -> None:
    """Whatever a failed test left running: the mission, and a simulator it left behind."""
    if proc.poll() is None:
        proc.kill()
        proc.communicate()
    if sim is not None and not gone(sim, 0.0):
        with contextlib.suppress(ProcessLookupError):
            os.kill(sim, signal.SIGKILL)


def last_mode(tlog: Path) -> str:
    """The flight mode in the vehicle's last heartbeat that the run's log has."""
    log = mavutil.mavlink_connection(str(tlog))
    last = None
    while (msg := log.recv_match(type="HEARTBEAT")) is not None:
        if msg.get_srcComponent() == 1:
            last = msg
    assert last is not None, tlog
    return str(mavutil.mode_string_v10(last))


def test_a_ctrl_c_in_the_terminal_holds_every_vehicle_before_the_simulator_stops(
    tmp_path: Path,
) -> None:
    proc = start_fly(tmp_path)
    sim: int | None = None
    try:
        wait_for_line(proc, " gather ", START_TIMEOUT_S)
        sim = simulator_of(proc)
        # the simulator is out of the terminal's reach: a Ctrl-C there is the mission's alone
        assert os.getsid(sim) != os.getsid(proc.pid)
        os.killpg(proc.pid, signal.SIGINT)  # what the terminal does on Ctrl-C
        _, err = proc.communicate(timeout=STOP_TIMEOUT_S)
        assert gone(sim, 10.0)
    finally:
        stop_all(proc, sim)
    assert "standoff fly: interrupted" in err
    assert "link lost" not in err
    assert "hold on exit failed" not in err
    for i in range(1, VEHICLES + 1):
        assert last_mode(tmp_path / f"vehicle-{i}.tlog") == "LOITER"  # PX4's hold


def test_a_mission_killed_outright_leaves_no_simulator_behind(tmp_path: Path) -> None:
    proc = start_fly(tmp_path)
    sim: int | None = None
    try:
        wait_for_line(proc, " gather ", START_TIMEOUT_S)
        sim = simulator_of(proc)
        proc.kill()
        proc.communicate(timeout=STOP_TIMEOUT_S)
        assert gone(sim, 10.0)
    finally:
        stop_all(proc, sim)
