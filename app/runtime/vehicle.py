"""A vehicle brought under the mission's control and let go again, over the vehicle-link port."""

import math
from collections.abc import Mapping
from dataclasses import dataclass

from app.errors import LinkError
from app.runtime.ports.events import EventSink
from app.runtime.ports.vehicle import CourseSpeedCommand, VehicleLink

#: a vehicle farther than this from the mission's origin is taken for a wrong ``[origin]``
MAX_DISTANCE_FROM_ORIGIN_M = 50_000.0


@dataclass(frozen=True, slots=True)
class BringUp:
    """How a vehicle is brought to offboard control: the waits for its health and its take-off
    (s), the altitude to hold (m above home; None keeps its own), the first setpoint's speed
    (m/s), and the mission origin (deg) it must be near."""

    connect_timeout_s: float
    take_off_timeout_s: float
    altitude_m: float | None
    cruise_speed_m_s: float
    origin_lat_deg: float
    origin_lon_deg: float


async def prepare_vehicle(link: VehicleLink, bring_up: BringUp, events: EventSink) -> None:
    """Health, arm, take off, first setpoint, offboard: the MAVSDK idiom, each step checked.

    A vehicle more than ``MAX_DISTANCE_FROM_ORIGIN_M`` from the mission's origin is refused
    before it is armed: the mission is planned in metres about that origin (a SITL's home
    differs from one autopilot to the next), and it would send the vehicle there."""
    frame = await link.wait_ready(bring_up.connect_timeout_s)
    distance = math.hypot(frame.east_m, frame.north_m)
    if distance > MAX_DISTANCE_FROM_ORIGIN_M:
        raise LinkError(
            f"vehicle {link.vehicle_id} is {distance / 1000.0:.0f} km from the mission's origin "
            f"({bring_up.origin_lat_deg:.6f}, {bring_up.origin_lon_deg:.6f}), at "
            f"({frame.latitude_deg:.6f}, {frame.longitude_deg:.6f}): set [origin] in the "
            "mission config to where the vehicles are"
        )
    await link.arm()
    await link.take_off(bring_up.take_off_timeout_s)
    latest = link.latest or frame
    first = CourseSpeedCommand(latest.course_rad, bring_up.cruise_speed_m_s, bring_up.altitude_m)
    await link.start_offboard(first)
    events.emit("offboard", latest.t_s, vehicle=link.vehicle_id - 1, autopilot=link.autopilot_name)


async def hold_all(links: Mapping[int, VehicleLink], events: EventSink, t_s: float) -> None:
    """Put every vehicle in hold (a refusal is logged, not raised: the others still hold)."""
    for i, link in links.items():
        try:
            await link.hold()
        except LinkError as exc:
            events.emit("hold_refused", t_s, vehicle=i, reason=str(exc))
