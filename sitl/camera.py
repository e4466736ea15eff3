"""A simulated tracking camera: noisy geolocation of the target, with dropouts and outliers."""

import math
from dataclasses import dataclass

import numpy as np

from sitl.config import CameraConfig
from sitl.target import TargetState


@dataclass(frozen=True, slots=True)
class Observation:
    """One geolocated sighting of the target (metres east/north of the origin, at ``t_s``).

    ``sigma_m`` is the noise the camera claims per axis (outliers excepted); ``outlier`` and the
    true position are kept for scoring, never sent.
    """

    t_s: float
    east_m: float
    north_m: float
    sigma_m: float
    range_m: float
    outlier: bool
    true_east_m: float
    true_north_m: float


class TrackingCamera:
    """Draws observations from its own seeded stream, one draw set per sample.

    Every sample draws the same number of random numbers whether it is dropped or not, so the
    noise of sample k does not depend on what happened before (deterministic under a seed).
    """

    __slots__ = ("_config", "_rng", "enabled")

    def __init__(self, config: CameraConfig, rng: np.random.Generator) -> None:
        self._config = config
        self._rng = rng
        self.enabled = config.enabled

    @property
    def config(self) -> CameraConfig:
        return self._config

    def observe(
        self,
        t_s: float,
        vehicle_east_m: float,
        vehicle_north_m: float,
        altitude_m: float,
        target: TargetState,
    ) -> Observation | None:
        """A sighting of ``target`` from the vehicle; None if off, dropped or out of range."""
        draws = self._rng.standard_normal(4)
        u_drop, u_outlier = self._rng.random(2)
        if not self.enabled:
            return None
        cfg = self._config
        d_east = target.east_m - vehicle_east_m
        d_north = target.north_m - vehicle_north_m
        range_m = math.sqrt(d_east * d_east + d_north * d_north + altitude_m * altitude_m)
        if cfg.max_range_m is not None and range_m > cfg.max_range_m:
            return None
        if u_drop < cfg.dropout_probability:
            return None
        sigma = cfg.sigma_m(range_m)
        east = target.east_m + sigma * float(draws[0])
        north = target.north_m + sigma * float(draws[1])
        outlier = bool(u_outlier < cfg.outlier_probability)
        if outlier:
            east += cfg.outlier_sigma_m * float(draws[2])
            north += cfg.outlier_sigma_m * float(draws[3])
        return Observation(
            t_s=t_s,
            east_m=east,
            north_m=north,
            sigma_m=sigma,
            range_m=range_m,
            outlier=outlier,
            true_east_m=target.east_m,
            true_north_m=target.north_m,
        )
