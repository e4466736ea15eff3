"""Config values bounded where physics or the machine bounds them, and vehicle URLs checked
up front with one line (issue #14)."""

from pathlib import Path

import pytest
from pydantic import ValidationError

from app.adapters.vehicle.mavsdk.urls import validate_url
from app.config.mission import SimSettings, StandbyConfig
from app.config.schema import VehicleStartConfig
from app.errors import ConfigError


@pytest.mark.parametrize("value", [1e308, -2e6, 1.000001e6])
def test_positions_beyond_1000_km_of_the_origin_are_refused(value: float) -> None:
    with pytest.raises(ValidationError, match="east_m"):
        StandbyConfig(east_m=value, north_m=0.0)
    with pytest.raises(ValidationError, match="north_m"):
        VehicleStartConfig(east_m=0.0, north_m=value, course_deg=0.0, speed_m_s=14.0)
    assert StandbyConfig(east_m=1e6, north_m=-1e6).east_m == 1e6


@pytest.mark.parametrize("value", [1e9, 100.5, 0.0])
def test_a_speedup_the_machine_cannot_give_is_refused(value: float) -> None:
    with pytest.raises(ValidationError, match="speedup"):
        SimSettings(speedup=value)
    assert SimSettings(speedup=100.0).speedup == 100.0


@pytest.mark.parametrize("url", ["udpin://[::1:26960", "udpout://[zz]:1"])
def test_a_malformed_vehicle_url_is_one_config_error(url: str) -> None:
    with pytest.raises(ConfigError, match="vehicle URL"):
        validate_url(url)


def test_two_urls_for_three_vehicles_are_refused_before_anything_starts(tmp_path: Path) -> None:
    from app.compose.mission import Mission
    from app.config import load_config
    from app.config.mission import MissionConfig
    from app.config.plan import build_plan

    plan = build_plan(load_config("test-short", MissionConfig))
    assert plan.count == 3
    urls = ["udpin://127.0.0.1:14540", "udpin://127.0.0.1:14541"]
    with pytest.raises(ConfigError, match="2 vehicle URLs for 3 vehicles"):
        Mission(plan, tmp_path, connect=urls)
    Mission(plan, tmp_path, connect=urls[:1])  # one URL carrying them all


def test_a_config_with_two_urls_for_three_vehicles_is_refused() -> None:
    from app.config import load_config
    from app.config.mission import MissionConfig

    config = load_config("test-short", MissionConfig)
    data = config.model_dump()
    data["link"]["connect"] = ["udpin://127.0.0.1:14540", "udpin://127.0.0.1:14541"]
    with pytest.raises(ValidationError, match="2 URLs for 3 vehicles"):
        MissionConfig.model_validate(data)
    data["link"]["connect"] = data["link"]["connect"][:1]
    assert MissionConfig.model_validate(data).link.connect == ["udpin://127.0.0.1:14540"]
