"""PNG figures of a target estimate against the truth, like the paper's Figs 12-14: trajectory
with measurements and estimate, position error versus time, velocity error per axis versus time.
Matplotlib with the Agg backend: no display needed."""

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from app.adapters.estimation_csv import Truth
from app.core.estimation.messages import Observation
from app.core.estimation.pipeline import EstimateTrack
from app.errors import InputError

_MAX_POINTS = 4000


def _thin(n: int) -> slice:
    return slice(None, None, max(1, n // _MAX_POINTS))


def plot_estimation(
    out_dir: Path, observations: Sequence[Observation], truth: Truth, track: EstimateTrack
) -> list[Path]:
    """Write fig12_trajectory.png, fig13_position_error.png, fig14_velocity_error.png to
    ``out_dir`` (created if needed); return their paths."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out_dir}: cannot create: {exc.strerror or exc}") from exc
    t = track.t_s
    inside = (t >= truth.t_s[0]) & (t <= truth.t_s[-1])
    t = t[inside]
    x = track.x[inside]
    true = np.stack([np.interp(t, truth.t_s, truth.states[:, k]) for k in range(4)], axis=1)
    obs = np.array([(o.t_s, o.east_m, o.north_m) for o in observations], dtype=np.float64).reshape(
        -1, 3
    )
    obs = obs[np.all(np.isfinite(obs), axis=1)]
    written: list[Path] = []

    fig, ax = plt.subplots(figsize=(7.5, 6.5), constrained_layout=True)
    thin = _thin(obs.shape[0])
    ax.plot(obs[thin, 1], obs[thin, 2], ".", ms=1.5, color="0.7", label="measurements")
    ax.plot(truth.states[:, 0], truth.states[:, 1], "k-", lw=1.2, label="true path")
    ax.plot(x[:, 0], x[:, 2], "r--", lw=1.0, label="estimate")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("Target trajectory and position estimate (cf. Fig. 12)")
    ax.legend(loc="best")
    written.append(_save(fig, out_dir / "fig12_trajectory.png"))

    fig, ax = plt.subplots(figsize=(9, 4.5), constrained_layout=True)
    if obs.shape[0]:
        raw = np.hypot(
            obs[:, 1] - np.interp(obs[:, 0], truth.t_s, truth.states[:, 0]),
            obs[:, 2] - np.interp(obs[:, 0], truth.t_s, truth.states[:, 1]),
        )
        ax.plot(obs[thin, 0], raw[thin], ".", ms=1.5, color="0.7", label="measurement error")
    err = np.hypot(x[:, 0] - true[:, 0], x[:, 2] - true[:, 1])
    ax.plot(t, err, "r-", lw=0.8, label="estimate error")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("position error (m)")
    ax.set_title(f"Position estimation error (cf. Fig. 13); RMSE {np.sqrt(np.mean(err**2)):.2f} m")
    ax.legend(loc="upper right")
    written.append(_save(fig, out_dir / "fig13_position_error.png"))

    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True, constrained_layout=True)
    for ax, k, truth_col, name in ((axes[0], 1, 2, "east (x)"), (axes[1], 3, 3, "north (y)")):
        ax.plot(t, x[:, k] - true[:, truth_col], "b-", lw=0.8)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(f"{name} velocity error (m/s)")
    axes[1].set_xlabel("t (s)")
    axes[0].set_title("Velocity estimation error (cf. Fig. 14)")
    written.append(_save(fig, out_dir / "fig14_velocity_error.png"))
    return written


def _save(fig: Any, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
