"""MAVLink telemetry logs (``.tlog``) that MAVProxy, QGroundControl and pymavlink can replay.

A .tlog is a sequence of records: an 8-byte big-endian timestamp (microseconds since the Unix
epoch) followed by one packed MAVLink packet. The mission writes one per vehicle from the
telemetry it received through MAVSDK, re-encoded with pymavlink, so the log reads the same
whichever autopilot flew.
"""

import math
import struct
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import BinaryIO, Self

from pymavlink.dialects.v20 import common as mavlink

from app.runtime.ports.vehicle import VehicleLink

# PX4 custom mode: main mode in bits 16-23 (6 = offboard, 4 = auto with sub mode 3 = loiter)
PX4_CUSTOM_MODES = {"offboard": 6 << 16, "hold": (4 << 16) | (3 << 24)}


@dataclass(frozen=True, slots=True)
class TlogSample:
    """One telemetry instant of a vehicle, in SI units and radians (course clockwise from north)."""

    t_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float
    relative_alt_m: float
    v_north_m_s: float
    v_east_m_s: float
    course_rad: float
    speed_m_s: float
    roll_rad: float = 0.0
    armed: bool = True
    mode: str = "offboard"


class TlogWriter:
    """Writes one vehicle's .tlog; use as a context manager so the file is always closed."""

    def __init__(self, path: Path, system_id: int, epoch_s: float) -> None:
        self._path = path
        self._epoch_s = epoch_s
        self._file: BinaryIO | None = None
        self._mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=1)
        self.records = 0

    def __enter__(self) -> Self:
        self._path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self._path.open("wb")
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def write(self, sample: TlogSample) -> None:
        """Append HEARTBEAT, GLOBAL_POSITION_INT, ATTITUDE and VFR_HUD for one sample."""
        if self._file is None:
            raise RuntimeError("TlogWriter used outside its context")
        values = (sample.t_s, sample.lat_deg, sample.lon_deg, sample.alt_m, sample.speed_m_s)
        if not all(math.isfinite(v) for v in values):
            return  # a log never carries garbage; the mission counts bad telemetry elsewhere
        boot_ms = int(sample.t_s * 1000.0) & 0xFFFFFFFF
        heading_cdeg = round(math.degrees(sample.course_rad) % 360.0 * 100.0) % 36000
        base_mode = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
            mavlink.MAV_MODE_FLAG_SAFETY_ARMED if sample.armed else 0
        )
        messages = (
            self._mav.heartbeat_encode(
                mavlink.MAV_TYPE_FIXED_WING,
                mavlink.MAV_AUTOPILOT_PX4,
                base_mode,
                PX4_CUSTOM_MODES.get(sample.mode, 0),
                mavlink.MAV_STATE_ACTIVE,
            ),
            self._mav.global_position_int_encode(
                boot_ms,
                round(sample.lat_deg * 1e7),
                round(sample.lon_deg * 1e7),
                round(sample.alt_m * 1000.0),
                round(sample.relative_alt_m * 1000.0),
                round(sample.v_north_m_s * 100.0),
                round(sample.v_east_m_s * 100.0),
                0,
                heading_cdeg,
            ),
            self._mav.attitude_encode(
                boot_ms, sample.roll_rad, 0.0, sample.course_rad, 0.0, 0.0, 0.0
            ),
            self._mav.vfr_hud_encode(
                sample.speed_m_s,
                sample.speed_m_s,
                heading_cdeg // 100,
                50,
                sample.alt_m,
                0.0,
            ),
        )
        stamp = struct.pack(">Q", int((self._epoch_s + sample.t_s) * 1e6))
        for message in messages:
            self._file.write(stamp + message.pack(self._mav))
            self.records += 1


async def record_tlog(link: VehicleLink, writer: TlogWriter) -> None:
    """Write every telemetry frame of ``link`` to ``writer`` until the link closes."""
    async for f in link.telemetry():
        writer.write(
            TlogSample(
                f.t_s,
                f.latitude_deg,
                f.longitude_deg,
                f.altitude_m,
                f.relative_altitude_m,
                f.ground_speed_m_s * math.cos(f.course_rad),
                f.ground_speed_m_s * math.sin(f.course_rad),
                f.course_rad,
                f.ground_speed_m_s,
                armed=f.armed,
                mode=f.flight_mode.lower(),
            )
        )
