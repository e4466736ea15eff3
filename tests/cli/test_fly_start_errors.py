"""What ``standoff fly`` says when it cannot start: the port that is taken, and the reason a
simulator stopped (from its simulator.log), never a bare "no output"."""

import asyncio
import dataclasses
import socket

import pytest

from app.cli import main
from app.compose.simulator import failure_reason, simulator_process
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan, sim_config
from app.errors import LinkError
from sitl.ports import find_free_udp_base_port
from sitl.server import SimulatorServer


def test_a_taken_simulator_port_is_named():
    plan = build_plan(load_config("test-short", MissionConfig))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        config = sim_config(plan, find_free_udp_base_port(3))
        bound = dataclasses.replace(config, bind_base_port=port)

        async def start() -> None:
            async with SimulatorServer(bound):
                pass

        with pytest.raises(OSError, match=f"vehicle 1: cannot bind UDP 127.0.0.1:{port}"):
            asyncio.run(start())


def test_the_failure_reason_is_the_last_line_of_the_simulators_log(tmp_path):
    log = tmp_path / "simulator.log"
    log.write_text("Traceback (most recent call last):\n  ...\nValueError: bad thing\n\n")
    assert failure_reason(log, 1).startswith("ValueError: bad thing (see ")
    log.write_text("")
    assert failure_reason(log, 3) == f"it exited with code 3 and wrote nothing to {log}"


@pytest.mark.slow
async def test_a_simulator_that_cannot_start_says_why(tmp_path):
    config = load_config("test-short", MissionConfig)
    with pytest.raises(LinkError, match=r"did not start: error: .*65534 .*outside 1\.\.65535"):
        async with simulator_process(config, 3, 65534, tmp_path):
            pass
    assert "65534" in (tmp_path / "simulator.log").read_text(encoding="utf-8")


@pytest.mark.slow
def test_fly_names_the_vehicle_port_that_is_taken(tmp_path, capsys):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        code = main(
            [
                "fly",
                "test-short",
                "--base-port",
                str(port),
                "--quiet",
                "--no-stdin",
                "--no-gcs",
                "--out",
                str(tmp_path / "run"),
            ]
        )
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert f"UDP 127.0.0.1:{port}" in err[0]
