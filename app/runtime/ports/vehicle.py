"""The vehicle-link port: the values and the Protocol the mission uses to fly one vehicle.

Courses are radians clockwise from north (MAVLink); positions are metres east/north/up of a
mission origin; times are mission time in seconds: each vehicle's telemetry time (its boot clock)
mapped by the link onto the mission clock, so that vehicles booted at different times agree.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator, Awaitable
from dataclasses import dataclass
from typing import Protocol, TypeVar, runtime_checkable

import pymap3d

from app.errors import LinkError


def _require_finite(name: str, value: float) -> None:
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")


@dataclass(frozen=True, slots=True)
class GeodeticOrigin:
    """The mission origin: WGS-84 latitude/longitude in degrees and altitude in metres (AMSL)."""

    latitude_deg: float
    longitude_deg: float
    altitude_m: float = 0.0

    def __post_init__(self) -> None:
        for name in ("latitude_deg", "longitude_deg", "altitude_m"):
            _require_finite(name, getattr(self, name))
        if not -90.0 <= self.latitude_deg <= 90.0:
            raise ValueError(f"latitude_deg must be in [-90, 90], got {self.latitude_deg}")
        if not -180.0 <= self.longitude_deg <= 180.0:
            raise ValueError(f"longitude_deg must be in [-180, 180], got {self.longitude_deg}")

    def to_enu(
        self, latitude_deg: float, longitude_deg: float, altitude_m: float
    ) -> tuple[float, float, float]:
        """(east_m, north_m, up_m) of a geodetic point about this origin (pymap3d, WGS-84)."""
        east, north, up = pymap3d.geodetic2enu(
            latitude_deg,
            longitude_deg,
            altitude_m,
            self.latitude_deg,
            self.longitude_deg,
            self.altitude_m,
        )
        return float(east), float(north), float(up)

    def to_geodetic(
        self, east_m: float, north_m: float, up_m: float = 0.0
    ) -> tuple[float, float, float]:
        """(latitude_deg, longitude_deg, altitude_m) of a local point about this origin."""
        lat, lon, alt = pymap3d.enu2geodetic(
            east_m, north_m, up_m, self.latitude_deg, self.longitude_deg, self.altitude_m
        )
        return float(lat), float(lon), float(alt)


@dataclass(frozen=True, slots=True)
class CourseSpeedCommand:
    """What guidance asks of a vehicle: a course (rad, clockwise from north) and a speed (m/s).

    ``altitude_m`` is the altitude above the vehicle's home (MAVLink relative altitude) to hold;
    ``None`` keeps the altitude the vehicle had when offboard started. ``course_rate_rad_s`` is
    the rate at which the wanted ground course turns (rad/s, positive clockwise seen from above),
    for adapters that can feed the path's curvature forward (PX4's offboard acceleration).
    ``path_course_rad`` is the wanted ground course itself, before the course command's lead
    for a first-order course loop (``guidance.course.course_command``: rate / k ahead of it);
    an adapter that hands the path to a path follower feeding its curvature forward flies it
    instead of ``course_rad`` (None: ``course_rad``).
    """

    course_rad: float
    speed_m_s: float
    altitude_m: float | None = None
    course_rate_rad_s: float = 0.0
    path_course_rad: float | None = None

    def __post_init__(self) -> None:
        _require_finite("course_rad", self.course_rad)
        _require_finite("speed_m_s", self.speed_m_s)
        if self.speed_m_s < 0.0:
            raise ValueError(f"speed_m_s must be >= 0, got {self.speed_m_s}")
        if self.altitude_m is not None:
            _require_finite("altitude_m", self.altitude_m)
        _require_finite("course_rate_rad_s", self.course_rate_rad_s)
        if self.path_course_rad is not None:
            _require_finite("path_course_rad", self.path_course_rad)


@dataclass(frozen=True, slots=True)
class VehicleTelemetry:
    """One telemetry frame of one vehicle, stamped with the vehicle's own time.

    ``altitude_m`` is AMSL, ``relative_altitude_m`` above home; ``east_m``/``north_m``/``up_m``
    are about the mission origin; the ground velocity is in m/s. ``in_air`` is the autopilot's
    landed state, or a height above home over ``LinkConfig.airborne_altitude_m`` before that
    state arrives. ``link_ok`` is False on the copy of the last frame that is published when the
    link is declared lost. ``airspeed_m_s`` is the autopilot's newest airspeed (VFR_HUD), None
    when the link has none; ``wind_m_s`` its newest wind estimate (east, north m/s, where the
    air moves to: PX4 WIND_COV, ArduPilot WIND), None when it sends none or it is stale.
    """

    vehicle_id: int
    t_s: float
    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    relative_altitude_m: float
    east_m: float
    north_m: float
    up_m: float
    course_rad: float
    ground_speed_m_s: float
    v_east_m_s: float
    v_north_m_s: float
    climb_rate_m_s: float
    flight_mode: str
    armed: bool
    in_air: bool
    link_ok: bool = True
    airspeed_m_s: float | None = None
    wind_m_s: tuple[float, float] | None = None


@dataclass(frozen=True, slots=True)
class TargetObservation:
    """A target position seen by a vehicle's camera (CAMERA_TRACKING_GEO_STATUS).

    ``t_s`` is the observing vehicle's telemetry time at reception (the message carries no time
    of its own). ``sigma_m`` is the camera's horizontal accuracy when it reports one.
    """

    vehicle_id: int
    t_s: float
    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    east_m: float
    north_m: float
    sigma_m: float | None


# ---------------------------------------------------------------------------------------------
# Events: things that happen to a link on their own. Refusals of what the mission asked for are
# raised as exceptions from the call instead.
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class LinkLost:
    """No telemetry from the vehicle for ``silent_s`` seconds (wall clock) since time ``t_s``."""

    vehicle_id: int
    t_s: float
    silent_s: float


@dataclass(frozen=True, slots=True)
class LinkRestored:
    """Telemetry flows again after a ``LinkLost``; ``t_s`` is the first new frame's time."""

    vehicle_id: int
    t_s: float


@dataclass(frozen=True, slots=True)
class LeftOffboard:
    """The vehicle left the offboard/guided mode on its own (failsafe, pilot, autopilot)."""

    vehicle_id: int
    t_s: float
    flight_mode: str


@dataclass(frozen=True, slots=True)
class SetpointLimited:
    """A setpoint was brought within the limits before it was sent (counted, not hidden)."""

    vehicle_id: int
    t_s: float
    reason: str
    count: int


@dataclass(frozen=True, slots=True)
class VehicleClockReset:
    """The vehicle's boot time jumped backwards (a reboot); times restart from ``t_s``."""

    vehicle_id: int
    t_s: float
    previous_t_s: float


@dataclass(frozen=True, slots=True)
class ClockRebased:
    """The vehicle's boot clock started again (``reason``: ``reboot``, its boot time went back;
    ``jump``, it leapt ahead of the host's clock): the link re-based its offset onto the mission
    clock (s), so mission time goes on at ``t_s`` and the vehicle stays in the formation."""

    vehicle_id: int
    t_s: float
    reason: str
    boot_s: float
    previous_boot_s: float | None
    offset_s: float
    previous_offset_s: float | None


@dataclass(frozen=True, slots=True)
class TurnLearned:
    """The adapter learned (or re-learned) how much of the coordinated turn the airframe flies
    at a bank, ``efficiency``, from ``samples`` samples over ``turning_s`` s of turning, and
    sizes its turn commands on it (the ArduPlane adapter's ``turn_efficiency``)."""

    vehicle_id: int
    t_s: float
    efficiency: float
    samples: int
    turning_s: float


@dataclass(frozen=True, slots=True)
class SpeedLagLearned:
    """The adapter learned (or re-learned) how far the airspeed lags its speed command, a
    first-order time constant ``tau_s`` from ``samples`` samples, and leads the command through
    it (the ArduPlane adapter's ``speed_lag_s``)."""

    vehicle_id: int
    t_s: float
    tau_s: float
    samples: int


LinkEvent = (
    LinkLost
    | LinkRestored
    | LeftOffboard
    | SetpointLimited
    | VehicleClockReset
    | ClockRebased
    | TurnLearned
    | SpeedLagLearned
)


class OffboardLostError(LinkError):
    """A command was sent to a vehicle that has left offboard on its own; restart offboard."""


class UnsupportedVehicleError(LinkError):
    """The vehicle takes none of the command forms this app can produce."""


T_co = TypeVar("T_co", covariant=True)


class FrameStream(Protocol[T_co]):
    """An ``async for`` stream that its reader releases with ``aclose()`` when it stops early."""

    def __aiter__(self) -> AsyncIterator[T_co]: ...  # an async generator is one too

    def __anext__(self) -> Awaitable[T_co]: ...

    def aclose(self) -> Awaitable[None]: ...


@runtime_checkable
class VehicleLink(Protocol):
    """One vehicle, as the mission sees it. Implementations are async context managers.

    The sequence is ``wait_ready`` -> ``arm`` -> ``take_off`` (does nothing in the air) ->
    ``start_offboard(first)`` -> ``send(command)`` at 10 Hz or more -> ``hold`` (also done on
    exit). Refusals raise ``LinkError`` (with the autopilot's result in the message);
    ``send`` raises ``OffboardLostError`` once the vehicle left offboard on its own.
    """

    @property
    def vehicle_id(self) -> int:
        """The MAVLink system id."""
        ...

    @property
    def autopilot_name(self) -> str:
        """The command adapter in use (``velocity``, ``px4-fixed-wing``, ``arduplane``)."""
        ...

    @property
    def honours_speed(self) -> bool:
        """Whether the vehicle flies the commanded speed under the mission's control (else the
        phase keeping must act through something other than speed)."""
        ...

    @property
    def course_error_limit_rad(self) -> float | None:
        """The course error (command - course, rad) at which the autopilot's own turn command
        saturates whatever its loop's gain (the ArduPlane adapter's bank limit), None when
        it has none: what the course-loop identification must not fit beyond."""
        ...

    @property
    def latest(self) -> VehicleTelemetry | None:
        """The newest telemetry frame, or None before the first."""
        ...

    @property
    def link_ok(self) -> bool:
        """False while the link is declared lost."""
        ...

    async def wait_ready(self, timeout_s: float) -> VehicleTelemetry:
        """Wait for telemetry and a healthy global position; return the first good frame."""
        ...

    async def arm(self) -> None:
        """Arm; does nothing if already armed."""
        ...

    async def take_off(self, timeout_s: float, altitude_m: float | None = None) -> None:
        """Take off if on the ground and wait until in the air; nothing if already flying.
        ``altitude_m``: the height over home to climb to where the autopilot's take-off takes
        one (PX4's NAV_TAKEOFF); None leaves the vehicle's own take-off altitude."""
        ...

    async def start_offboard(self, first: CourseSpeedCommand) -> None:
        """Send a first setpoint, then switch the vehicle to offboard (or guided) control."""
        ...

    async def send(self, command: CourseSpeedCommand) -> None:
        """Send one (course, speed[, altitude]) command, checked against the limits."""
        ...

    async def hold(self) -> None:
        """Stop offboard control and put the vehicle in hold/loiter."""
        ...

    def telemetry(self) -> FrameStream[VehicleTelemetry]:
        """Every telemetry frame from this call on; ends when the link closes. A reader that
        stops early calls ``aclose()`` (else the frames keep queueing for it)."""
        ...

    def observations(self) -> AsyncIterator[TargetObservation]:
        """Every target observation from the vehicle's camera from this call on."""
        ...

    def events(self) -> AsyncIterator[LinkEvent]:
        """Every link event from this call on (subscribe before the action that causes it)."""
        ...
