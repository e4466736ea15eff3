"""The autopilot's own wind estimate reaches the frames: PX4's WIND_COV and ArduPilot's WIND
from the built-in simulator over real UDP MAVLink, decoded into (east, north) where the air
moves to."""

import asyncio
import math
from contextlib import aclosing

import pytest

from app.adapters.vehicle.autopilots.limits import SetpointLimits
from app.adapters.vehicle.mavsdk import telemetry
from app.adapters.vehicle.mavsdk.hub import MavsdkHub
from app.adapters.vehicle.mavsdk.link import LinkConfig
from app.core.plant import VehicleEnvelope
from sitl.config import WindConfig
from tests.adapters.test_vehicle_link_sim import origin_of, urls_of
from tests.support.sitl_fixtures import running_sim, sim_config

LIMITS = SetpointLimits(VehicleEnvelope(18.0, 12.0, 24.0, 2.0, 0.2))


@pytest.mark.parametrize(
    ("autopilot", "adapter"), [("px4", "px4-fixed-wing"), ("arduplane", "arduplane")]
)
async def test_the_autopilots_wind_comes_with_the_frames(autopilot: str, adapter: str) -> None:
    """A steady wind of 3 m/s east and 2 m/s south: the frames carry it as (3, -2) once the
    autopilot has sent its estimate (PX4 every second, ArduPlane with its EXTRA3 stream)."""
    wind = WindConfig(east_m_s=3.0, north_m_s=-2.0)
    config = sim_config(1, speedup=2.0, autopilot=autopilot, wind=wind)
    async with (
        asyncio.timeout(30.0),
        running_sim(config) as sim,
        MavsdkHub(urls_of(sim), origin_of(sim)) as hub,
        hub.link(1, LinkConfig(LIMITS, arduplane_airspeed_check=False)) as link,
    ):
        assert link.autopilot_name == adapter
        await link.wait_ready(10.0)
        async with aclosing(link.telemetry()) as frames:
            async for frame in frames:
                if frame.wind_m_s is not None:
                    break
        assert frame.wind_m_s is not None
        east, north = frame.wind_m_s
        assert east == pytest.approx(3.0, abs=1e-3)
        assert north == pytest.approx(-2.0, abs=1e-3)


def test_wind_messages_decode_to_where_the_air_moves() -> None:
    # PX4: wind_x is north, wind_y east (MavlinkStreamWindCov)
    assert telemetry.wind_cov({"wind_x": -2.0, "wind_y": 3.0}) == (3.0, -2.0)
    assert telemetry.wind_cov({"wind_x": math.nan, "wind_y": 3.0}) is None
    # ArduPilot: the direction the wind comes from; from the north (0 deg) it blows south
    from_north = telemetry.ardupilot_wind({"direction": 0.0, "speed": 4.0})
    assert from_north is not None
    assert from_north[0] == pytest.approx(0.0, abs=1e-9)
    assert from_north[1] == pytest.approx(-4.0)
    from_west = telemetry.ardupilot_wind({"direction": -90.0, "speed": 2.0})
    assert from_west is not None
    assert from_west[0] == pytest.approx(2.0)
    assert from_west[1] == pytest.approx(0.0, abs=1e-9)
    assert telemetry.ardupilot_wind({"direction": 10.0, "speed": -1.0}) is None
    assert telemetry.ardupilot_wind({"direction": math.inf, "speed": 1.0}) is None


@pytest.mark.parametrize(
    ("autopilot", "config", "adapter", "only_its_own"),
    [
        ("px4", LinkConfig(LIMITS, autopilot="velocity"), "velocity", set()),
        (
            "px4",
            LinkConfig(LIMITS, px4_offboard_loss_action=None),
            "px4-fixed-wing",
            {"local-position"},
        ),
        (
            "arduplane",
            LinkConfig(LIMITS, arduplane_airspeed_check=False),
            "arduplane",
            {"attitude"},
        ),
    ],
)
async def test_a_link_reads_only_the_messages_its_adapter_uses(
    autopilot: str, config: LinkConfig, adapter: str, only_its_own: set[str]
) -> None:
    """Every message read is a call from MAVSDK's callback thread into Python: the bank
    (ATTITUDE) is read for ArduPlane's turn fit alone, the local position for PX4's setpoints
    alone, though the simulator streams both to every link."""
    sim = sim_config(1, speedup=2.0, autopilot=autopilot)
    async with (
        asyncio.timeout(30.0),
        running_sim(sim) as running,
        MavsdkHub(urls_of(running), origin_of(running)) as hub,
        hub.link(1, config) as link,
    ):
        assert link.autopilot_name == adapter
        await link.wait_ready(10.0)
        assert {"heartbeat", "position", "airspeed", "wind", "observations"} <= set(link.readers)
        assert set(link.readers) & {"attitude", "local-position"} == only_its_own
