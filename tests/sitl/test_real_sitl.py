"""Optional: the mission flown against a real autopilot's SITL build (issue #13, item 6).

Skipped unless an environment variable points at a build you made yourself (the project never
ships, builds or needs one):

- ``STANDOFF_PX4_SITL``: a PX4 SITL build folder with the SIH airplane, e.g.
  ``PX4-Autopilot/build/px4_sitl_sih`` (``bin/px4`` and ``etc/``; v1.16 was checked). The test
  starts one SIH airplane (airframe 10041, instance 0: system id 1, UDP 14540) in a scratch
  folder and stops it afterwards.
- ``STANDOFF_ARDUPLANE_SITL``: an ArduPlane SITL binary (``build/sitl/bin/arduplane``, 4.6 was
  checked), with ``STANDOFF_ARDUPLANE_DEFAULTS`` its plane parameter file (default: the
  source tree's ``Tools/autotest/models/plane.parm`` next to the build). One instance, system id
  1, TCP 5760, its parameters wiped.

Both bind every interface (0.0.0.0): run them where that is safe (a network namespace with
only loopback, say). Each flies one vehicle through ``configs/test-short.toml``'s timeline (the
target parked 60 s, then 120 m at 3 m/s) with the real autopilot's adapter, in real time (about
three minutes), and checks what the mission must do on the real thing: the hand-over only in the
air, the phase actuator the autopilot honours, the circle reached, nothing refused.
"""

import json
import os
import shutil
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.compose.mission import Mission
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan

pytestmark = [pytest.mark.slow, pytest.mark.asyncio]

PX4_BUILD = os.environ.get("STANDOFF_PX4_SITL")
ARDUPLANE_BIN = os.environ.get("STANDOFF_ARDUPLANE_SITL")
BOOT_S = 20.0  # after start, before the mission connects (the autopilot's EKF settles)


def _one_vehicle(real: str, url: str) -> MissionConfig:
    """test-short's timeline and team limits, one vehicle, the real-autopilot file's link,
    origin, observations (no camera in SITL) and guidance."""
    base = load_config("test-short", MissionConfig)
    file = load_config(real, MissionConfig)
    return base.model_copy(
        update={
            "vehicles": 1,
            "link": file.link.model_copy(update={"connect": [url]}),
            "origin": file.origin,
            "observations": file.observations,
            "guidance": file.guidance,
            "sim": base.sim.model_copy(update={"speedup": 1.0}),
        }
    )


def _started(args: list[str], cwd: Path, env: dict[str, str]) -> subprocess.Popen[bytes]:
    log = (cwd / "autopilot.log").open("wb")
    return subprocess.Popen(
        args, cwd=cwd, env={**os.environ, **env}, stdin=subprocess.DEVNULL, stdout=log, stderr=log
    )


def _stopped(process: subprocess.Popen[bytes]) -> None:
    process.terminate()
    try:
        process.wait(10.0)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait(10.0)


@pytest.fixture
def px4(tmp_path: Path) -> Iterator[Path]:
    if not PX4_BUILD:
        pytest.skip("STANDOFF_PX4_SITL (a PX4 SITL SIH build folder) is not set")
    build = Path(PX4_BUILD)
    work = tmp_path / "px4-0"
    work.mkdir()
    file = load_config("px4-sitl", MissionConfig)
    env = {
        "PX4_SYS_AUTOSTART": "10041",
        "PX4_SIM_MODEL": "sihsim_airplane",
        "PX4_SIMULATOR": "sihsim",
        "PX4_HOME_LAT": str(file.origin.lat_deg),
        "PX4_HOME_LON": str(file.origin.lon_deg),
        "PX4_HOME_ALT": str(file.origin.alt_m),
    }
    process = _started(
        [str(build / "bin" / "px4"), "-d", "-i", "0", "-w", str(work), str(build / "etc")],
        work,
        env,
    )
    try:
        time.sleep(BOOT_S)
        assert process.poll() is None, (work / "autopilot.log").read_text()[-2000:]
        yield tmp_path
    finally:
        _stopped(process)


@pytest.fixture
def arduplane(tmp_path: Path) -> Iterator[Path]:
    if not ARDUPLANE_BIN:
        pytest.skip("STANDOFF_ARDUPLANE_SITL (an ArduPlane SITL binary) is not set")
    binary = Path(ARDUPLANE_BIN)
    defaults = os.environ.get("STANDOFF_ARDUPLANE_DEFAULTS") or str(
        binary.parents[3] / "Tools" / "autotest" / "models" / "plane.parm"
    )
    work = tmp_path / "ap-0"
    work.mkdir()
    o = load_config("ardupilot-sitl", MissionConfig).origin
    args = [str(binary), "-S", "--model", "plane", "--speedup", "1", "-I", "0", "--sysid", "1"]
    args += ["--home", f"{o.lat_deg},{o.lon_deg},{o.alt_m},0", "--defaults", defaults]
    args += ["-w", "--serial0", "tcp:0"]  # wiped parameters; boot without waiting for a client
    process = _started(args, work, {})
    try:
        time.sleep(BOOT_S)
        assert process.poll() is None, (work / "autopilot.log").read_text()[-2000:]
        yield tmp_path
    finally:
        _stopped(process)
        shutil.rmtree(work, ignore_errors=True)


async def _fly(config: MissionConfig, out_dir: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    await Mission(build_plan(config), out_dir).run()
    summary = json.loads((out_dir / "summary.json").read_text())
    events = [json.loads(line) for line in (out_dir / "events.jsonl").read_text().splitlines()]
    return summary, events


def _check_the_flight(
    summary: dict[str, Any], events: list[dict[str, Any]], actuator: str, min_speed: float
) -> None:
    handover = [e for e in events if e["kind"] == "handover"]
    assert len(handover) == 1, handover
    assert handover[0]["height_m"] >= 30.0
    assert handover[0]["airspeed_m_s"] >= min_speed
    actuators = [e for e in events if e["kind"] == "phase_actuator"]
    assert [e["actuator"] for e in actuators] == [actuator]
    assert summary["convergence"]["time_to_circle_s"] is not None, summary["convergence"]
    assert not [e for e in events if e["kind"] in ("command_refused", "pilot_took_over")]
    assert events[-1]["kind"] == "mission_complete"


async def test_px4_sih_airplane_flies_the_mission_by_radius(px4: Path) -> None:
    config = _one_vehicle("px4-sitl", "udpin://0.0.0.0:14540")
    summary, events = await _fly(config, px4 / "run")
    _check_the_flight(summary, events, "radius", config.limits.min_speed_m_s)


async def test_arduplane_flies_the_mission_in_guided_by_speed(arduplane: Path) -> None:
    config = _one_vehicle("ardupilot-sitl", "tcpout://127.0.0.1:5760")
    summary, events = await _fly(config, arduplane / "run")
    _check_the_flight(summary, events, "speed", config.limits.min_speed_m_s)
    # the identification at work: ArduPlane 4.6.2's loop fits eq. (2) loosely, so in this
    # short flight the fit may not yet reach its 5 % standard error (at 0cf9cfd: 20 s of
    # informative flight, 8 % after 100 s); whatever it found is near the adapter's
    # linearised k = 1 /s (the full mission's three vehicles: 0.77-1.08 /s)
    loop = summary["agents"]["1"]["course_loop"]
    assert loop["informative_s"] >= loop["min_s"], loop
    assert loop["rel_se"] is not None, loop
    assert loop["rel_se"] < 0.25, loop
    assert 0.6 <= loop["fit_gain_per_s"] <= 1.6, loop
    identified = [e for e in events if e["kind"] == "course_loop_identified"]
    assert bool(identified) == loop["identified"], (identified, loop)
