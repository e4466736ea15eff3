"""Error figures of an estimate track against the truth: RMSE overall and per segment, NEES.

The truth is given at its own times and interpolated linearly to the estimate times; an
estimate outside the truth's time span is not scored. Segment labels come from the truth row at
or before each estimate time.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2  # type: ignore[import-untyped]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class ErrorSeries:
    """Per-estimate errors: time (n,), position error vector (n, 2) m, velocity (n, 2) m/s,
    NEES of [x, vx, y, vy] (n,) (NaN without covariances), segment label per estimate."""

    t_s: FloatArray
    position_m: FloatArray
    velocity_m_s: FloatArray
    nees: FloatArray
    segments: tuple[str, ...]

    def rmse(self, mask: NDArray[np.bool_] | None = None) -> tuple[float, float]:
        """(position RMSE m, velocity RMSE m/s) over the estimates selected by ``mask``."""
        pos, vel = self.position_m, self.velocity_m_s
        if mask is not None:
            pos, vel = pos[mask], vel[mask]
        if pos.shape[0] == 0:
            return float("nan"), float("nan")
        return (
            float(np.sqrt(np.mean(np.sum(pos * pos, axis=1)))),
            float(np.sqrt(np.mean(np.sum(vel * vel, axis=1)))),
        )

    def mask_for(self, prefix: str) -> NDArray[np.bool_]:
        """Estimates whose segment label starts with ``prefix`` (e.g. "turn", "straight")."""
        return np.array([s.startswith(prefix) for s in self.segments], dtype=bool)

    def per_segment(self) -> dict[str, tuple[float, float, int]]:
        """RMSE (position, velocity) and count per segment label, in order of appearance."""
        labels = np.array(self.segments, dtype=object)
        out: dict[str, tuple[float, float, int]] = {}
        for label in dict.fromkeys(self.segments):
            mask = labels == label
            pos, vel = self.rmse(mask)
            out[label] = (pos, vel, int(mask.sum()))
        return out


def errors(
    t_s: FloatArray,
    x: FloatArray,
    truth_t_s: FloatArray,
    truth: FloatArray,
    truth_segments: Sequence[str] | None = None,
    p: FloatArray | None = None,
) -> ErrorSeries:
    """Errors of estimates ``x`` (n, 6) in the paper's order [x, vx, y, vy, ax, ay] (or (n, 4) as
    [east, north, v_east, v_north] when ``p`` is None) against ``truth`` (m, 4) =
    [east, north, v_east, v_north] at ``truth_t_s`` (m,), increasing."""
    inside = (t_s >= truth_t_s[0]) & (t_s <= truth_t_s[-1])
    t = t_s[inside]
    est = x[inside]
    if est.shape[1] == 6:
        east, north, ve, vn = est[:, 0], est[:, 2], est[:, 1], est[:, 3]
    else:
        east, north, ve, vn = est[:, 0], est[:, 1], est[:, 2], est[:, 3]
    true = np.stack([np.interp(t, truth_t_s, truth[:, k]) for k in range(4)], axis=1)
    pos = np.stack([east - true[:, 0], north - true[:, 1]], axis=1)
    vel = np.stack([ve - true[:, 2], vn - true[:, 3]], axis=1)
    if p is not None and est.shape[1] == 6:
        idx = [0, 1, 2, 3]
        cov = p[inside][:, idx][:, :, idx]
        err = np.stack([pos[:, 0], vel[:, 0], pos[:, 1], vel[:, 1]], axis=1)
        nees = np.einsum("ni,ni->n", err, np.linalg.solve(cov, err[:, :, None])[:, :, 0])
    else:
        nees = np.full(t.shape[0], np.nan)
    if truth_segments is None:
        segments: tuple[str, ...] = ("all",) * t.shape[0]
    else:
        where = np.clip(np.searchsorted(truth_t_s, t, side="right") - 1, 0, len(truth_t_s) - 1)
        segments = tuple(truth_segments[int(i)] for i in where)
    return ErrorSeries(t, pos, vel, nees, segments)


def nees_band(n_runs: int, dof: int = 4, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided band of the NEES averaged over ``n_runs`` independent runs (Bar-Shalom, Li and
    Kirubarajan, section 5.4.2): n_runs * mean ~ chi-square(n_runs * dof)."""
    tail = 0.5 * (1.0 - confidence)
    total = n_runs * dof
    return float(chi2.ppf(tail, total) / n_runs), float(chi2.ppf(1.0 - tail, total) / n_runs)
