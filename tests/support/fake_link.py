"""A vehicle link for tests of the agent loop: fed by the test through queues, silent where the
test puts nothing (a stream with nothing queued waits forever), every command accepted unless
the test made the vehicle leave offboard (``leave_offboard``: ``send`` then raises, as a real
link's does, until ``start_offboard``)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncGenerator, AsyncIterator

from app.runtime.ports.vehicle import (
    CourseSpeedCommand,
    LeftOffboard,
    LinkEvent,
    OffboardLostError,
    TargetObservation,
    VehicleTelemetry,
)


class QueueLink:
    """``put`` a telemetry frame (it becomes ``latest``, as on a real link whose reader ran
    while the agent was busy) and ``seen`` camera fixes; ``sent`` counts the setpoints and
    ``commands`` keeps them, ``offboard_starts`` and ``holds`` count those calls."""

    vehicle_id = 1
    autopilot_name = "fake"
    link_ok = True
    honours_speed = True
    course_error_limit_rad: float | None = None

    def __init__(self) -> None:
        self.frames: asyncio.Queue[VehicleTelemetry] = asyncio.Queue()
        self.seen: asyncio.Queue[TargetObservation] = asyncio.Queue()
        self.latest: VehicleTelemetry | None = None
        self.sent = 0
        self.commands: list[CourseSpeedCommand] = []
        self.offboard_starts = 0
        self.holds = 0
        self.mode = "OFFBOARD"
        self.link_events: asyncio.Queue[LinkEvent] = asyncio.Queue()

    def put(self, frame: VehicleTelemetry) -> None:
        self.latest = frame
        self.frames.put_nowait(frame)

    async def wait_ready(self, timeout_s: float) -> VehicleTelemetry:
        raise NotImplementedError

    async def arm(self) -> None: ...

    async def take_off(self, timeout_s: float, altitude_m: float | None = None) -> None: ...

    def leave_offboard(self, mode: str, t_s: float) -> None:
        """Someone else put the vehicle in ``mode``: the event, and ``send`` refused."""
        self.mode = mode
        self.link_events.put_nowait(LeftOffboard(self.vehicle_id, t_s, mode))

    async def start_offboard(self, first: CourseSpeedCommand) -> None:
        self.offboard_starts += 1
        self.mode = "OFFBOARD"
        self.commands.append(first)

    async def send(self, command: CourseSpeedCommand) -> None:
        if self.mode != "OFFBOARD":
            raise OffboardLostError(f"vehicle {self.vehicle_id} left offboard (now {self.mode})")
        self.sent += 1
        self.commands.append(command)

    async def hold(self) -> None:
        self.holds += 1

    async def telemetry(self) -> AsyncGenerator[VehicleTelemetry, None]:
        while True:
            yield await self.frames.get()

    async def observations(self) -> AsyncIterator[TargetObservation]:
        while True:
            yield await self.seen.get()

    async def events(self) -> AsyncIterator[LinkEvent]:
        while True:
            yield await self.link_events.get()


def frame(t_s: float, east_m: float, north_m: float, **changes: object) -> VehicleTelemetry:
    """A telemetry frame at (east, north), 100 m up, flying east at 14 m/s in offboard;
    ``changes`` replace any other field."""
    fields: dict[str, object] = {
        "vehicle_id": 1,
        "t_s": t_s,
        "latitude_deg": 0.0,
        "longitude_deg": 0.0,
        "altitude_m": 100.0,
        "relative_altitude_m": 100.0,
        "east_m": east_m,
        "north_m": north_m,
        "up_m": 100.0,
        "course_rad": 1.5708,
        "ground_speed_m_s": 14.0,
        "v_east_m_s": 14.0,
        "v_north_m_s": 0.0,
        "climb_rate_m_s": 0.0,
        "flight_mode": "OFFBOARD",
        "armed": True,
        "in_air": True,
        "link_ok": True,
    }
    fields.update(changes)
    return VehicleTelemetry(**fields)  # type: ignore[arg-type]
