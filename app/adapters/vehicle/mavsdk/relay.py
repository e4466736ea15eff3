"""A MAVLink relay between one vehicle connection, the app's MAVSDK and a ground station: the
flight log and QGroundControl beside the app, in the way mavlink-router sits beside a
companion computer's programs.

::

    vehicle (udpin/udpout/tcpout URL) <--> relay <--> app's MAVSDK (udpout://127.0.0.1:<port>)
                                      ^--> ground station (udpout:127.0.0.1:14550, or udpin)
                                      '--> vehicle-<sysid>.tlog

Every datagram is passed on as it came, at once, in the socket's callback: the relay adds no
latency beyond one datagram forward and never re-encodes, with one exception: PX4 v1.16 answers
TIMESYNC with its MAVLink 2 target fields uninitialised, and MAVSDK drops such an answer as
another system's, so the relay passes a vehicle's TIMESYNC answer on as a broadcast
(``packets.broadcast_timesync_answers``; counted in ``timesync_answers_broadcast``, recorded
as it came). Then each of its MAVLink packets is
appended to its vehicle's .tlog (``app.adapters.tlog.TlogRecorder``) with the wall-clock time
of its receipt: what the vehicle sent (every component: autopilot, camera) and what was sent
to it (by the app or the ground station).

Routing, as mavlink-router does it: a packet addressed to a system (``target_system`` != 0)
goes only to the side that has that system (the vehicle's ACKs to the app do not reach the
ground station, and the other way round); broadcasts go everywhere. The ground station is a
peer of the app: what it sends reaches the vehicle, so its operator can take a vehicle over
(a mode change makes the app leave that vehicle alone until ``resume``); it never reaches
the app.

A fault of the relay's own (a datagram it cannot parse, a log it cannot write, a ground
station that is not there) is counted or logged, never raised into the mission; only a vehicle
port that cannot be bound stops the start, with the port named.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import ipaddress
import logging
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Final, Self

from app.adapters.tlog import TlogRecorder
from app.adapters.vehicle.mavsdk.packets import (
    Packet,
    broadcast_timesync_answers,
    split_packets,
    split_stream,
)
from app.adapters.vehicle.mavsdk.urls import UdpEndpoint
from app.errors import LinkError

log = logging.getLogger(__name__)

Address = tuple[str, int]

#: how many peers a listening side remembers (the newest kept)
MAX_PEERS: Final = 8
#: how many of a kind of relay fault go to the log (the rest are only counted)
MAX_LOGGED_FAULTS: Final = 5
#: a TCP vehicle (ArduPilot SITL): how long to wait for the connection, how often to try again
#: after it drops, and how much is read at once (one datagram to MAVSDK)
TCP_CONNECT_TIMEOUT_S: Final = 10.0
TCP_RETRY_S: Final = 1.0
TCP_READ_BYTES: Final = 16384
RECEIVE_BUFFER_BYTES: Final = 1 << 20


@dataclass(slots=True)
class RelayCounters:
    """What a relay passed on, recorded and dropped (datagrams and packets)."""

    from_vehicle: int = 0
    from_app: int = 0
    from_gcs: int = 0
    packets_recorded: int = 0
    bytes_skipped: int = 0
    no_app_yet: int = 0
    gcs_refused: int = 0
    send_errors: int = 0
    faults: int = 0
    timesync_answers_broadcast: int = 0


class _Side(asyncio.DatagramProtocol):
    """One socket of the relay: datagrams to ``on_datagram``, socket errors counted."""

    def __init__(
        self, on_datagram: Callable[[bytes, Address], None], on_error: Callable[[Exception], None]
    ) -> None:
        self._on_datagram = on_datagram
        self._on_error = on_error

    def datagram_received(self, data: bytes, addr: Address) -> None:
        self._on_datagram(data, addr[:2])

    def error_received(self, exc: Exception) -> None:
        self._on_error(exc)


def _enlarge_receive_buffer(transport: asyncio.DatagramTransport) -> None:
    """Ask for a 1 MiB receive buffer (best effort, capped by the OS): the default holds a few
    hundred datagrams, which a loaded machine's scheduling hiccup can overflow."""
    sock = transport.get_extra_info("socket")
    if sock is not None:
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)


def _any_host(host: str) -> str:
    """The local address to send to ``host`` from: loopback for loopback, else every interface."""
    try:
        return "127.0.0.1" if ipaddress.ip_address(host).is_loopback else "0.0.0.0"
    except ValueError:
        return "127.0.0.1" if host == "localhost" else "0.0.0.0"


class MavlinkRelay:
    """One vehicle connection relayed to the app (``app_url``, for MAVSDK) and optionally to a
    ground station, recorded into ``recorder``; an async context manager (sockets open inside).

    ``vehicle``: the vehicle's connection as MAVSDK would have opened it (``udpin``: listen for
    the vehicle, as the built-in simulator and PX4 SITL expect on 14540+i; ``udpout``: send to
    it; ``tcpout``: connect to its TCP server, as to ArduPilot SITL's 5760, the byte stream cut
    into packets and passed on as datagrams). ``gcs``: the ground-station endpoint (``udpin``
    ports are shifted by ``gcs_index``, one per vehicle). ``system_ids``: the vehicles expected
    on this connection (more are learned from what it carries). ``wall_clock``: the tlog's
    timestamps (s since the Unix epoch).
    """

    def __init__(
        self,
        vehicle: UdpEndpoint,
        *,
        recorder: TlogRecorder | None = None,
        gcs: UdpEndpoint | None = None,
        gcs_index: int = 0,
        system_ids: frozenset[int] = frozenset(),
        wall_clock: Callable[[], float] = time.time,
        name: str = "relay",
    ) -> None:
        self.vehicle = vehicle
        self.gcs = gcs.shifted(gcs_index) if gcs is not None and gcs.mode == "udpin" else gcs
        self.name = name
        self.counters = RelayCounters()
        self._recorder = recorder
        self._wall_clock = wall_clock
        self._vehicle_t: asyncio.DatagramTransport | None = None
        self._app_t: asyncio.DatagramTransport | None = None
        self._gcs_t: asyncio.DatagramTransport | None = None
        self._vehicle_peers: dict[Address, None] = {}
        self._gcs_peers: dict[Address, None] = {}
        self._app_peer: Address | None = None
        self._app_port = 0
        self._vehicle_ids: set[int] = set(system_ids)
        self._app_ids: set[int] = set()
        self._gcs_ids: set[int] = set()
        self._logged: dict[str, int] = {}
        self._tcp_writer: asyncio.StreamWriter | None = None
        self._stack: contextlib.AsyncExitStack | None = None
        self._tcp_task: asyncio.Task[None] | None = None
        if vehicle.mode == "udpout":
            self._vehicle_peers[(vehicle.host, vehicle.port)] = None
        if self.gcs is not None and self.gcs.mode == "udpout":
            self._gcs_peers[(self.gcs.host, self.gcs.port)] = None

    # ---- lifecycle ---------------------------------------------------------------------------

    async def __aenter__(self) -> Self:
        loop = asyncio.get_running_loop()
        v = self.vehicle
        if v.mode == "tcpout":
            await self._open_tcp()
        else:
            await self._open_udp(loop)
        try:
            self._app_t, _ = await loop.create_datagram_endpoint(
                functools.partial(_Side, self._from_app, self._socket_error),
                local_addr=("127.0.0.1", 0),
            )
            self._app_port = self._app_t.get_extra_info("sockname")[1]
            _enlarge_receive_buffer(self._app_t)
        except OSError as exc:
            await self._aclose()
            raise LinkError(f"cannot open the relay's local port for MAVSDK: {exc}") from exc
        await self._open_gcs(loop)
        for transport in (self._vehicle_t, self._gcs_t):
            if transport is not None:
                _enlarge_receive_buffer(transport)
        log.info("%s: %s <-> %s%s", self.name, v.url, self.app_url, self._gcs_text())
        return self

    async def _open_udp(self, loop: asyncio.AbstractEventLoop) -> None:
        v = self.vehicle
        local = (v.host, v.port) if v.mode == "udpin" else (_any_host(v.host), 0)
        try:
            self._vehicle_t, _ = await loop.create_datagram_endpoint(
                functools.partial(_Side, self._from_vehicle, self._socket_error),
                local_addr=local,
            )
        except OSError as exc:
            raise LinkError(
                f"cannot listen for the vehicle on UDP {local[0]}:{local[1]} ({v.url}): "
                f"{exc.strerror or exc}"
                + (
                    " (another simulator, SITL or ground station has that port?)"
                    if v.mode == "udpin"
                    else ""
                )
            ) from exc

    async def _open_tcp(self) -> None:
        """Connect to the vehicle's TCP server (ArduPilot SITL's 5760) and read it in a task
        of the relay's own; a connection that drops is tried again every
        ``TCP_RETRY_S`` until the relay closes."""
        v = self.vehicle
        try:
            async with asyncio.timeout(TCP_CONNECT_TIMEOUT_S):
                reader, self._tcp_writer = await asyncio.open_connection(v.host, v.port)
        except (OSError, TimeoutError) as exc:
            raise LinkError(
                f"cannot connect to the vehicle on TCP {v.host}:{v.port} ({v.url}): "
                f"{getattr(exc, 'strerror', None) or exc or 'no answer'}"
            ) from exc
        stack = contextlib.AsyncExitStack()
        group = await stack.enter_async_context(asyncio.TaskGroup())
        self._tcp_task = group.create_task(self._read_tcp(reader), name=f"{self.name} tcp")
        self._stack = stack

    async def _read_tcp(self, reader: asyncio.StreamReader) -> None:
        buffer = b""
        while True:
            try:
                data = await reader.read(TCP_READ_BYTES)
            except OSError as exc:
                data = b""
                log.debug("%s: TCP read: %s", self.name, exc)
            if not data:
                log.warning("%s: the vehicle's TCP connection closed; reconnecting", self.name)
                reader = await self._reconnect_tcp()
                buffer = b""
                continue
            buffer += data
            try:
                packets, skipped, end = split_stream(buffer)
                self.counters.bytes_skipped += skipped
                if end:
                    self._vehicle_packets(self._wall_clock(), buffer[:end], packets)
                buffer = buffer[end:]
                if len(buffer) > TCP_READ_BYTES:  # never a packet: let it go
                    self.counters.bytes_skipped += len(buffer)
                    buffer = b""
            except Exception as exc:  # a bug here must not cut the vehicle off
                self._fault("vehicle stream", exc)
                buffer = b""

    async def _reconnect_tcp(self) -> asyncio.StreamReader:
        v = self.vehicle
        writer, self._tcp_writer = self._tcp_writer, None
        if writer is not None:
            writer.close()
        while True:
            await asyncio.sleep(TCP_RETRY_S)
            try:
                reader, self._tcp_writer = await asyncio.open_connection(v.host, v.port)
            except OSError as exc:
                log.debug("%s: TCP reconnect: %s", self.name, exc)
                continue
            log.info("%s: the vehicle's TCP connection is back", self.name)
            return reader

    async def _open_gcs(self, loop: asyncio.AbstractEventLoop) -> None:
        """The ground station's socket; one that cannot be opened is an error in the log and
        no ground station, never a stopped mission."""
        gcs = self.gcs
        if gcs is None:
            return
        local = (gcs.host, gcs.port) if gcs.mode == "udpin" else (_any_host(gcs.host), 0)
        try:
            self._gcs_t, _ = await loop.create_datagram_endpoint(
                functools.partial(_Side, self._from_gcs, self._gcs_error),
                local_addr=local,
            )
        except OSError as exc:
            log.error(
                "%s: no ground station: cannot open UDP %s:%d for %s: %s",
                self.name,
                local[0],
                local[1],
                gcs.spec,
                exc.strerror or exc,
            )
            self.gcs = None

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._aclose()
        c = self.counters
        log.info(
            "%s closed: %d datagrams from the vehicle, %d from the app, %d from the ground "
            "station; %d packets recorded; %d bytes skipped, %d send errors",
            self.name,
            c.from_vehicle,
            c.from_app,
            c.from_gcs,
            c.packets_recorded,
            c.bytes_skipped,
            c.send_errors,
        )

    async def _aclose(self) -> None:
        for transport in (self._vehicle_t, self._app_t, self._gcs_t):
            if transport is not None:
                transport.close()
        self._vehicle_t = self._app_t = self._gcs_t = None
        stack, self._stack = self._stack, None
        if stack is not None:
            if self._tcp_task is not None:
                self._tcp_task.cancel()
            await stack.aclose()
        writer, self._tcp_writer = self._tcp_writer, None
        if writer is not None:
            writer.close()
            with contextlib.suppress(OSError):
                await writer.wait_closed()

    # ---- what the app and the operator see ---------------------------------------------------

    @property
    def app_url(self) -> str:
        """The MAVSDK URL the app connects to the vehicle through."""
        return f"udpout://127.0.0.1:{self._app_port}"

    @property
    def vehicle_ids(self) -> frozenset[int]:
        """The system ids heard from the vehicle side."""
        return frozenset(self._vehicle_ids)

    def _gcs_text(self) -> str:
        return "" if self.gcs is None else f", ground station {self.gcs.spec}"

    def describe(self) -> str:
        """One line for the operator: where the vehicle is, where a ground station sees it."""
        where = "not served" if self.gcs is None else self.gcs.spec
        if self.gcs is not None and self.gcs.mode == "udpout":
            where = f"{self.gcs.spec} (sent to)"
        elif self.gcs is not None:
            where = f"{self.gcs.spec} (listening)"
        return f"vehicle link {self.vehicle.url}, ground station {where}"

    # ---- datagrams ---------------------------------------------------------------------------

    def _from_vehicle(self, data: bytes, addr: Address) -> None:
        now = self._wall_clock()
        if self.vehicle.mode == "udpin":
            self._remember(self._vehicle_peers, addr)
        try:
            packets, skipped = split_packets(data)
            self.counters.bytes_skipped += skipped
        except Exception as exc:
            self._fault("vehicle datagram", exc)
            return
        self._vehicle_packets(now, data, packets)

    def _vehicle_packets(self, now: float, data: bytes, packets: list[Packet]) -> None:
        """What the vehicle sent (``data``, holding ``packets``): on to the app and the ground
        station, then into the log."""
        self.counters.from_vehicle += 1
        try:
            for p in packets:
                self._vehicle_ids.add(p.system_id)
            # on to the app and the ground station first, then the log (as it came)
            out = broadcast_timesync_answers(data, packets)
            if out is not data:
                self.counters.timesync_answers_broadcast += 1
                out_packets, _ = split_packets(out)
            else:
                out_packets = packets
            if self._app_peer is None:
                self.counters.no_app_yet += 1
            else:
                self._send(self._app_t, (self._app_peer,), out, out_packets, self._app_ids)
            if self._gcs_t is not None and self._gcs_peers:
                self._send(self._gcs_t, tuple(self._gcs_peers), out, out_packets, self._gcs_ids)
            if self._recorder is not None:
                for p in packets:
                    self._recorder.write(p.system_id, now, data[p.start : p.end])
                self.counters.packets_recorded += len(packets)
        except Exception as exc:  # a bug here must not cut the vehicle off
            self._fault("vehicle datagram", exc)

    def _from_app(self, data: bytes, addr: Address) -> None:
        now = self._wall_clock()
        self.counters.from_app += 1
        self._app_peer = addr
        try:
            packets, skipped = split_packets(data)
            self.counters.bytes_skipped += skipped
            for p in packets:
                self._app_ids.add(p.system_id)
            self._send_to_vehicle(data)
            self._record_to_vehicle(now, data, packets)
        except Exception as exc:
            self._fault("app datagram", exc)

    def _from_gcs(self, data: bytes, addr: Address) -> None:
        now = self._wall_clock()
        self.counters.from_gcs += 1
        if self.gcs is not None and self.gcs.mode == "udpin":
            self._remember(self._gcs_peers, addr)
        try:
            packets, skipped = split_packets(data)
            self.counters.bytes_skipped += skipped
            for p in packets:
                self._gcs_ids.add(p.system_id)
            # a ground station sends to every vehicle it knows on every link: only what is for
            # this connection's vehicles (or broadcast) goes on
            mine = [p for p in packets if p.target_system in (0, *self._vehicle_ids)]
            self.counters.gcs_refused += len(packets) - len(mine)
            if not mine:
                return
            out = (
                data if len(mine) == len(packets) else b"".join(data[p.start : p.end] for p in mine)
            )
            self._send_to_vehicle(out)
            self._record_to_vehicle(now, data, mine)
        except Exception as exc:
            self._fault("ground station datagram", exc)

    # ---- helpers -----------------------------------------------------------------------------

    def _send_to_vehicle(self, data: bytes) -> None:
        if self.vehicle.mode == "tcpout":
            writer = self._tcp_writer
            if writer is None or writer.is_closing():
                self.counters.send_errors += 1  # reconnecting: dropped, as a radio would
                return
            writer.write(data)
            return
        transport = self._vehicle_t
        if transport is None:
            return
        for peer in tuple(self._vehicle_peers):
            try:
                transport.sendto(data, peer)
            except OSError as exc:
                self.counters.send_errors += 1
                self._fault("send to the vehicle", exc)

    def _send(
        self,
        transport: asyncio.DatagramTransport | None,
        peers: tuple[Address, ...],
        data: bytes,
        packets: list[Packet],
        ids: set[int],
    ) -> None:
        """``data`` to ``peers``, less the packets addressed to a system that side does not
        have."""
        if transport is None:
            return
        wanted = [p for p in packets if p.target_system == 0 or p.target_system in ids]
        if len(wanted) != len(packets):
            if not wanted:
                return
            data = b"".join(data[p.start : p.end] for p in wanted)
        for peer in peers:
            try:
                transport.sendto(data, peer)
            except OSError as exc:
                self.counters.send_errors += 1
                self._fault("send", exc)

    def _record_to_vehicle(self, now: float, data: bytes, packets: list[Packet]) -> None:
        """Packets sent to the vehicle side, into the log of the system each is for (a
        broadcast: every vehicle heard on this connection)."""
        recorder = self._recorder
        if recorder is None:
            return
        for p in packets:
            packet = data[p.start : p.end]
            if p.target_system != 0:
                recorder.write(p.target_system, now, packet)
                self.counters.packets_recorded += 1
            else:
                for system_id in self._vehicle_ids:
                    recorder.write(system_id, now, packet)
                    self.counters.packets_recorded += 1

    @staticmethod
    def _remember(peers: dict[Address, None], addr: Address) -> None:
        if addr in peers:
            return
        if len(peers) >= MAX_PEERS:
            del peers[next(iter(peers))]
        peers[addr] = None

    def _socket_error(self, exc: Exception) -> None:
        # a peer gone (MAVSDK closed first at the end, a vehicle switched off): ICMP port
        # unreachable on the next datagram; counted, not an error
        self.counters.send_errors += 1
        log.debug("%s: socket error %s", self.name, exc)

    def _gcs_error(self, exc: Exception) -> None:
        # nobody listening on the ground station's port (ICMP port unreachable): normal
        self.counters.send_errors += 1

    def _fault(self, what: str, exc: BaseException) -> None:
        self.counters.faults += 1
        seen = self._logged.get(what, 0)
        self._logged[what] = seen + 1
        if seen < MAX_LOGGED_FAULTS:
            log.error("%s: %s: %s (relaying goes on)", self.name, what, exc)
