"""A vehicle brought under the mission's control and let go again, over the vehicle-link port."""

import asyncio
import math
from collections.abc import Mapping
from dataclasses import dataclass

from app.errors import LinkError
from app.runtime.ports.events import EventSink
from app.runtime.ports.vehicle import CourseSpeedCommand, VehicleLink, VehicleTelemetry

#: a vehicle farther than this from the mission's origin is taken for a wrong ``[origin]``
MAX_DISTANCE_FROM_ORIGIN_M = 50_000.0


@dataclass(frozen=True, slots=True)
class BringUp:
    """How a vehicle is brought to offboard control: the waits for its health and its take-off
    (s), the altitude to hold (m above home; None keeps its own), the first setpoint's speed
    (m/s), and the mission origin (deg) it must be near. The hand-over waits (at most
    ``handover_timeout_s``) until the vehicle is above ``handover_min_height_m`` over home and
    flies at ``handover_min_airspeed_m_s`` or faster (its airspeed when the link reads one, else
    its ground speed): offboard/GUIDED is never taken on the runway."""

    connect_timeout_s: float
    take_off_timeout_s: float
    altitude_m: float | None
    cruise_speed_m_s: float
    origin_lat_deg: float
    origin_lon_deg: float
    handover_min_height_m: float = 30.0
    handover_min_airspeed_m_s: float = 0.0
    handover_timeout_s: float = 120.0


class HandoverTimeout(LinkError):
    """The vehicle did not reach the hand-over's height or airspeed in time."""


def _speed(frame: VehicleTelemetry) -> tuple[float, str]:
    """The speed the hand-over judges by, and which it is."""
    if frame.airspeed_m_s is not None and math.isfinite(frame.airspeed_m_s):
        return frame.airspeed_m_s, "airspeed"
    return frame.ground_speed_m_s, "ground_speed"


def _ready_for_handover(frame: VehicleTelemetry, bring_up: BringUp) -> bool:
    return (
        frame.in_air
        and frame.relative_altitude_m >= bring_up.handover_min_height_m
        and _speed(frame)[0] >= bring_up.handover_min_airspeed_m_s
    )


async def wait_for_handover(
    link: VehicleLink, bring_up: BringUp, events: EventSink
) -> VehicleTelemetry:
    """The first frame on which the vehicle is airborne above the hand-over height and at the
    hand-over speed (an event ``handover`` with both); ``HandoverTimeout`` (and an event
    ``handover_timeout``) naming what was not reached otherwise."""
    vehicle = link.vehicle_id - 1
    latest = link.latest
    if latest is not None and _ready_for_handover(latest, bring_up):
        ready = latest
    else:
        ready = None
        # closed when done: a subscription left behind after the hand-over would fill up at
        # the vehicle's rate (50 Hz on PX4) for the rest of the mission
        frames = link.telemetry()
        try:
            async with asyncio.timeout(bring_up.handover_timeout_s):
                async for frame in frames:
                    if _ready_for_handover(frame, bring_up):
                        ready = frame
                        break
        except TimeoutError:
            pass
        finally:
            await frames.aclose()
    if ready is None:
        last = link.latest
        missing = []
        if last is None:
            missing.append("no telemetry")
        else:
            speed, kind = _speed(last)
            if not last.in_air:
                missing.append("not in the air")
            if last.relative_altitude_m < bring_up.handover_min_height_m:
                missing.append(
                    f"height {last.relative_altitude_m:.1f} m < "
                    f"{bring_up.handover_min_height_m:.1f} m"
                )
            if speed < bring_up.handover_min_airspeed_m_s:
                missing.append(
                    f"{kind.replace('_', ' ')} {speed:.1f} m/s < "
                    f"{bring_up.handover_min_airspeed_m_s:.1f} m/s"
                )
        detail = "; ".join(missing) or "the link closed"
        events.emit(
            "handover_timeout",
            last.t_s if last is not None else 0.0,
            vehicle=vehicle,
            timeout_s=bring_up.handover_timeout_s,
            reason=detail,
        )
        raise HandoverTimeout(
            f"vehicle {link.vehicle_id} not ready for offboard control within "
            f"{bring_up.handover_timeout_s:.0f} s of its take-off: {detail}"
        )
    speed, kind = _speed(ready)
    events.emit(
        "handover",
        ready.t_s,
        vehicle=vehicle,
        height_m=round(ready.relative_altitude_m, 2),
        airspeed_m_s=round(speed, 2),
        speed_source=kind,
        flight_mode=ready.flight_mode,
    )
    return ready


async def prepare_vehicle(link: VehicleLink, bring_up: BringUp, events: EventSink) -> None:
    """Health, arm, take off, the hand-over's height and airspeed, first setpoint, offboard:
    the MAVSDK idiom, each step checked.

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
    await link.take_off(bring_up.take_off_timeout_s, bring_up.altitude_m)
    latest = await wait_for_handover(link, bring_up, events)
    first = CourseSpeedCommand(latest.course_rad, bring_up.cruise_speed_m_s, bring_up.altitude_m)
    await link.start_offboard(first)
    events.emit("offboard", latest.t_s, vehicle=link.vehicle_id - 1, autopilot=link.autopilot_name)


HOLD_TIMEOUT_S = 10.0
"""Host seconds a vehicle is given to accept the hold at the end of a mission (one real run
waited 2.5 minutes in a MAVSDK offboard stop)."""


async def hold_all(
    links: Mapping[int, VehicleLink],
    events: EventSink,
    t_s: float,
    timeout_s: float = HOLD_TIMEOUT_S,
) -> None:
    """Put every vehicle in hold, all at once, each given ``timeout_s`` (a refusal or a
    timeout is logged as ``hold_refused``, not raised: the others still hold)."""

    async def hold(i: int, link: VehicleLink) -> None:
        try:
            async with asyncio.timeout(timeout_s):
                await link.hold()
        except LinkError as exc:
            events.emit("hold_refused", t_s, vehicle=i, reason=str(exc))
        except TimeoutError:
            events.emit("hold_refused", t_s, vehicle=i, reason=f"no answer within {timeout_s:g} s")

    async with asyncio.TaskGroup() as tg:
        for i, link in links.items():
            tg.create_task(hold(i, link), name=f"hold-{i}")
