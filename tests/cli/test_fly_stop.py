"""How ``standoff fly`` on the built-in simulator ends when it is stopped from outside: a Ctrl-C in
its terminal holds every vehicle (through the MAVLink relays) before the simulator and the
relays stop, and a mission killed outright leaves neither behind. Both run the real command in
a process of its own."""

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


def children_of(proc: subprocess.Popen[str]) -> dict[str, int]:
    """The processes the mission started, by role: ``simulator`` and ``relays`` (its only
    child processes)."""
    roles = {"app.compose.simulator": "simulator", "mavsdk.relay_process": "relays"}
    found: dict[str, int] = {}
    for pid in Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split():
        command = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        (role,) = [r for module, r in roles.items() if module in command]
        found[role] = int(pid)
    assert sorted(found) == ["relays", "simulator"], found
    return found


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


def stop_all(proc: subprocess.Popen[str], children: dict[str, int]) -> None:
    """Whatever a failed test left running: the mission, and what it left behind."""
    if proc.poll() is None:
        proc.kill()
        proc.communicate()
    for pid in children.values():
        if not gone(pid, 0.0):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def how_it_ended(proc: subprocess.Popen[str], out: str, err: str, run_dir: Path) -> str:
    """What a failed stop test needs to tell how the mission ended: the exit code, the end
    of its output and the last events of its run folder."""
    events = run_dir / "events.jsonl"
    last = events.read_text().splitlines()[-12:] if events.exists() else ["(no events.jsonl)"]
    head = [f"exit code {proc.returncode}", "stdout:", *out.splitlines()[-8:], "stderr:", err]
    return "\n".join([*head, "events:", *last])


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
    children: dict[str, int] = {}
    try:
        wait_for_line(proc, " gather ", START_TIMEOUT_S)
        children = children_of(proc)
        # out of the terminal's reach: a Ctrl-C there is the mission's alone
        for pid in children.values():
            assert os.getsid(pid) != os.getsid(proc.pid)
        os.killpg(proc.pid, signal.SIGINT)  # what the terminal does on Ctrl-C
        out, err = proc.communicate(timeout=STOP_TIMEOUT_S)
        assert all(gone(pid, 10.0) for pid in children.values())
    finally:
        stop_all(proc, children)
    assert "standoff fly: interrupted" in err, how_it_ended(proc, out, err, tmp_path)
    assert "link lost" not in err
    assert "hold on exit failed" not in err
    for i in range(1, VEHICLES + 1):
        assert last_mode(tmp_path / f"vehicle-{i}.tlog") == "LOITER"  # PX4's hold


def test_a_mission_killed_outright_leaves_no_simulator_and_no_relays_behind(
    tmp_path: Path,
) -> None:
    proc = start_fly(tmp_path)
    children: dict[str, int] = {}
    try:
        wait_for_line(proc, " gather ", START_TIMEOUT_S)
        children = children_of(proc)
        proc.kill()
        proc.communicate(timeout=STOP_TIMEOUT_S)
        assert gone(children["simulator"], 10.0)
        assert gone(children["relays"], 10.0)
    finally:
        stop_all(proc, children)
