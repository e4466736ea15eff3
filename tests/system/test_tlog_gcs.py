"""A short ``standoff fly`` mission with a second ground station beside it, and its flight logs
read back as a user would: pymavlink, mavflightmodes, mavtogpx, mavlogdump.

The mission flies ``configs/test-short.toml`` (cut to 35 s) on the built-in simulator in its
own process, on free ports; its relays send every vehicle's traffic to a pymavlink ground
station listening on a free port (as QGroundControl listens on 14550). The ground station
heartbeats and asks one vehicle for a message while the mission flies; the mission must not
notice. Then each vehicle's .tlog must hold both directions of the traffic, the camera's
messages, wall-clock timestamps in order, a bank angle while orbiting and a GPS track.
"""

import asyncio
import math
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import pytest_asyncio
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from app.compose.mission import Mission
from app.compose.parts import MissionResult
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from sitl.ports import find_free_udp_base_port

pytestmark = [pytest.mark.slow, pytest.mark.asyncio(loop_scope="module")]

END_S = 35.0
SPEEDUP = 3.0
GCS_ID = 255
TOOLS = Path(sys.executable).parent


@dataclass
class GroundStation:
    """A second ground station (pymavlink, in a thread): what it heard, and the one command it
    sent and the answer."""

    port: int
    positions: Counter[int] = field(default_factory=Counter)
    heartbeats: Counter[int] = field(default_factory=Counter)
    asked: int | None = None
    answers: list[Any] = field(default_factory=list)
    stop: threading.Event = field(default_factory=threading.Event)

    def run(self) -> None:
        conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{self.port}", source_system=GCS_ID, source_component=190
        )
        try:
            next_beat = 0.0
            while not self.stop.is_set():
                msg = conn.recv_match(blocking=True, timeout=0.2)
                now = time.monotonic()
                if msg is not None and msg.get_type() == "GLOBAL_POSITION_INT":
                    self.positions[msg.get_srcSystem()] += 1
                if msg is not None and msg.get_type() == "HEARTBEAT":
                    self.heartbeats[msg.get_srcSystem()] += 1
                if msg is not None and msg.get_type() == "COMMAND_ACK":
                    self.answers.append(msg)
                if msg is None or now < next_beat:
                    continue
                next_beat = now + 1.0
                # to the relay it heard last, as QGroundControl answers each link's peer
                conn.mav.heartbeat_send(
                    mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0
                )
                if self.asked is None and sum(self.positions.values()) > 50:
                    self.asked = msg.get_srcSystem()
                    conn.mav.command_long_send(
                        self.asked,
                        1,
                        mavlink.MAV_CMD_REQUEST_MESSAGE,
                        0,
                        mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                        0,
                        0,
                        0,
                        0,
                        0,
                        0,
                    )
        finally:
            conn.close()


@dataclass
class Run:
    result: MissionResult
    gcs: GroundStation
    wall_start_s: float
    wall_end_s: float


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    out = tmp_path_factory.mktemp("tlog-run")
    gcs = GroundStation(find_free_udp_base_port(1, "127.0.0.1"))
    config = load_config("test-short", MissionConfig)
    config = config.model_copy(
        update={
            "end_s": END_S,
            "sim": config.sim.model_copy(update={"speedup": SPEEDUP}),
            "link": config.link.model_copy(update={"gcs_forward": f"udpout:127.0.0.1:{gcs.port}"}),
        }
    )
    plan = build_plan(config)
    lines: list[str] = []
    thread = threading.Thread(target=gcs.run, name="second-gcs", daemon=True)
    thread.start()
    start = time.time()
    try:
        mission = Mission(
            plan, out, base_port=find_free_udp_base_port(plan.count), notify=lines.append
        )
        async with asyncio.timeout(120.0):
            result = await mission.run()
    finally:
        gcs.stop.set()
        thread.join(5.0)
    assert len(lines) == plan.count  # one line per vehicle link, naming the ground station
    assert all(f"udpout:127.0.0.1:{gcs.port}" in line for line in lines)
    return Run(result, gcs, start, time.time())


def read_tlog(path: Path) -> list[Any]:
    reader = mavutil.mavlink_connection(str(path))
    out = []
    while (msg := reader.recv_match()) is not None:
        out.append(msg)
    return out


async def test_the_mission_flew_undisturbed_by_the_second_ground_station(run: Run) -> None:
    summary = run.result.summary
    assert summary["events"].get("mission_complete") == 1
    assert "pilot_took_over" not in summary["events"]
    assert summary["events"].get("vehicle_joined") == 3


async def test_a_second_ground_station_sees_every_vehicles_position_stream(run: Run) -> None:
    # 35 s of mission at 3x is about 12 s of wall time at 10 Hz of simulated time per vehicle
    assert set(run.gcs.positions) == {1, 2, 3}
    assert all(n > 100 for n in run.gcs.positions.values()), run.gcs.positions
    assert set(run.gcs.heartbeats) >= {1, 2, 3}
    # its command reached the vehicle and the answer came back to it (not to the app)
    assert run.gcs.asked in (1, 2, 3)
    acks = [a for a in run.gcs.answers if a.command == mavlink.MAV_CMD_REQUEST_MESSAGE]
    assert acks, "no COMMAND_ACK for the ground station's request"
    assert acks[0].result == mavlink.MAV_RESULT_ACCEPTED
    assert acks[0].target_system == GCS_ID


async def test_each_tlog_holds_both_directions_the_camera_and_wall_clock_times(run: Run) -> None:
    for i in (1, 2, 3):
        messages = read_tlog(run.result.out_dir / f"vehicle-{i}.tlog")
        kinds = Counter((m.get_srcSystem(), m.get_srcComponent(), m.get_type()) for m in messages)
        app = {k for s, _, k in kinds if s == 245}
        vehicle = {k for s, c, k in kinds if s == i and c == 1}
        assert {"SET_POSITION_TARGET_LOCAL_NED", "COMMAND_LONG", "HEARTBEAT"} <= app
        assert {"HEARTBEAT", "GLOBAL_POSITION_INT", "GPS_RAW_INT", "ATTITUDE", "VFR_HUD"} <= vehicle
        assert {"COMMAND_ACK", "STATUSTEXT"} <= vehicle
        assert kinds[(i, 100, "CAMERA_TRACKING_GEO_STATUS")] > 50
        assert not {s for s, _, _ in kinds} - {i, 245, GCS_ID}  # nothing of another vehicle
        stamps = [m._timestamp for m in messages]
        assert stamps == sorted(stamps)
        assert run.wall_start_s - 1.0 <= stamps[0]
        assert stamps[-1] <= run.wall_end_s + 1.0
        # the app's setpoints and commands are addressed to this vehicle
        commands = [m for m in messages if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
        assert {m.target_system for m in commands} == {i}
    asked = run.gcs.asked
    assert asked is not None
    heard = read_tlog(run.result.out_dir / f"vehicle-{asked}.tlog")
    assert any(m.get_srcSystem() == GCS_ID and m.get_type() == "COMMAND_LONG" for m in heard), (
        "the second ground station's command is not in the vehicle's log"
    )


async def test_the_tlog_carries_the_real_flight_bank_mode_and_airspeed(run: Run) -> None:
    messages = read_tlog(run.result.out_dir / "vehicle-1.tlog")
    beats = [m for m in messages if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1]
    assert {b.autopilot for b in beats} == {mavlink.MAV_AUTOPILOT_PX4}
    assert {b.type for b in beats} == {mavlink.MAV_TYPE_FIXED_WING}
    modes = {mavutil.mode_string_v10(b) for b in beats}
    assert {"TAKEOFF", "OFFBOARD"} <= modes
    rolls = [m.roll for m in messages if m.get_type() == "ATTITUDE"]
    assert max(abs(r) for r in rolls) > math.radians(5.0)  # the turns of gather and adjust
    huds = [m for m in messages if m.get_type() == "VFR_HUD" and m.airspeed > 5.0]
    assert huds
    assert {h.throttle for h in huds} - {0, 60}, "a fixed throttle is not a flight"
    texts = {m.text for m in messages if m.get_type() == "STATUSTEXT"}
    assert {"Armed by external command", "Takeoff detected"} <= texts


def tool(name: str, *args: str, cwd: Path) -> str:
    done = subprocess.run(
        [sys.executable, str(TOOLS / name), *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    return done.stdout


async def test_pymavlinks_tools_read_the_tlog(run: Run) -> None:
    out = run.result.out_dir
    modes = tool("mavflightmodes.py", "vehicle-1.tlog", cwd=out)
    assert "MAV.flightmode=OFFBOARD" in modes
    assert "MAV.flightmode=TAKEOFF" in modes
    gpx = tool("mavtogpx.py", "vehicle-1.tlog", cwd=out)
    points = int(gpx.split(" with ")[1].split()[0])
    assert points > 100, gpx
    assert (out / "vehicle-1.tlog.gpx").read_text(encoding="utf-8").count("<trkpt") == points
    dump = tool("mavlogdump.py", "--types", "ATTITUDE", "vehicle-2.tlog", cwd=out)
    assert dump.count("ATTITUDE") > 100
