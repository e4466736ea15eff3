"""Simulator test helpers: a raw asyncio MAVLink client (pymavlink codec) and sim set-up."""

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field, replace

from pymavlink.dialects.v20 import common as mavlink

from sitl.arduplane import ArduPlaneAutopilot
from sitl.config import SimConfig, default_vehicles
from sitl.ports import find_free_udp_base_port
from sitl.px4 import Px4Autopilot
from sitl.server import SimulatorServer
from sitl.vehicle import SimVehicle

GCS_SYSTEM_ID = 255
GCS_COMPONENT_ID = 190


def sim_config(count: int, speedup: float, **overrides: object) -> SimConfig:
    """A config on free ports (both where vehicles send and where they listen)."""
    base = find_free_udp_base_port(count)
    config = SimConfig(vehicles=default_vehicles(count), base_port=base, speedup=speedup)
    return replace(config, **overrides)  # type: ignore[arg-type]


def px4_of(vehicle: SimVehicle) -> Px4Autopilot:
    """The vehicle's PX4 personality (the test fails if it flies another)."""
    autopilot = vehicle.autopilot
    assert isinstance(autopilot, Px4Autopilot)
    return autopilot


def arduplane_of(vehicle: SimVehicle) -> ArduPlaneAutopilot:
    """The vehicle's ArduPlane personality (the test fails if it flies another)."""
    autopilot = vehicle.autopilot
    assert isinstance(autopilot, ArduPlaneAutopilot)
    return autopilot


@contextlib.asynccontextmanager
async def running_sim(config: SimConfig) -> AsyncIterator[SimulatorServer]:
    async with SimulatorServer(config) as sim:
        yield sim


@dataclass
class _Inbox:
    messages: list[mavlink.MAVLink_message] = field(default_factory=list)
    arrived: asyncio.Event = field(default_factory=asyncio.Event)
    vehicle_addr: tuple[str, int] | None = None


class _ClientProtocol(asyncio.DatagramProtocol):
    def __init__(self, inbox: _Inbox) -> None:
        self._inbox = inbox
        self._decoder = mavlink.MAVLink(None, GCS_SYSTEM_ID, GCS_COMPONENT_ID)
        self._decoder.robust_parsing = True

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        for msg in self._decoder.parse_buffer(data) or []:
            if isinstance(msg, mavlink.MAVLink_bad_data | mavlink.MAVLink_unknown):
                continue
            self._inbox.vehicle_addr = addr
            self._inbox.messages.append(msg)
        self._inbox.arrived.set()


class RawClient:
    """A ground station written with pymavlink's codec alone: listens on the vehicle's GCS port
    (as ``udpin``), answers the vehicle at the address its packets come from."""

    def __init__(self, port: int, host: str = "127.0.0.1") -> None:
        self.port = port
        self.host = host
        self.inbox = _Inbox()
        self.encoder = mavlink.MAVLink(None, GCS_SYSTEM_ID, GCS_COMPONENT_ID)
        self._transport: asyncio.DatagramTransport | None = None

    async def __aenter__(self) -> "RawClient":
        loop = asyncio.get_running_loop()
        self._transport, _ = await loop.create_datagram_endpoint(
            lambda: _ClientProtocol(self.inbox), local_addr=(self.host, self.port)
        )
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._transport is not None:
            self._transport.close()

    def send(self, msg: mavlink.MAVLink_message) -> None:
        assert self._transport is not None
        assert self.inbox.vehicle_addr is not None
        self._transport.sendto(msg.pack(self.encoder), self.inbox.vehicle_addr)
        self.encoder.seq = (self.encoder.seq + 1) % 256

    async def wait_for(
        self,
        predicate: Callable[[mavlink.MAVLink_message], bool],
        timeout_s: float = 5.0,
        start: int | None = None,
    ) -> mavlink.MAVLink_message:
        """The first message (from index ``start``, default: from now on) matching ``predicate``."""
        seen = len(self.inbox.messages) if start is None else start
        async with asyncio.timeout(timeout_s):
            while True:
                for msg in self.inbox.messages[seen:]:
                    if predicate(msg):
                        return msg
                seen = len(self.inbox.messages)
                self.inbox.arrived.clear()
                await self.inbox.arrived.wait()

    async def heartbeat(self, timeout_s: float = 5.0) -> mavlink.MAVLink_message:
        return await self.wait_for(lambda m: m.get_type() == "HEARTBEAT", timeout_s, start=0)

    async def command(
        self,
        command: int,
        *params: float,
        target_system: int,
        timeout_s: float = 1.0,
        tries: int = 3,
    ) -> int:
        """Send COMMAND_LONG and return the COMMAND_ACK result, resending (with the
        confirmation count raised) after ``timeout_s`` without an ack, as MAVSDK does."""
        full = [*params, *([math.nan] * (7 - len(params)))]
        for confirmation in range(tries):
            start = len(self.inbox.messages)
            self.send(
                mavlink.MAVLink_command_long_message(target_system, 1, command, confirmation, *full)
            )
            try:
                ack = await self.wait_for(
                    lambda m: m.get_type() == "COMMAND_ACK" and m.command == command,
                    timeout_s,
                    start=start,
                )
            except TimeoutError:
                continue
            return int(ack.result)
        raise TimeoutError(f"no COMMAND_ACK for command {command} after {tries} tries")

    def velocity_setpoint(
        self, target_system: int, north_m_s: float, east_m_s: float, time_boot_ms: int = 0
    ) -> None:
        # ignore position (1|2|4), acceleration (64|128|256), yaw (1024), yaw rate (2048)
        mask = 1 | 2 | 4 | 64 | 128 | 256 | 1024 | 2048
        self.send(
            mavlink.MAVLink_set_position_target_local_ned_message(
                time_boot_ms,
                target_system,
                1,
                mavlink.MAV_FRAME_LOCAL_NED,
                mask,
                0.0,
                0.0,
                0.0,
                north_m_s,
                east_m_s,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            )
        )


async def stream_setpoints(
    client: RawClient,
    target_system: int,
    north_m_s: float,
    east_m_s: float,
    rate_hz: float,
    stop: asyncio.Event,
) -> None:
    """Resend a velocity setpoint at ``rate_hz`` wall time until ``stop`` is set (as MAVSDK)."""
    while not stop.is_set():
        client.velocity_setpoint(target_system, north_m_s, east_m_s)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(1.0 / rate_hz):
                await stop.wait()
