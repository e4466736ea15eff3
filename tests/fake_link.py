"""A vehicle link for tests of the agent loop: fed by the test through queues, silent where the
test puts nothing (a stream with nothing queued waits forever), every command accepted."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

from app.adapters.vehicle.link import (
    CourseSpeedCommand,
    LinkEvent,
    TargetObservation,
    VehicleTelemetry,
)


class QueueLink:
    """``put`` a telemetry frame (it becomes ``latest``, as on a real link whose reader ran
    while the agent was busy) and ``seen`` camera fixes; ``sent`` counts the setpoints."""

    vehicle_id = 1
    autopilot_name = "fake"
    link_ok = True

    def __init__(self) -> None:
        self.frames: asyncio.Queue[VehicleTelemetry] = asyncio.Queue()
        self.seen: asyncio.Queue[TargetObservation] = asyncio.Queue()
        self.latest: VehicleTelemetry | None = None
        self.sent = 0

    def put(self, frame: VehicleTelemetry) -> None:
        self.latest = frame
        self.frames.put_nowait(frame)

    async def wait_ready(self, timeout_s: float) -> VehicleTelemetry:
        raise NotImplementedError

    async def arm(self) -> None: ...

    async def take_off(self, timeout_s: float) -> None: ...

    async def start_offboard(self, first: CourseSpeedCommand) -> None: ...

    async def send(self, command: CourseSpeedCommand) -> None:
        self.sent += 1

    async def hold(self) -> None: ...

    async def telemetry(self) -> AsyncIterator[VehicleTelemetry]:
        while True:
            yield await self.frames.get()

    async def observations(self) -> AsyncIterator[TargetObservation]:
        while True:
            yield await self.seen.get()

    async def events(self) -> AsyncIterator[LinkEvent]:
        await asyncio.Event().wait()
        yield  # type: ignore[misc]  # never reached: no events
