"""MAVSDK's offboard and MavlinkDirect plugins on the event loop, without a thread hop per call.

MAVSDK 4's asyncio wrappers run every plugin call in the loop's thread pool and hand every
subscribed message to the loop with ``call_soon_threadsafe``. For the calls that only queue a
message (the offboard setpoints, ``send_message``) the hop costs far more than the call: a pool
thread woken, a future chained back, a write to the loop's self-pipe and a loop wake-up, for each
setpoint of each vehicle. So here those calls are made on the loop itself; only the calls that
wait for the vehicle's answer (offboard start / stop, a command and its ack) go to the pool.

Subscribed messages come from MAVSDK's callback thread into a ``LoopInbox``, which wakes the loop
once for whatever has arrived since it last looked, however many messages and vehicles that is.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import AsyncGenerator, Callable
from typing import Any

from mavsdk.plugins.mavlink_direct import MavlinkDirect, MavlinkMessage
from mavsdk.plugins.offboard import (
    AccelerationNed,
    Offboard,
    PositionNedYaw,
    VelocityNedYaw,
)


class LoopInbox:
    """Calls posted from any thread, run on the loop in the order posted, with one wake-up of
    the loop per batch.

    ``posted`` counts the calls, ``wakeups`` the loop wake-ups they took.
    """

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._pending: deque[tuple[Callable[[Any], object], Any]] = deque()
        self._scheduled = False
        self.posted = 0
        self.wakeups = 0

    def post(self, call: Callable[[Any], object], arg: Any) -> None:
        """Run ``call(arg)`` on the loop soon. Safe from any thread; a no-op once the loop is
        closed (the mission is over)."""
        self.posted += 1
        # append before looking at the flag: a drain that has already cleared it will still
        # find this call, and one that has not yet will be followed by the one scheduled here
        self._pending.append((call, arg))
        if self._scheduled:
            return
        self._scheduled = True
        try:
            self._loop.call_soon_threadsafe(self._drain)
        except RuntimeError:  # the loop is closed
            return
        self.wakeups += 1

    def _drain(self) -> None:
        self._scheduled = False
        pending = self._pending
        while pending:
            call, arg = pending.popleft()
            call(arg)


class LoopMavlinkDirect:
    """MavlinkDirect for one vehicle: ``send_message`` on the loop (MAVSDK queues the message),
    ``send_command`` in the thread pool (it waits for the final COMMAND_ACK), subscriptions
    through the inbox."""

    def __init__(self, plugin: MavlinkDirect, inbox: LoopInbox) -> None:
        self._plugin = plugin
        self._inbox = inbox

    async def subscribe_message(self, message_name: str) -> AsyncGenerator[MavlinkMessage]:
        """Every incoming message of that name ("" for all), until the generator is closed."""
        queue: asyncio.Queue[MavlinkMessage] = asyncio.Queue()
        post, put = self._inbox.post, queue.put_nowait

        def heard(message: MavlinkMessage, _user_data: object) -> None:
            post(put, message)

        handle = self._plugin.subscribe_message(message_name, heard)
        try:
            while True:
                yield await queue.get()
        finally:
            self._plugin.unsubscribe_message(handle)

    async def send_message(self, message: MavlinkMessage) -> Any:
        return self._plugin.send_message(message)

    async def send_command(self, command: MavlinkMessage) -> MavlinkMessage:
        loop = asyncio.get_running_loop()
        ack: MavlinkMessage = await loop.run_in_executor(None, self._plugin.send_command, command)
        return ack


class LoopOffboard:
    """Offboard for one vehicle: the setpoints on the loop (MAVSDK stores the setpoint, sends it
    at once and resends it at 20 Hz), start and stop in the thread pool (they wait for the
    vehicle's answer)."""

    def __init__(self, plugin: Offboard) -> None:
        self._plugin = plugin

    async def set_velocity_ned(self, velocity_ned_yaw: VelocityNedYaw) -> Any:
        return self._plugin.set_velocity_ned(velocity_ned_yaw)

    async def set_position_velocity_ned(
        self, position_ned_yaw: PositionNedYaw, velocity_ned_yaw: VelocityNedYaw
    ) -> Any:
        return self._plugin.set_position_velocity_ned(position_ned_yaw, velocity_ned_yaw)

    async def set_position_velocity_acceleration_ned(
        self,
        position_ned_yaw: PositionNedYaw,
        velocity_ned_yaw: VelocityNedYaw,
        acceleration_ned: AccelerationNed,
    ) -> Any:
        return self._plugin.set_position_velocity_acceleration_ned(
            position_ned_yaw, velocity_ned_yaw, acceleration_ned
        )

    async def start(self) -> Any:
        return await asyncio.get_running_loop().run_in_executor(None, self._plugin.start)

    async def stop(self) -> Any:
        return await asyncio.get_running_loop().run_in_executor(None, self._plugin.stop)
