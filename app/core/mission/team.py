"""What the mission knows of the team: a vehicle's fix dead-reckoned, and the recorded sample.

A ``TeamSample`` is what the ground station records at each tick (and what the run's figures,
``app.report.summary``, are computed from): the team's positions and the target, true or
estimated, at one instant of vehicle time.
"""

import math
from dataclasses import dataclass

from app.core.frames import TAU
from app.core.mission.stage import vehicle_spacing_errors


def dead_reckon(
    east_m: float, north_m: float, course_rad: float, speed_m_s: float, dt_s: float
) -> tuple[float, float]:
    """Position ``dt_s`` later along a straight course (rad clockwise from north, m/s); a
    negative ``dt_s`` goes back along it."""
    return (
        east_m + speed_m_s * math.sin(course_rad) * dt_s,
        north_m + speed_m_s * math.cos(course_rad) * dt_s,
    )


@dataclass(frozen=True, slots=True)
class VehicleSample:
    vehicle: int
    active: bool
    east_m: float
    north_m: float
    speed_m_s: float
    course_rad: float = 0.0
    up_m: float | None = None  # height about the origin, where known


@dataclass(frozen=True, slots=True)
class TeamSample:
    """The team and the target at one instant of vehicle time."""

    t_s: float
    stage: str
    target_segment: str
    target_east_m: float
    target_north_m: float
    target_v_east_m_s: float
    target_v_north_m_s: float
    estimate: tuple[float, float, float, float] | None  # east, north, v_east, v_north
    vehicles: tuple[VehicleSample, ...]

    def distance_errors(self, radius_m: float) -> dict[int, float]:
        """r - r_d about the true target for each active vehicle."""
        return {
            v.vehicle: math.hypot(v.east_m - self.target_east_m, v.north_m - self.target_north_m)
            - radius_m
            for v in self.vehicles
            if v.active
        }

    def spacing_errors(self) -> dict[int, float]:
        """For each active vehicle, the counter-clockwise gap to its neighbour minus 2 pi / n."""
        return vehicle_spacing_errors(
            {
                v.vehicle: math.atan2(
                    v.north_m - self.target_north_m, v.east_m - self.target_east_m
                )
                % TAU
                for v in self.vehicles
                if v.active
            }
        )
