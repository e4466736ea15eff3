"""A fast simulation's record of a run: every vehicle and the target, sampled at every step."""

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.core.agent import AgentEvent

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class SimulationResult:
    """Sampled run: ``t_s`` shape (m,); per-vehicle arrays shape (m, n); target arrays (m,).

    ``course_rate_rad_s`` and ``accel_m_s2`` at row j are those applied over the step that
    ended at ``t_s[j]`` (0 in row 0). ``events`` are (vehicle index, event) in time order.
    """

    t_s: FloatArray
    east_m: FloatArray
    north_m: FloatArray
    course_rad: FloatArray
    speed_m_s: FloatArray
    course_rate_rad_s: FloatArray
    accel_m_s2: FloatArray
    c: FloatArray
    inverse: NDArray[np.bool_]
    target_east_m: FloatArray
    target_north_m: FloatArray
    radius_m: float
    orbit_sign: int
    events: tuple[tuple[int, AgentEvent], ...]

    @property
    def n_vehicles(self) -> int:
        return int(self.east_m.shape[1])

    def distance_error_m(self) -> FloatArray:
        """r - r_d per sample and vehicle, m (negative inside the circle)."""
        return (
            np.hypot(
                self.east_m - self.target_east_m[:, None],
                self.north_m - self.target_north_m[:, None],
            )
            - self.radius_m
        )

    def phases_rad(self) -> FloatArray:
        """Polar angle about the target times the orbit sign (grows along the orbit), rad."""
        return self.orbit_sign * np.arctan2(
            self.north_m - self.target_north_m[:, None], self.east_m - self.target_east_m[:, None]
        )
