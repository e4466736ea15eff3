"""The velocity adapter: velocity + yaw offboard setpoints (the built-in simulator, PX4
multicopters)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from mavsdk.plugins.offboard import VelocityNedYaw

from app.adapters.vehicle.autopilots.base import (
    AutopilotName,
    OffboardControl,
    OffboardPort,
    VehicleState,
    altitude_rate,
    check_finite,
    offboard_call,
)
from app.adapters.vehicle.autopilots.limits import SetpointLimits
from app.adapters.vehicle.autopilots.px4 import px4_mode_name
from app.core.frames import wrap_pi
from app.runtime.ports.vehicle import CourseSpeedCommand


@dataclass(slots=True)
class VelocityAdapter(OffboardControl):
    """Velocity + yaw setpoints (SET_POSITION_TARGET_LOCAL_NED, resent by MAVSDK at 20 Hz).

    The horizontal velocity is the course at the commanded speed, the yaw is the course, and the
    vertical velocity closes the altitude error (saturated climb rate). The speed is flown as
    commanded (``honours_speed``); no parameter is changed, so there is none to restore.
    """

    vehicle_id: int
    offboard: OffboardPort
    limits: SetpointLimits
    name: AutopilotName = "velocity"

    @property
    def honours_speed(self) -> bool:
        return True

    def mode_name(self, custom_mode: int) -> str:
        return px4_mode_name(custom_mode)

    @property
    def control_mode(self) -> str:
        return "OFFBOARD"

    async def prepare(self) -> None:
        return None

    async def restore_params(self) -> None:
        return None

    def setpoint(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> VelocityNedYaw:
        north = setpoint.speed_m_s * math.cos(setpoint.course_rad)
        east = setpoint.speed_m_s * math.sin(setpoint.course_rad)
        down = -altitude_rate(altitude_m, state, self.limits)
        yaw = math.degrees(wrap_pi(setpoint.course_rad))
        check_finite({"north": north, "east": east, "down": down, "yaw": yaw}, "velocity setpoint")
        return VelocityNedYaw(north_m_s=north, east_m_s=east, down_m_s=down, yaw_deg=yaw)

    async def send(
        self, setpoint: CourseSpeedCommand, altitude_m: float, state: VehicleState
    ) -> None:
        value = self.setpoint(setpoint, altitude_m, state)
        await offboard_call(
            "velocity setpoint", self.vehicle_id, self.offboard.set_velocity_ned(value)
        )
