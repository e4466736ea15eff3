"""One Mavsdk instance with one or many connections, handing out a vehicle link per system id."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable, Iterable
from contextlib import asynccontextmanager

from mavsdk import ComponentType, Configuration, ForwardingOption, Mavsdk, System
from mavsdk.exceptions import ConnectionError as MavsdkConnectionError

from app.adapters.vehicle.autopilots.base import MAVSDK_GCS_SYSTEM_ID
from app.adapters.vehicle.mavsdk.direct import LoopInbox
from app.adapters.vehicle.mavsdk.link import LinkConfig, MavsdkVehicleLink
from app.adapters.vehicle.mavsdk.logs import route_mavsdk_logs
from app.adapters.vehicle.mavsdk.urls import validate_url
from app.errors import ConfigError, LinkError
from app.runtime.ports.vehicle import GeodeticOrigin


class MavsdkHub:
    """One Mavsdk instance with one or many connections, handing out a link per system id.

    MAVSDK's own (blocking) API, with the calls that wait run in the loop's thread pool: the
    links make the calls that only queue a message on the loop (``direct``), and every link's
    subscribed messages reach the loop through one ``LoopInbox``.

    ``mission_clock``: mission time on the host, onto which every link maps its vehicle's boot
    clock (None: frames carry the vehicles' own boot times).

    ::

        async with MavsdkHub(["udpin://0.0.0.0:14540", "udpin://0.0.0.0:14541"], origin) as hub:
            async with hub.link(1, config) as v1, hub.link(2, config) as v2:
                ...
    """

    def __init__(
        self,
        urls: Iterable[str],
        origin: GeodeticOrigin,
        *,
        clock: Callable[[], float] = time.monotonic,
        route_logs: bool = True,
        mission_clock: Callable[[], float | None] | None = None,
    ) -> None:
        self._urls = [validate_url(url) for url in urls]
        if not self._urls:
            raise ConfigError("at least one vehicle connection URL is needed")
        self._origin = origin
        self._clock = clock
        self._route_logs = route_logs
        self._mission_clock = mission_clock
        self._mavsdk: Mavsdk | None = None
        self._gcs_system_id = MAVSDK_GCS_SYSTEM_ID
        self._open_ids: set[int] = set()
        self._inbox: LoopInbox | None = None

    async def __aenter__(self) -> MavsdkHub:
        if self._route_logs:
            route_mavsdk_logs()
        configuration = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        self._gcs_system_id = configuration.system_id  # what ArduPlane's SYSID_MYGCS must be
        loop = asyncio.get_running_loop()
        mavsdk = Mavsdk(configuration)
        try:
            for url in self._urls:
                try:
                    await loop.run_in_executor(
                        None,
                        mavsdk.add_any_connection_with_handle_and_forwarding,
                        url,
                        ForwardingOption.OFF,
                    )
                except MavsdkConnectionError as exc:
                    raise LinkError(f"cannot open vehicle connection {url}: {exc}") from exc
        except BaseException:
            mavsdk.destroy()
            raise
        self._mavsdk = mavsdk
        self._inbox = LoopInbox(loop)
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        mavsdk, self._mavsdk, self._inbox = self._mavsdk, None, None
        if mavsdk is not None:
            mavsdk.destroy()

    async def system(self, system_id: int, timeout_s: float) -> System:
        """The autopilot system with this MAVLink system id, waited for up to ``timeout_s``."""
        mavsdk = self._mavsdk
        if mavsdk is None:
            raise LinkError("hub not open (use it as 'async with')")
        try:
            async with asyncio.timeout(timeout_s):
                while True:
                    for system in await self._systems(mavsdk):
                        if system.get_system_id() == system_id and system.has_autopilot():
                            return system
                    await asyncio.sleep(0.1)
        except TimeoutError as exc:
            raise LinkError(
                f"no autopilot with system id {system_id} on {', '.join(self._urls)} "
                f"within {timeout_s} s"
            ) from exc

    @property
    def inbox(self) -> LoopInbox | None:
        """Where the links' subscribed messages reach the loop (None while the hub is closed):
        its counters say how many messages a wake-up of the loop carries."""
        return self._inbox

    async def system_ids(self) -> list[int]:
        """The system ids of the autopilots seen so far."""
        mavsdk = self._mavsdk
        if mavsdk is None:
            raise LinkError("hub not open (use it as 'async with')")
        return sorted([s.get_system_id() for s in await self._systems(mavsdk) if s.has_autopilot()])

    @staticmethod
    async def _systems(mavsdk: Mavsdk) -> list[System]:
        systems: list[System] = await asyncio.get_running_loop().run_in_executor(
            None, mavsdk.get_systems
        )
        return systems

    @asynccontextmanager
    async def link(
        self, system_id: int, config: LinkConfig, *, timeout_s: float = 10.0
    ) -> AsyncIterator[MavsdkVehicleLink]:
        """A link to one vehicle, open for the ``async with`` block (holds the vehicle on exit).

        One link per system id at a time: MAVSDK 4.1 resets a plugin's cached values when
        another instance of that plugin on the same system goes away.
        """
        if system_id in self._open_ids:
            raise LinkError(f"vehicle {system_id} already has an open link on this hub")
        system = await self.system(system_id, timeout_s)
        inbox = self._inbox
        if inbox is None:  # set with the Mavsdk instance, which system() has found
            raise LinkError("hub not open (use it as 'async with')")
        self._open_ids.add(system_id)
        try:
            async with MavsdkVehicleLink(
                system,
                system_id,
                self._origin,
                config,
                self._clock,
                self._gcs_system_id,
                self._mission_clock,
                inbox=inbox,
            ) as link:
                yield link
        finally:
            self._open_ids.discard(system_id)
