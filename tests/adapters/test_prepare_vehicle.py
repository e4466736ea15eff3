"""``prepare_vehicle``: the steps before a vehicle flies the mission, on a fake link."""

import asyncio
from dataclasses import replace

import pytest

from app.compose.parts import bring_up
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.errors import LinkError
from app.runtime.ports.vehicle import CourseSpeedCommand, VehicleTelemetry
from app.runtime.vehicle import prepare_vehicle
from tests.support.fake_link import frame


def frame_at(east_m: float, north_m: float) -> VehicleTelemetry:
    """Vehicle 2 on the ground, disarmed, in HOLD."""
    return frame(
        1.0,
        east_m,
        north_m,
        vehicle_id=2,
        altitude_m=500.0,
        relative_altitude_m=0.0,
        up_m=0.0,
        course_rad=0.3,
        ground_speed_m_s=0.0,
        v_east_m_s=0.0,
        flight_mode="HOLD",
        armed=False,
        in_air=False,
        link_ok=True,
    )


class FakeLink:
    vehicle_id = 2
    autopilot_name = "velocity"

    def __init__(self, frame: VehicleTelemetry) -> None:
        self.frame = frame
        self.latest: VehicleTelemetry | None = None
        self.steps: list[str] = []

    async def wait_ready(self, timeout_s: float) -> VehicleTelemetry:
        self.steps.append("ready")
        return self.frame

    async def arm(self) -> None:
        self.steps.append("arm")

    async def take_off(self, timeout_s: float, altitude_m: float | None = None) -> None:
        self.steps.append("take-off")
        # climbed out: above the hand-over height, at flying speed
        self.latest = replace(
            self.frame, relative_altitude_m=60.0, ground_speed_m_s=16.0, in_air=True
        )

    async def start_offboard(self, first: CourseSpeedCommand) -> None:
        self.steps.append("offboard")


class Events:
    def __init__(self) -> None:
        self.kinds: list[str] = []

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        self.kinds.append(kind)


async def test_a_vehicle_near_the_origin_is_armed_launched_and_put_in_offboard():
    plan = build_plan(load_config("hil", MissionConfig))
    link, events = FakeLink(frame_at(-1200.0, 300.0)), Events()
    await prepare_vehicle(link, bring_up(plan, 1), events)  # type: ignore[arg-type]
    assert link.steps == ["ready", "arm", "take-off", "offboard"]
    assert events.kinds == ["handover", "offboard"]


async def test_a_vehicle_far_from_the_mission_origin_is_refused_before_it_is_armed():
    # e.g. an ArduPilot SITL at its default home flown with a config whose origin is elsewhere
    plan = build_plan(load_config("hil", MissionConfig))
    link = FakeLink(frame_at(-2.744e6, 1.855e6))
    with pytest.raises(LinkError, match=r"vehicle 2 is 3312 km from the mission's origin"):
        await prepare_vehicle(link, bring_up(plan, 1), Events())  # type: ignore[arg-type]
    assert link.steps == ["ready"]


async def test_the_hand_over_releases_its_telemetry_subscription() -> None:
    """Frames published after the hand-over are queued for nobody: a reader left behind
    would lose (drop) frames at the vehicle's rate for the rest of the mission."""
    from app.adapters.vehicle.mavsdk.broadcast import Broadcast
    from app.runtime.vehicle import wait_for_handover

    plan_link = FakeLink(frame_at(10.0, 10.0))
    stream: Broadcast[VehicleTelemetry] = Broadcast("vehicle 2 telemetry", queue_size=4)
    plan_link.telemetry = stream.subscribe  # type: ignore[attr-defined]
    climbing = replace(plan_link.frame, relative_altitude_m=5.0, ground_speed_m_s=9.0, in_air=True)
    flying = replace(climbing, relative_altitude_m=60.0, ground_speed_m_s=16.0)

    async def climb() -> None:
        await asyncio.sleep(0.01)
        stream.publish(climbing)
        stream.publish(flying)

    class Events:
        def emit(self, kind: str, t_s: float, **fields: object) -> None: ...

    plan = build_plan(load_config("test-short", MissionConfig))
    task = asyncio.create_task(climb())
    ready = await wait_for_handover(plan_link, bring_up(plan, 1), Events())  # type: ignore[arg-type]
    await task
    assert ready is flying
    for _ in range(20):
        stream.publish(flying)
    assert stream.dropped == 0
