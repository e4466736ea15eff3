"""``[link] gcs_forward`` and ``fly --gcs`` / ``--no-gcs``: where a ground station beside the
app sees the vehicles, checked like the rest of the file."""

import argparse

import pytest

from app.adapters.vehicle.mavsdk.urls import UdpEndpoint
from app.cli.fly import gcs_line, with_gcs
from app.compose.parts import gcs_endpoint
from app.config import load_config
from app.config.loading import validate_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.errors import ConfigError


def config_with(**link: object) -> MissionConfig:
    raw = load_config("test-short", MissionConfig).model_dump()
    raw["link"].update(link)
    return validate_config(raw, MissionConfig, "test")


def test_the_default_is_qgroundcontrols_port_as_px4_sitl_sends_it():
    config = load_config("test-short", MissionConfig)
    assert config.link.gcs_forward == "udpout:127.0.0.1:14550"
    assert gcs_endpoint(build_plan(config)) == UdpEndpoint("udpout", "127.0.0.1", 14550)
    assert "QGroundControl's default port" in gcs_line(config)


def test_endpoints_are_normalised_and_off_turns_it_off():
    assert config_with(gcs_forward="10.0.0.5:14550").link.gcs_forward == "udpout:10.0.0.5:14550"
    udpin = config_with(gcs_forward="udpin://0.0.0.0:14560")
    assert udpin.link.gcs_forward == "udpin:0.0.0.0:14560"
    assert "PORT+i" in gcs_line(udpin) or "+i" in gcs_line(udpin)
    off = config_with(gcs_forward="off")
    assert gcs_endpoint(build_plan(off)) is None
    assert "none" in gcs_line(off)


@pytest.mark.parametrize("bad", ["14550", "udpout:127.0.0.1:", "tcp:1.2.3.4:5760", "x:70000"])
def test_a_bad_endpoint_is_refused_naming_it(bad):
    with pytest.raises(ConfigError, match="gcs_forward"):
        config_with(gcs_forward=bad)


def test_the_command_line_overrides_the_file():
    config = load_config("test-short", MissionConfig)
    gcs = with_gcs(config, argparse.Namespace(gcs="127.0.0.1:24550", no_gcs=False))
    assert gcs.link.gcs_forward == "udpout:127.0.0.1:24550"
    off = with_gcs(config, argparse.Namespace(gcs=None, no_gcs=True))
    assert off.link.gcs_forward == "off"
    assert with_gcs(config, argparse.Namespace(gcs=None, no_gcs=False)) is config
    with pytest.raises(ConfigError, match="--gcs"):
        with_gcs(config, argparse.Namespace(gcs="nonsense", no_gcs=False))


def test_the_camera_component_id_is_a_mavlink_component_not_the_autopilot():
    assert config_with(camera_component_id=154).link.camera_component_id == 154
    for bad in (0, 1, 256):
        with pytest.raises(ConfigError, match="camera_component_id"):
            config_with(camera_component_id=bad)
