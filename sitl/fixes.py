"""Seeded estimation scenarios: a scripted target's truth and noisy position fixes from n sensors.

A scenario is a target path (``sitl.target.TargetPath``: the Fig. 12-like manoeuvre path or the
section 5.2 A-B-C-D path, both described in ``configs/est-*.toml``) plus how the vehicles see
it: n sensors at a rate, each sensor's clock offset (staggered by default, so observations
arrive asynchronously), and Gaussian position noise of ``sigma_m`` per axis. The same seed gives
the same data.
"""

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.core.estimation.messages import Observation
from sitl.target import TargetPath

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class SensorSpec:
    """How the team sees the target.

    Parameters
    ----------
    n_sensors
        Number of vehicles taking fixes (sensor ids "1".."n").
    rate_hz
        Fixes per second per sensor.
    sigma_m
        Standard deviation of each coordinate of a fix, m (sigma^2 = 10 m^2: about 3.16 m).
    stagger
        Offset sensor i's clock by i / (n rate) so the fixes interleave; else all fire together.
    """

    n_sensors: int = 3
    rate_hz: float = 10.0
    sigma_m: float = float(np.sqrt(10.0))
    stagger: bool = True

    def __post_init__(self) -> None:
        if self.n_sensors < 1:
            raise ValueError(f"n_sensors must be >= 1, got {self.n_sensors}")
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0.0):
            raise ValueError(f"rate_hz must be > 0, got {self.rate_hz}")
        if not (np.isfinite(self.sigma_m) and self.sigma_m > 0.0):
            raise ValueError(f"sigma_m must be > 0, got {self.sigma_m}")


@dataclass(frozen=True, slots=True)
class ScenarioData:
    """Generated data.

    Attributes
    ----------
    observations
        Every fix, in time order.
    truth_t_s
        Distinct observation times, (m,).
    truth
        True [east, north, v_east, v_north] at those times, (m, 4).
    segments
        The path segment label at each of those times, (m,).
    """

    observations: tuple[Observation, ...]
    truth_t_s: FloatArray
    truth: FloatArray
    segments: tuple[str, ...]


def generate(
    path: TargetPath, sensors: SensorSpec, seed: int, duration_s: float | None = None
) -> ScenarioData:
    """Sample the path and add noise: sensor i fixes at t = i * offset + k / rate, t <= duration.

    ``duration_s`` defaults to the path's own duration.
    """
    duration = path.duration_s if duration_s is None else float(duration_s)
    rng = np.random.default_rng(seed)
    period = 1.0 / sensors.rate_hz
    per_sensor: list[FloatArray] = []
    for i in range(sensors.n_sensors):
        offset = i * period / sensors.n_sensors if sensors.stagger else 0.0
        count = int(np.floor((duration - offset) / period + 1e-9)) + 1
        per_sensor.append(offset + period * np.arange(count, dtype=np.float64))
    rows: list[tuple[float, int]] = [
        (float(t), i) for i, times in enumerate(per_sensor) for t in times
    ]
    rows.sort()
    all_times = np.array([t for t, _ in rows])
    truth_t = np.unique(all_times)
    states = path.sample(truth_t)
    truth = states[:, :4]
    index = np.searchsorted(truth_t, all_times)
    noise = rng.normal(0.0, sensors.sigma_m, size=(len(rows), 2))
    observations = tuple(
        Observation(
            t_s=t,
            sensor=str(i + 1),
            east_m=float(truth[k, 0] + noise[j, 0]),
            north_m=float(truth[k, 1] + noise[j, 1]),
            sigma_m=sensors.sigma_m,
        )
        for j, ((t, i), k) in enumerate(zip(rows, index, strict=True))
    )
    segments = tuple(path.segment_at(float(t)) for t in truth_t)
    return ScenarioData(observations, truth_t, truth, segments)
