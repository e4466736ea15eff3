"""MAVLink messages as MAVSDK's MavlinkDirect hands them over (JSON fields), decoded into the
link's values: pure functions, no socket, no state.

A message whose fields are missing or of the wrong type raises ``KeyError``, ``ValueError`` or
``TypeError``, for the reader to count as malformed.
"""

from __future__ import annotations

import json
import math
from typing import Any, Final

from pymavlink.dialects.v20 import common as mavlink

from app.core.frames import course_from_velocity
from app.runtime.ports.vehicle import GeodeticOrigin, TargetObservation, VehicleTelemetry

#: GLOBAL_POSITION_INT.hdg when the heading is unknown
HEADING_UNKNOWN: Final = 65535
#: below this ground speed (m/s) the course is the reported heading, not the velocity's direction
COURSE_FROM_HEADING_BELOW_M_S: Final = 0.5


def fields(message: Any) -> dict[str, Any]:
    """The fields of a MavlinkDirect message (``fields_json``) as a dict."""
    loaded = json.loads(message.fields_json)
    if not isinstance(loaded, dict):
        raise ValueError(f"fields are not an object: {message.fields_json!r}")
    return loaded


def heartbeat_modes(f: dict[str, Any]) -> tuple[int, bool]:
    """HEARTBEAT: (custom_mode, armed)."""
    custom_mode = int(f["custom_mode"])
    base_mode = int(f["base_mode"])
    return custom_mode, bool(base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)


def time_boot_s(f: dict[str, Any]) -> float:
    """The vehicle's boot time (s) of a message with ``time_boot_ms``."""
    return int(f["time_boot_ms"]) / 1000.0


def global_position(
    f: dict[str, Any],
    vehicle_id: int,
    origin: GeodeticOrigin,
    *,
    flight_mode: str,
    armed: bool,
    landed_state_in_air: bool,
    airborne_altitude_m: float,
    t_s: float | None = None,
    airspeed_m_s: float | None = None,
    wind_m_s: tuple[float, float] | None = None,
) -> VehicleTelemetry:
    """GLOBAL_POSITION_INT as a frame in the mission frame (``link_ok`` True).

    The course is the ground velocity's direction, or the heading when the vehicle is nearly at
    rest; the vehicle is in the air when its landed state says so or when it is more than
    ``airborne_altitude_m`` above home. ``t_s``: the frame's time (mission time; None: the
    message's boot time); ``airspeed_m_s``: the newest VFR_HUD airspeed, when the link has one;
    ``wind_m_s``: the autopilot's newest wind estimate (east, north), when it sends one.
    """
    if t_s is None:
        t_s = time_boot_s(f)
    lat = int(f["lat"]) / 1e7
    lon = int(f["lon"]) / 1e7
    alt = int(f["alt"]) / 1000.0
    v_north = int(f["vx"]) / 100.0
    v_east = int(f["vy"]) / 100.0
    v_down = int(f["vz"]) / 100.0
    speed = math.hypot(v_north, v_east)
    hdg = int(f["hdg"])
    if speed < COURSE_FROM_HEADING_BELOW_M_S and hdg != HEADING_UNKNOWN:
        course = math.radians(hdg / 100.0)
    else:
        course = course_from_velocity(v_east, v_north)
    relative_altitude = int(f["relative_alt"]) / 1000.0
    east, north, up = origin.to_enu(lat, lon, alt)
    return VehicleTelemetry(
        vehicle_id=vehicle_id,
        t_s=t_s,
        latitude_deg=lat,
        longitude_deg=lon,
        altitude_m=alt,
        relative_altitude_m=relative_altitude,
        east_m=east,
        north_m=north,
        up_m=up,
        course_rad=course,
        ground_speed_m_s=speed,
        v_east_m_s=v_east,
        v_north_m_s=v_north,
        climb_rate_m_s=-v_down,
        flight_mode=flight_mode,
        armed=armed,
        in_air=landed_state_in_air or relative_altitude > airborne_altitude_m,
        link_ok=True,
        airspeed_m_s=airspeed_m_s,
        wind_m_s=wind_m_s,
    )


def _wind(east: float, north: float) -> tuple[float, float] | None:
    if not (math.isfinite(east) and math.isfinite(north)):
        return None
    return east, north


def wind_cov(f: dict[str, Any]) -> tuple[float, float] | None:
    """PX4's WIND_COV: the wind (east, north m/s, where the air moves to): wind_x is north and
    wind_y east (MavlinkStreamWindCov); None while not finite (no estimate yet)."""
    return _wind(float(f["wind_y"]), float(f["wind_x"]))


def ardupilot_wind(f: dict[str, Any]) -> tuple[float, float] | None:
    """ArduPilot's WIND: ``direction`` is where the wind comes *from* (degrees), ``speed`` m/s;
    as (east, north) m/s where it blows to. None when not finite or the speed is negative."""
    speed = float(f["speed"])
    direction = math.radians(float(f["direction"]))
    if not (speed >= 0.0 and math.isfinite(direction)):
        return None
    return _wind(-speed * math.sin(direction), -speed * math.cos(direction))


def vfr_hud_airspeed(f: dict[str, Any]) -> float | None:
    """VFR_HUD: the airspeed (m/s); None when it is not a finite, non-negative number."""
    airspeed = float(f["airspeed"])
    return airspeed if math.isfinite(airspeed) and airspeed >= 0.0 else None


def attitude_roll(f: dict[str, Any]) -> float | None:
    """ATTITUDE: the roll (rad, > 0 right wing down); None when it is not a finite bank
    within +-pi/2."""
    roll = float(f["roll"])
    return roll if math.isfinite(roll) and abs(roll) < 0.5 * math.pi else None


def local_position_ned(f: dict[str, Any]) -> tuple[float, float, float]:
    """LOCAL_POSITION_NED: (north, east, down) in metres, the vehicle's own local frame."""
    return float(f["x"]), float(f["y"]), float(f["z"])


def tracking_observation(
    f: dict[str, Any], vehicle_id: int, origin: GeodeticOrigin, t_s: float | None
) -> TargetObservation | None:
    """CAMERA_TRACKING_GEO_STATUS as an observation stamped ``t_s`` (vehicle time); None when
    the tracker is idle or failing, or when there is no vehicle time to stamp it with yet (None).
    An unknown altitude is the origin's; an unknown or non-positive horizontal accuracy gives no
    sigma."""
    status = int(f["tracking_status"])
    if (
        not status & mavlink.CAMERA_TRACKING_STATUS_FLAGS_ACTIVE
        or status & mavlink.CAMERA_TRACKING_STATUS_FLAGS_ERROR
        or t_s is None
    ):
        return None
    lat = int(f["lat"]) / 1e7
    lon = int(f["lon"]) / 1e7
    raw_alt = f.get("alt")
    alt = float(raw_alt) if raw_alt is not None else origin.altitude_m
    if not math.isfinite(alt):
        alt = origin.altitude_m
    h_acc = f.get("h_acc")
    sigma = float(h_acc) if h_acc is not None else None
    if sigma is not None and not (math.isfinite(sigma) and sigma > 0.0):
        sigma = None
    east, north, _ = origin.to_enu(lat, lon, alt)
    return TargetObservation(
        vehicle_id=vehicle_id,
        t_s=t_s,
        latitude_deg=lat,
        longitude_deg=lon,
        altitude_m=alt,
        east_m=east,
        north_m=north,
        sigma_m=sigma,
    )
