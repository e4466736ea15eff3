"""Vehicle link pieces that need no vehicle: URLs, the mission frame, subscriptions, frame and
observation decoding, the link-loss watchdog, and hub errors against real MAVSDK."""

import asyncio
import math
from contextlib import aclosing
from typing import Any

import pytest
from mavsdk.exceptions import ConnectionError as MavsdkConnectionError
from mavsdk.plugins.action import ActionError, ActionResult

from app.adapters.vehicle.autopilots.limits import SetpointLimits
from app.adapters.vehicle.autopilots.velocity import VelocityAdapter
from app.adapters.vehicle.mavsdk import telemetry
from app.adapters.vehicle.mavsdk.broadcast import Broadcast
from app.adapters.vehicle.mavsdk.hub import MavsdkHub
from app.adapters.vehicle.mavsdk.link import LinkConfig, MavsdkVehicleLink
from app.adapters.vehicle.mavsdk.logs import RepeatLimiter
from app.adapters.vehicle.mavsdk.urls import validate_url
from app.core.plant import VehicleEnvelope
from app.errors import ConfigError, LinkError
from app.runtime.ports.vehicle import (
    ClockRebased,
    CourseSpeedCommand,
    GeodeticOrigin,
    LinkLost,
    VehicleClockReset,
)
from sitl.ports import find_free_udp_base_port

ORIGIN = GeodeticOrigin(47.397742, 8.545594, 488.0)
CONFIG = LinkConfig(
    SetpointLimits(VehicleEnvelope(18.0, 12.0, 24.0, 2.0, 0.2)), autopilot="velocity"
)


@pytest.mark.parametrize(
    "url",
    [
        "udpin://0.0.0.0:14540",
        "udpout://192.168.1.10:14550",
        "tcp://127.0.0.1:5760",
        "tcpout://127.0.0.1:5760",
        "serial:///dev/ttyUSB0:57600",
    ],
)
def test_supported_urls_pass(url):
    assert validate_url(url) == url


@pytest.mark.parametrize(
    ("url", "why"),
    [
        ("udp://:14540", "scheme must be one of"),
        ("http://host:80", "scheme must be one of"),
        ("udpin://0.0.0.0", "expected udpin://<host>:<port>"),
        ("udpin://0.0.0.0:99999", "bad port"),
        ("udpin://0.0.0.0:0", "port must be in 1..65535"),
        ("serial:///dev/ttyUSB0", "expected serial:///dev/<device>:<baud>"),
    ],
)
def test_bad_urls_are_config_errors_naming_the_url(url, why):
    with pytest.raises(ConfigError, match=why) as info:
        validate_url(url)
    assert url in str(info.value)


def test_a_hub_needs_a_url():
    with pytest.raises(ConfigError, match="at least one"):
        MavsdkHub([], ORIGIN)


async def test_a_connection_mavsdk_cannot_open_is_a_link_error():
    hub = MavsdkHub(["serial:///dev/standoff-no-such-port:57600"], ORIGIN)
    with pytest.raises(LinkError, match="cannot open vehicle connection") as info:
        async with hub:
            pass
    assert isinstance(info.value.__cause__, MavsdkConnectionError)


async def test_a_vehicle_that_never_appears_times_out_as_a_link_error():
    port = find_free_udp_base_port(1)
    hub = MavsdkHub([f"udpin://127.0.0.1:{port}"], ORIGIN)
    inboxes = [hub.inbox]  # before, while and after the hub is open
    async with hub:
        inboxes.append(hub.inbox)
        with pytest.raises(LinkError, match="no autopilot with system id 2"):
            await hub.system(2, timeout_s=0.3)
    inboxes.append(hub.inbox)
    assert [inbox is None for inbox in inboxes] == [True, False, True]
    with pytest.raises(LinkError, match="hub not open"):
        await hub.system_ids()


def test_origin_round_trip_and_scale():
    east, north, up = ORIGIN.to_enu(*ORIGIN.to_geodetic(120.0, -350.0, 40.0))
    assert east == pytest.approx(120.0, abs=1e-6)
    assert north == pytest.approx(-350.0, abs=1e-6)
    assert up == pytest.approx(40.0, abs=1e-6)
    # a thousandth of a degree of latitude is about 111 m north
    _, north, _ = ORIGIN.to_enu(ORIGIN.latitude_deg + 1e-3, ORIGIN.longitude_deg, 488.0)
    assert north == pytest.approx(111.2, abs=0.2)


@pytest.mark.parametrize(("lat", "lon"), [(91.0, 0.0), (0.0, -181.0), (math.nan, 0.0)])
def test_origin_rejects_impossible_coordinates(lat, lon):
    with pytest.raises(ValueError, match=r"latitude_deg|longitude_deg"):
        GeodeticOrigin(lat, lon)


# ---- subscriptions -----------------------------------------------------------------------------


async def test_a_subscription_sees_what_is_published_after_the_call_until_close():
    broadcast: Broadcast[int] = Broadcast("test", 8)
    broadcast.publish(0)  # before anyone listens: nobody gets it
    subscription = broadcast.subscribe()
    broadcast.publish(1)  # before the first read: kept
    broadcast.publish(2)
    broadcast.close()
    assert [item async for item in subscription] == [1, 2]


async def test_a_lagging_subscriber_loses_the_oldest_items_counted():
    broadcast: Broadcast[int] = Broadcast("test", 3)
    subscription = broadcast.subscribe()
    for item in range(5):
        broadcast.publish(item)
    broadcast.close()
    assert [item async for item in subscription] == [3, 4]  # the end marker took a slot
    assert broadcast.dropped == 2


async def test_a_closed_subscription_no_longer_receives():
    broadcast: Broadcast[int] = Broadcast("test", 3)
    async with aclosing(broadcast.subscribe()) as subscription:
        broadcast.publish(1)
        assert await anext(subscription) == 1
    broadcast.publish(2)  # nobody listening any more, nothing dropped
    assert broadcast.dropped == 0
    assert broadcast.subscribe().__class__.__name__ == "Subscription"


# ---- decoding ----------------------------------------------------------------------------------


def link(clock: Any = None, config: LinkConfig = CONFIG) -> MavsdkVehicleLink:
    """A link that is never opened: its decoding and watchdog need no vehicle."""
    if clock is None:
        return MavsdkVehicleLink(None, 4, ORIGIN, config)
    return MavsdkVehicleLink(None, 4, ORIGIN, config, clock)


def position(t_ms: int, **changes: int) -> dict[str, int]:
    fields = {
        "time_boot_ms": t_ms,
        "lat": round(ORIGIN.latitude_deg * 1e7),
        "lon": round(ORIGIN.longitude_deg * 1e7),
        "alt": 588_000,
        "relative_alt": 100_000,
        "vx": 0,
        "vy": 1500,
        "vz": -100,
        "hdg": 9000,
    }
    fields.update(changes)
    return fields


def test_global_position_becomes_a_frame_in_the_mission_frame():
    frame = link()._frame(position(12_345))
    assert frame is not None
    assert frame.vehicle_id == 4
    assert frame.t_s == 12.345
    assert frame.east_m == pytest.approx(0.0, abs=0.01)
    assert frame.north_m == pytest.approx(0.0, abs=0.01)
    assert frame.up_m == pytest.approx(100.0, abs=0.01)
    assert frame.relative_altitude_m == 100.0
    assert frame.course_rad == pytest.approx(math.pi / 2)  # flying east
    assert frame.ground_speed_m_s == 15.0
    assert (frame.v_east_m_s, frame.v_north_m_s) == (15.0, 0.0)
    assert frame.climb_rate_m_s == 1.0
    assert frame.in_air  # 100 m above home, before any landed state arrived


def test_a_vehicle_near_home_height_is_on_the_ground_until_it_says_otherwise():
    vehicle = link()
    frame = vehicle._frame(position(1_000, relative_alt=300))
    assert frame is not None
    assert not frame.in_air
    vehicle._in_air = True
    frame = vehicle._frame(position(1_100, relative_alt=300))
    assert frame is not None
    assert frame.in_air


def test_course_of_a_vehicle_at_rest_is_its_heading():
    frame = link()._frame(position(1000, vy=0, hdg=27000))
    assert frame is not None
    assert frame.course_rad == pytest.approx(math.radians(270.0))


async def test_out_of_order_frames_are_dropped_and_a_reboot_is_an_event():
    vehicle = link()
    events = vehicle.events()
    first = vehicle._frame(position(20_000))
    vehicle._latest = first
    assert vehicle._frame(position(19_900)) is None  # late UDP packet
    assert vehicle._frame(position(20_000)) is None  # duplicate
    assert vehicle.counters.stale_frames == 2
    rebooted = vehicle._frame(position(1_000))
    assert rebooted is not None
    assert rebooted.t_s == 1.0
    vehicle._events.close()
    assert [event async for event in events] == [VehicleClockReset(4, 1.0, 20.0)]


class HostClock:
    """Mission time on the host, set by the test."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def mapped(host: HostClock) -> MavsdkVehicleLink:
    return MavsdkVehicleLink(None, 4, ORIGIN, CONFIG, mission_clock=host)


def test_boot_clocks_seconds_and_minutes_apart_give_one_mission_time():
    host = HostClock()
    # booted 2.1 s, 4.4 s and 3 minutes before mission time 0
    links = [mapped(host) for _ in range(3)]
    booted = (2.1, 4.4, 180.0)
    for k in range(100):
        host.now_s = 0.1 * k
        for i, (vehicle, boot0) in enumerate(zip(links, booted, strict=True)):
            delay = 0.001 * ((7 * k + 3 * i) % 20)  # 0-19 ms of transport jitter
            host.now_s = 0.1 * k + delay
            frame = vehicle._frame(position(round(1000 * (boot0 + 0.1 * k))))
            assert frame is not None
            vehicle._latest = frame
    times = [vehicle._latest.t_s for vehicle in links if vehicle._latest is not None]
    assert max(times) - min(times) < 0.02
    assert times[0] == pytest.approx(9.9, abs=0.02)


async def test_a_reboot_rebases_the_mapped_clock_and_mission_time_goes_on():
    host = HostClock()
    vehicle = mapped(host)
    events = vehicle.events()
    for k in range(50):
        host.now_s = 0.1 * k + 0.002
        frame = vehicle._frame(position(300_000 + 100 * k))
        assert frame is not None
        vehicle._latest = frame
    assert vehicle._frame(position(304_800)) is None  # a late packet is still dropped
    host.now_s = 4.9 + 10.0  # 10 s later it has rebooted: its clock restarts at 0.8 s
    rebooted = vehicle._frame(position(800))
    assert rebooted is not None
    assert rebooted.t_s == pytest.approx(14.9)
    vehicle._latest = rebooted
    host.now_s = 15.0 + 0.003
    after = vehicle._frame(position(900))
    assert after is not None
    assert after.t_s == pytest.approx(15.0)
    assert vehicle.counters.clock_rebases == 1
    vehicle._events.close()
    [event] = [event async for event in events]
    assert isinstance(event, ClockRebased)
    assert (event.reason, event.boot_s, event.previous_boot_s) == ("reboot", 0.8, 304.9)
    assert event.t_s == pytest.approx(14.9)


def test_frames_carry_boot_time_until_the_mission_epoch_is_known_then_mission_time():
    epoch: list[float | None] = [None]
    host = HostClock()

    def deferred() -> float | None:
        return None if epoch[0] is None else host.now_s - epoch[0]

    vehicle = MavsdkVehicleLink(None, 4, ORIGIN, CONFIG, mission_clock=deferred)
    before = vehicle._frame(position(500_000))  # booted 500 s ago, no epoch yet
    assert before is not None
    assert before.t_s == 500.0
    vehicle._latest = before
    host.now_s, epoch[0] = 1000.2, 1000.0  # the ground's epoch arrives: mission time 0.2 s
    after = vehicle._frame(position(500_100))
    assert after is not None  # not dropped as older than the boot-stamped frame
    assert after.t_s == pytest.approx(0.2)
    vehicle._latest = after
    host.now_s = 1000.3
    later = vehicle._frame(position(500_200))
    assert later is not None
    assert later.t_s == pytest.approx(0.3)
    assert vehicle.counters.clock_rebases == 0


def test_the_airspeed_of_vfr_hud_reaches_the_frames():
    vehicle = link()
    assert vehicle._frame(position(1_000)).airspeed_m_s is None  # type: ignore[union-attr]
    vehicle._airspeed_m_s = telemetry.vfr_hud_airspeed({"airspeed": 16.5})
    assert vehicle._frame(position(1_100)).airspeed_m_s == 16.5  # type: ignore[union-attr]
    assert telemetry.vfr_hud_airspeed({"airspeed": float("nan")}) is None
    with pytest.raises(KeyError):
        telemetry.vfr_hud_airspeed({})


class RestoringAdapter:
    def __init__(self, fail: bool = False) -> None:
        self.fail = fail
        self.restored = 0

    async def restore_params(self) -> None:
        self.restored += 1
        if self.fail:
            raise LinkError("param set refused")


@pytest.mark.parametrize("fail", [False, True])
async def test_the_parameters_are_restored_on_exit_and_a_failure_is_logged(fail, caplog):
    vehicle = link()
    adapter = RestoringAdapter(fail)
    vehicle._adapter = adapter  # type: ignore[assignment]
    vehicle._link_ok = True
    await vehicle.__aexit__(None, None, None)
    assert adapter.restored == 1
    assert ("restoring its parameters failed" in caplog.text) is fail


async def test_a_lost_link_restores_nothing_and_says_so(caplog):
    vehicle = link()
    adapter = RestoringAdapter()
    vehicle._adapter = adapter  # type: ignore[assignment]
    await vehicle.__aexit__(None, None, None)
    assert adapter.restored == 0
    assert "parameters the mission changed are not restored" in caplog.text


def geo_status(**changes: Any) -> dict[str, Any]:
    fields: dict[str, Any] = {
        "tracking_status": 1,
        "lat": round(ORIGIN.latitude_deg * 1e7) + 900,  # about 10 m north
        "lon": round(ORIGIN.longitude_deg * 1e7),
        "alt": 488.0,
        "h_acc": 3.0,
        "v_acc": None,  # MAVSDK's JSON for a NaN float
    }
    fields.update(changes)
    return fields


def test_tracking_status_becomes_an_observation_at_the_vehicle_time():
    vehicle = link()
    assert vehicle._observation(geo_status()) is None  # no telemetry yet: no time to stamp
    vehicle._latest = vehicle._frame(position(7_500))
    observation = vehicle._observation(geo_status())
    assert observation is not None
    assert observation.t_s == 7.5
    assert observation.north_m == pytest.approx(10.0, abs=0.05)
    assert observation.east_m == pytest.approx(0.0, abs=0.01)
    assert observation.sigma_m == 3.0


@pytest.mark.parametrize(
    ("changes", "sigma"), [({"h_acc": None}, None), ({"h_acc": 0.0}, None), ({}, 3.0)]
)
def test_unknown_accuracy_gives_no_sigma(changes, sigma):
    vehicle = link()
    vehicle._latest = vehicle._frame(position(1_000))
    observation = vehicle._observation(geo_status(**changes))
    assert observation is not None
    assert observation.sigma_m == sigma


@pytest.mark.parametrize("status", [0, 2, 3])
def test_idle_or_failing_tracker_gives_no_observation(status):
    vehicle = link()
    vehicle._latest = vehicle._frame(position(1_000))
    assert vehicle._observation(geo_status(tracking_status=status)) is None


def test_malformed_fields_raise_for_the_reader_to_count():
    with pytest.raises(KeyError):
        link()._frame({"time_boot_ms": 1})


# ---- watchdog ----------------------------------------------------------------------------------


async def test_watchdog_declares_the_link_lost_after_the_timeout_of_silence():
    now = [100.0]
    config = LinkConfig(
        SetpointLimits(VehicleEnvelope(18.0, 12.0, 24.0, 2.0, 0.2)), link_timeout_s=0.04
    )
    vehicle = link(lambda: now[0], config)
    vehicle._latest = vehicle._frame(position(3_000))
    vehicle._last_rx = 100.0
    vehicle._link_ok = True
    async with (
        aclosing(vehicle.events()) as events,
        aclosing(vehicle.telemetry()) as frames,
        asyncio.TaskGroup() as group,
    ):
        watchdog = group.create_task(vehicle._watchdog(), name="watchdog")
        await asyncio.sleep(0.05)  # silent for no time on the injected clock: still up
        up_before = vehicle.link_ok
        now[0] = 100.5
        async with asyncio.timeout(1.0):
            event = await anext(events)
            frame = await anext(frames)
        watchdog.cancel()
    assert up_before
    assert event == LinkLost(4, 3.0, 0.5)
    assert frame.link_ok is False
    assert frame.t_s == 3.0
    assert not vehicle.link_ok
    assert vehicle.counters.link_losses == 1


# ---- commands on an unopened link with recorders in place of the plugins ------------------------


class AcceptingOffboard:
    def __init__(self) -> None:
        self.calls: list[str] = []

    async def set_velocity_ned(self, velocity_ned_yaw: Any) -> None:
        self.calls.append("velocity")

    async def set_position_velocity_ned(self, position_ned_yaw: Any, velocity_ned_yaw: Any) -> None:
        self.calls.append("position+velocity")

    async def start(self) -> None:
        self.calls.append("start")

    async def stop(self) -> None:
        self.calls.append("stop")


class RefusingAction:
    def __init__(self, result: ActionResult) -> None:
        self.result = result
        self.calls = 0

    async def arm(self) -> None:
        self.calls += 1
        raise ActionError(self.result, "arm()")


async def test_commands_on_a_link_that_is_not_open_say_so():
    with pytest.raises(LinkError, match="link not open"):
        await link().arm()


async def test_a_refused_arm_is_a_link_error_with_the_result():
    vehicle = link()
    vehicle._adapter = VelocityAdapter(
        vehicle_id=4, offboard=AcceptingOffboard(), limits=CONFIG.limits
    )
    action = RefusingAction(ActionResult.COMMAND_DENIED)
    vehicle._action = action
    with pytest.raises(LinkError, match="vehicle 4: arm refused: COMMAND_DENIED") as info:
        await vehicle.arm()
    assert isinstance(info.value.__cause__, ActionError)
    vehicle._armed = True
    await vehicle.arm()  # already armed: nothing asked
    assert action.calls == 1


async def test_an_offboard_start_the_vehicle_acks_but_never_shows_is_a_link_error():
    config = LinkConfig(
        SetpointLimits(VehicleEnvelope(18.0, 12.0, 24.0, 2.0, 0.2)), mode_confirm_timeout_s=0.1
    )
    vehicle = link(config=config)
    offboard = AcceptingOffboard()
    vehicle._adapter = VelocityAdapter(vehicle_id=4, offboard=offboard, limits=config.limits)
    vehicle._latest = vehicle._frame(position(2_000))
    vehicle._mode = "HOLD"
    with pytest.raises(
        LinkError, match=r"vehicle 4 accepted OFFBOARD but still reports HOLD after 0\.1 s"
    ):
        await vehicle.start_offboard(CourseSpeedCommand(math.pi / 2, 15.0))
    assert offboard.calls == ["velocity", "start"]
    with pytest.raises(LinkError, match="start_offboard before send"):
        await vehicle.send(CourseSpeedCommand(math.pi / 2, 15.0))


def test_repeat_limiter_lets_a_repeated_line_through_once_per_window_with_a_count():
    now = [0.0]
    limiter = RepeatLimiter(5.0, clock=lambda: now[0])
    assert limiter.admit("Sending message failed") == 0
    for _ in range(99):  # a cut link at 20 Hz for 5 s
        now[0] += 0.05
        assert limiter.admit("Sending message failed") is None
    assert limiter.admit("another line") == 0  # other lines are not held back by it
    now[0] = 5.0
    assert limiter.admit("Sending message failed") == 99
    now[0] += 60.0
    assert limiter.admit("Sending message failed") == 0


def test_repeat_limiter_refuses_a_bad_window():
    with pytest.raises(ValueError, match="window_s"):
        RepeatLimiter(math.nan)
