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


def test_the_ground_stations_port_is_never_a_simulated_vehicles(tmp_path, monkeypatch, caplog):
    # at 14540 + i, vehicle 11's port is QGroundControl's 14550, where every relay sends its
    # copies of every vehicle's traffic: that vehicle heard the whole team as itself and its
    # arming timed out; the simulator now takes other ports
    from contextlib import AsyncExitStack, asynccontextmanager

    from app.adapters.vehicle.mavsdk.urls import UdpEndpoint
    from app.compose import mission as mission_module
    from app.compose.parts import gcs_ports

    assert gcs_ports(UdpEndpoint("udpout", "127.0.0.1", 14550), 20) == {14550}
    assert gcs_ports(UdpEndpoint("udpout", "10.0.0.5", 14550), 20) == set()
    assert gcs_ports(UdpEndpoint("udpin", "0.0.0.0", 14600), 3) == {14600, 14601, 14602}
    assert gcs_ports(None, 3) == set()

    started: list[int] = []

    @asynccontextmanager
    async def fake_simulator(config, vehicles, base_port, workdir):
        started.append(base_port)
        yield None

    monkeypatch.setattr(mission_module, "simulator_process", fake_simulator)
    config = load_config("test-short", MissionConfig)
    assert config.link.gcs_forward == "udpout:127.0.0.1:14550"
    assert config.sim.base_port == 14540

    async def urls(vehicles: int) -> list[str]:
        plan = build_plan(config, vehicles=vehicles)
        async with AsyncExitStack() as stack:
            return await mission_module.Mission(plan, tmp_path)._vehicle_urls(stack)

    team = asyncio.run(urls(12))
    ports = [int(url.rsplit(":", 1)[1]) for url in team]
    assert len(ports) == 12
    assert ports == list(range(started[0], started[0] + 12))
    assert 14550 not in ports
    assert "the ground station's port 14550 is among them" in caplog.text
