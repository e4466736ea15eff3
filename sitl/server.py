"""The simulator's asyncio front: N vehicles on real UDP sockets, one physics loop, simulated time.

Use it as an async context manager::

    async with SimulatorServer(SimConfig(vehicles=default_vehicles(3), base_port=14540)) as sim:
        print(sim.endpoints)          # where each vehicle sends, and the port it answers on
        await sim.wait_until(60.0)    # simulated seconds
        truth = sim.truth()           # vehicle states, modes, target state, simulated time

Bad input never stops the server: undecodable packets, unknown messages and messages for other
system ids are counted (``sim.stats``) and dropped.
"""

import asyncio
import contextlib
import functools
import logging
import math
import socket
import time
from collections import deque
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Self

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from sitl.arduplane import ArduPlaneAutopilot
from sitl.camera import Observation, TrackingCamera
from sitl.config import SimConfig, VehicleConfig, WindConfig
from sitl.geodesy import AnchoredGeodesy, Geodesy
from sitl.px4 import Px4Autopilot
from sitl.target import TargetState
from sitl.vehicle import (
    AUTOPILOT_COMPONENT,
    Autopilot,
    Outgoing,
    SimVehicle,
    VehicleTruth,
)

log = logging.getLogger(__name__)

Address = tuple[str, int]
Clock = Callable[[], float]

MAX_LEARNED_PEERS = 4
PEER_EXPIRY_WALL_S = 10.0
MAX_CATCH_UP_WALL_S = 0.25
MIN_SLEEP_WALL_S = 0.001
OBSERVATION_LOG_LENGTH = 10_000
RECEIVE_BUFFER_BYTES = 1 << 20


def autopilot_for(vehicle: VehicleConfig, sim: SimConfig, index: int = 0) -> Autopilot:
    """The autopilot personality ``sim.autopilot`` names, for vehicle ``index``."""
    if sim.autopilot == "arduplane":
        return ArduPlaneAutopilot(vehicle, sim, sim.boot_offset_s(index))
    trim = sim.px4_trim_airspeed_m_s
    trim_m_s = vehicle.cruise_speed_m_s if trim is None else vehicle.limits.clamp_speed(trim)
    return Px4Autopilot(sim, trim_m_s)


@dataclass(frozen=True, slots=True)
class Endpoint:
    """Where vehicle ``system_id`` sends (``gcs``) and the socket it sends from (``local``).

    A client listens on the gcs port (MAVSDK ``udpin://0.0.0.0:<gcs port>``) and is answered at
    the address its packets come from; or it sends to the local port (``udpout``).
    """

    system_id: int
    local_host: str
    local_port: int
    gcs_host: str
    gcs_port: int

    @property
    def mavsdk_url(self) -> str:
        return f"udpin://0.0.0.0:{self.gcs_port}"


@dataclass(slots=True)
class LinkStats:
    """Counters of one vehicle's link; drops are counted, never raised."""

    packets_in: int = 0
    messages_in: int = 0
    garbled: int = 0
    unknown: int = 0
    other_system: int = 0
    handler_errors: int = 0
    dropped_link_down: int = 0
    packets_out: int = 0
    send_errors: int = 0

    @property
    def dropped(self) -> int:
        return self.garbled + self.unknown + self.other_system + self.handler_errors


@dataclass(frozen=True, slots=True)
class SimTruth:
    """The simulation's ground truth at simulated time ``t_s``."""

    t_s: float
    vehicles: tuple[VehicleTruth, ...]
    target: TargetState


@dataclass(slots=True)
class _Link:
    index: int
    system_id: int
    gcs: Address
    encoders: dict[int, mavlink.MAVLink]
    decoder: mavlink.MAVLink
    transport: asyncio.DatagramTransport | None = None
    local: Address = ("", 0)
    learned: dict[Address, float] = field(default_factory=dict)
    up: bool = True
    stats: LinkStats = field(default_factory=LinkStats)


def _enlarge_receive_buffer(transport: asyncio.DatagramTransport) -> None:
    """Ask for a 1 MiB receive buffer (best effort, capped by the OS) to ride out bursts."""
    sock = transport.get_extra_info("socket")
    if sock is None:
        return
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)


class _Protocol(asyncio.DatagramProtocol):
    def __init__(
        self, on_datagram: Callable[[bytes, Address], None], on_error: Callable[[Exception], None]
    ) -> None:
        self._on_datagram = on_datagram
        self._on_error = on_error

    def datagram_received(self, data: bytes, addr: Address) -> None:
        self._on_datagram(data, addr)

    def error_received(self, exc: Exception) -> None:
        self._on_error(exc)


class SimulatorServer:
    """N simulated vehicles behind real UDP sockets, a target and a camera per vehicle.

    ``clock`` is the wall clock (seconds, monotonic); simulated time runs ``speedup`` times
    faster, in fixed physics steps, so the flight is the same function of the commands whatever
    the load (the server slows simulated time rather than skip steps when it falls behind).
    """

    def __init__(self, config: SimConfig, clock: Clock = time.monotonic) -> None:
        self.config = config
        self._clock = clock
        self._geodesy = Geodesy(config.origin_lat_deg, config.origin_lon_deg, config.origin_alt_m)
        seeds = np.random.SeedSequence(config.seed).spawn(len(config.vehicles) + 1)
        self._wind_rng = np.random.default_rng(seeds[0])
        self.vehicles = tuple(
            SimVehicle(
                i,
                vc,
                config,
                TrackingCamera(config.camera, np.random.default_rng(seeds[i + 1])),
                self._geodesy,
                autopilot_for(vc, config, i),
            )
            for i, vc in enumerate(config.vehicles)
        )
        self._links = tuple(self._make_link(v.index) for v in self.vehicles)
        self._tick = 0
        self._speedup = config.speedup
        self._wind = config.wind
        self._gust_east_m_s = 0.0
        self._gust_north_m_s = 0.0
        # slots: vehicle i is i, vehicle i's camera fixes are n + i
        self._anchored = AnchoredGeodesy(self._geodesy, 2 * len(config.vehicles))
        self._geo: np.ndarray | None = None
        self._geo_observed: list[tuple[SimVehicle, Observation]] = []
        self._geo_lookups = tuple(
            functools.partial(self._geo_of, i) for i in range(len(self.vehicles))
        )
        self._ticked = asyncio.Event()
        self._stack: contextlib.AsyncExitStack | None = None
        self._stopping = False
        self.lag_events = 0
        self.step_errors = 0
        self.observations: deque[tuple[int, Observation]] = deque(maxlen=OBSERVATION_LOG_LENGTH)

    def _make_link(self, index: int) -> _Link:
        system_id = index + 1
        encoders = {
            comp: mavlink.MAVLink(None, srcSystem=system_id, srcComponent=comp)
            for comp in (AUTOPILOT_COMPONENT, self.config.camera_component_id)
        }
        decoder = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=AUTOPILOT_COMPONENT)
        decoder.robust_parsing = True
        gcs = (self.config.gcs_host, self.config.base_port + index)
        return _Link(index=index, system_id=system_id, gcs=gcs, encoders=encoders, decoder=decoder)

    # ---- lifecycle ---------------------------------------------------------------------------

    async def __aenter__(self) -> Self:
        loop = asyncio.get_running_loop()
        async with contextlib.AsyncExitStack() as stack:
            for link in self._links:
                port = self.config.bind_base_port
                local = (self.config.bind_host, 0 if port is None else port + link.index)
                try:
                    transport, _ = await loop.create_datagram_endpoint(
                        functools.partial(
                            _Protocol,
                            functools.partial(self._on_datagram, link),
                            functools.partial(self._on_socket_error, link),
                        ),
                        local_addr=local,
                    )
                except OSError as exc:  # the port, not only "Address already in use"
                    raise OSError(
                        exc.errno,
                        f"vehicle {link.system_id}: cannot bind UDP {local[0]}:{local[1]}: "
                        f"{exc.strerror or exc}",
                    ) from exc
                stack.callback(transport.close)
                _enlarge_receive_buffer(transport)
                link.transport = transport
                host, bound_port = transport.get_extra_info("sockname")[:2]
                link.local = (host, bound_port)
            self._ticked = asyncio.Event()
            group = await stack.enter_async_context(asyncio.TaskGroup())
            self._stopping = False
            group.create_task(self._physics_loop(), name="sitl-physics")
            self._stack = stack.pop_all()
        log.info("simulator up: %d vehicles, speed-up %g", len(self.vehicles), self.config.speedup)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._stopping = True
        self._ticked.set()
        stack, self._stack = self._stack, None
        if stack is not None:
            await stack.__aexit__(exc_type, exc, tb)
        total = self.stats_total()
        log.info(
            "simulator down at t=%.1f s: %d packets in, %d dropped, %d out",
            self.time_s,
            total.packets_in,
            total.dropped,
            total.packets_out,
        )

    # ---- public view -------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        """Simulated time now."""
        return self._tick * self.config.physics_dt_s

    @property
    def endpoints(self) -> tuple[Endpoint, ...]:
        return tuple(
            Endpoint(link.system_id, link.local[0], link.local[1], link.gcs[0], link.gcs[1])
            for link in self._links
        )

    @property
    def geodesy(self) -> Geodesy:
        """Local east/north/up about the simulator's origin <-> latitude/longitude."""
        return self._geodesy

    @property
    def stats(self) -> tuple[LinkStats, ...]:
        return tuple(link.stats for link in self._links)

    def stats_total(self) -> LinkStats:
        total = LinkStats()
        for s in self.stats:
            for name in LinkStats.__slots__:
                setattr(total, name, getattr(total, name) + getattr(s, name))
        return total

    def truth(self) -> SimTruth:
        t = self.time_s
        return SimTruth(
            t_s=t,
            vehicles=tuple(
                v.truth(link.up) for v, link in zip(self.vehicles, self._links, strict=True)
            ),
            target=self.config.target.state_at(t),
        )

    async def wait_until(self, t_s: float) -> SimTruth:
        """Wait until simulated time reaches ``t_s``; return the truth then."""
        while self.time_s + 1e-9 < t_s:
            if self._stopping:
                raise RuntimeError("simulator stopped")
            await self._ticked.wait()
        return self.truth()

    async def truth_samples(self, period_s: float) -> AsyncIterator[SimTruth]:
        """The truth every ``period_s`` of simulated time, for scoring or plotting."""
        if not (period_s > 0.0 and math.isfinite(period_s)):
            raise ValueError(f"period_s must be finite and > 0, got {period_s!r}")
        t = self.time_s
        while True:
            yield await self.wait_until(t)
            t += period_s

    def run_offline(self, duration_s: float) -> SimTruth:
        """Advance ``duration_s`` of simulated time at once, with no sockets and no clock.

        For determinism checks and for stepping a scenario fast without clients; telemetry is
        built but goes nowhere, and wall time is taken to pass at 1/speedup of simulated time.
        Refused while the server is running.
        """
        if self._stack is not None:
            raise RuntimeError("run_offline is for a server that is not running")
        if not (math.isfinite(duration_s) and duration_s >= 0.0):
            raise ValueError(f"duration_s must be finite and >= 0, got {duration_s!r}")
        dt = self.config.physics_dt_s
        wall = self._clock()
        for i in range(round(duration_s / dt)):
            self._substep(dt, wall + (i + 1) * dt / self._speedup)  # wall time as if running
        return self.truth()

    # ---- faults ------------------------------------------------------------------------------

    def set_link(self, index: int, up: bool) -> None:
        """Cut (or restore) vehicle ``index``'s radio link: nothing in, nothing out."""
        self._links[index].up = up
        log.info("vehicle %d link %s", index + 1, "up" if up else "down")

    def set_camera(self, index: int, enabled: bool) -> None:
        """Stop (or restart) vehicle ``index``'s tracking camera."""
        self.vehicles[index].camera.enabled = enabled

    def set_wind(self, wind: WindConfig) -> None:
        self._wind = wind

    @property
    def speedup(self) -> float:
        return self._speedup

    def set_speedup(self, speedup: float) -> None:
        """Run simulated time ``speedup`` times faster than wall time from now on."""
        if not (math.isfinite(speedup) and speedup > 0.0):
            raise ValueError(f"speedup must be finite and > 0, got {speedup!r}")
        self._speedup = speedup  # the physics loop rebases its clock at its next wake-up

    # ---- physics loop ------------------------------------------------------------------------

    async def _physics_loop(self) -> None:
        dt = self.config.physics_dt_s
        speedup = self._speedup
        wall_per_tick = dt / speedup
        wall_base = self._clock()
        tick_base = self._tick
        max_behind = max(1, math.ceil(MAX_CATCH_UP_WALL_S / wall_per_tick))
        while not self._stopping:
            now = self._clock()
            if speedup != self._speedup:
                speedup = self._speedup
                wall_per_tick = dt / speedup
                wall_base, tick_base = now, self._tick
                max_behind = max(1, math.ceil(MAX_CATCH_UP_WALL_S / wall_per_tick))
            target = tick_base + int((now - wall_base) / wall_per_tick)
            if target - self._tick > max_behind:
                # fell behind (overload, a packet flood): slow simulated time, never skip steps
                self.lag_events += 1
                target = self._tick + max_behind
                wall_base, tick_base = now - max_behind * wall_per_tick, self._tick
            while self._tick < target:
                self._substep(dt, now)
            ticked, self._ticked = self._ticked, asyncio.Event()
            ticked.set()
            next_wall = wall_base + (self._tick + 1 - tick_base) * wall_per_tick
            await asyncio.sleep(max(MIN_SLEEP_WALL_S, next_wall - self._clock()))

    def _substep(self, dt: float, wall_s: float) -> None:
        """One physics step of every vehicle, then the telemetry and camera frames now due.

        All vehicles move first, so every message of a step describes the same instant; the
        geodetic positions of the vehicles and of the camera fixes of a step are converted
        together, through pymap3d anchors (``AnchoredGeodesy``: a pymap3d call costs about
        0.5 ms whatever the number of points, so it is made only when a point moves 50 m).
        """
        wind_e, wind_n = self._step_wind(dt)
        self._tick += 1
        t = self.time_s
        outs: list[list[Outgoing]] = []
        observed: list[tuple[SimVehicle, Observation]] = []
        target: TargetState | None = None
        for vehicle in self.vehicles:
            try:
                outs.append(vehicle.advance(dt, t, wall_s, wind_e, wind_n))
            except Exception:  # a bug must not stop the other vehicles or the server
                self.step_errors += 1
                if self.step_errors <= 10:
                    log.exception("vehicle %d: physics step failed", vehicle.system_id)
                outs.append([])
                continue
            if vehicle.camera_due(t):
                if target is None:
                    target = self.config.target.state_at(t)
                s = vehicle.state
                obs = vehicle.camera.observe(t, s.east_m, s.north_m, vehicle.altitude_m, target)
                if obs is not None and vehicle.in_air:
                    observed.append((vehicle, obs))
        self._geo_observed = observed
        self._geo = None
        for vehicle, link, out in zip(self.vehicles, self._links, outs, strict=True):
            out.extend(vehicle.telemetry(t, self._geo_lookups[vehicle.index]))
            self._send(link, out)
        for k, (vehicle, obs) in enumerate(observed):
            self.observations.append((vehicle.system_id, obs))
            lat, lon, alt = self._geo_of(len(self.vehicles) + k)
            self._send(self._links[vehicle.index], [vehicle.tracking_message(obs, lat, lon, alt)])

    def _step_wind(self, dt: float) -> tuple[float, float]:
        w = self._wind
        draws = self._wind_rng.standard_normal(2)
        if w.gust_sigma_m_s > 0.0:
            decay = math.exp(-dt / w.gust_tau_s)
            spread = w.gust_sigma_m_s * math.sqrt(1.0 - decay * decay)
            self._gust_east_m_s = decay * self._gust_east_m_s + spread * float(draws[0])
            self._gust_north_m_s = decay * self._gust_north_m_s + spread * float(draws[1])
        else:
            self._gust_east_m_s = self._gust_north_m_s = 0.0
        return w.east_m_s + self._gust_east_m_s, w.north_m_s + self._gust_north_m_s

    def _geo_of(self, index: int) -> tuple[float, float, float]:
        """Geodetic position of vehicle ``index`` (or, past the vehicles, of a camera fix)."""
        if self._geo is None:
            n = len(self.vehicles)
            slots = list(range(n))
            points = [(v.state.east_m, v.state.north_m, v.altitude_m) for v in self.vehicles]
            for vehicle, obs in self._geo_observed:
                slots.append(n + vehicle.index)  # each camera's fixes have their own anchor
                points.append((obs.east_m, obs.north_m, 0.0))
            self._geo = self._anchored.to_geodetic(
                np.array(slots, dtype=np.intp), np.array(points, dtype=np.float64)
            )
        lat, lon, alt = self._geo[index]
        return float(lat), float(lon), float(alt)

    # ---- I/O ---------------------------------------------------------------------------------

    def _send(self, link: _Link, out: list[Outgoing]) -> None:
        if not out or link.transport is None:
            return
        if not link.up:
            return
        now = self._clock()
        if link.learned:
            for addr in [a for a, seen in link.learned.items() if now - seen > PEER_EXPIRY_WALL_S]:
                del link.learned[addr]
        peers = [link.gcs, *(a for a in link.learned if a != link.gcs)]
        delay_wall_s = self.config.vehicles[link.index].link_delay_s / self._speedup
        for component, msg in out:
            encoder = link.encoders[component]
            try:
                buf = msg.pack(encoder)
            except Exception:  # a message we built badly must not stop the others
                log.exception("vehicle %d: cannot pack %s", link.system_id, msg.get_type())
                continue
            encoder.seq = (encoder.seq + 1) % 256
            for peer in peers:
                if delay_wall_s > 0.0:
                    asyncio.get_running_loop().call_later(
                        delay_wall_s, self._send_now, link, buf, peer
                    )
                else:
                    self._send_now(link, buf, peer)

    def _send_now(self, link: _Link, buf: bytes, peer: Address) -> None:
        if link.transport is None or not link.up:
            return
        try:
            link.transport.sendto(buf, peer)
            link.stats.packets_out += 1
        except OSError as exc:
            link.stats.send_errors += 1
            log.debug("vehicle %d: send to %s failed: %s", link.system_id, peer, exc)

    def _on_socket_error(self, link: _Link, exc: Exception) -> None:
        link.stats.send_errors += 1
        log.debug("vehicle %d: socket error %s", link.system_id, exc)

    def _on_datagram(self, link: _Link, data: bytes, addr: Address) -> None:
        delay_wall_s = self.config.vehicles[link.index].link_delay_s / self._speedup
        if delay_wall_s > 0.0:
            asyncio.get_running_loop().call_later(delay_wall_s, self._receive, link, data, addr)
        else:
            self._receive(link, data, addr)

    def _receive(self, link: _Link, data: bytes, addr: Address) -> None:
        stats = link.stats
        stats.packets_in += 1
        if not link.up:
            stats.dropped_link_down += 1
            return
        decoder = link.decoder
        decoder.buf = bytearray()  # one datagram holds whole packets: never carry a fragment
        decoder.buf_index = 0
        decoder.expected_length = mavlink.HEADER_LEN_V1 + 2
        try:
            messages = decoder.parse_buffer(data) or []
        except Exception as exc:  # robust parsing should not raise; count it if it does
            stats.garbled += 1
            log.debug("vehicle %d: undecodable packet from %s: %s", link.system_id, addr, exc)
            return
        if decoder.buf_len() > 0:
            stats.garbled += 1  # a truncated packet at the end of the datagram
        vehicle = self.vehicles[link.index]
        wall = self._clock()
        for msg in messages:
            if isinstance(msg, mavlink.MAVLink_bad_data):
                stats.garbled += 1
                continue
            if isinstance(msg, mavlink.MAVLink_unknown):
                stats.unknown += 1
                continue
            stats.messages_in += 1
            target = getattr(msg, "target_system", 0)
            if target not in (0, link.system_id):
                stats.other_system += 1
                continue
            if addr != link.gcs:
                if addr not in link.learned and len(link.learned) >= MAX_LEARNED_PEERS:
                    del link.learned[min(link.learned, key=link.learned.__getitem__)]
                link.learned[addr] = wall
            try:
                replies = vehicle.handle(msg, self.time_s, wall)
            except Exception:
                stats.handler_errors += 1
                log.exception("vehicle %d: error handling %s", link.system_id, msg.get_type())
                continue
            self._send(link, replies)
