"""PNG figures of a fast simulation, like the paper's Figs 10/11 (trajectory, distance error,
course rate, laws side by side) and Fig. 15 (trajectories, speeds, adjacent phase differences).
Matplotlib with the Agg backend: no display needed."""

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from app.core.mission.stage import adjacent_phase_differences
from app.core.sampled_run import SimulationResult
from app.report.mission_plots import broken_at_wraps

_COLOURS = ("tab:red", "tab:blue", "tab:green", "tab:orange", "tab:purple", "tab:brown")


def _circle(ax: Any, result: SimulationResult) -> None:
    t = np.linspace(0.0, 2.0 * math.pi, 361)
    cx, cy = float(result.target_east_m[-1]), float(result.target_north_m[-1])
    ax.plot(cx + result.radius_m * np.cos(t), cy + result.radius_m * np.sin(t), "k--", lw=0.8)
    ax.plot(result.target_east_m, result.target_north_m, "k-", lw=0.8)
    ax.plot([cx], [cy], "k^", ms=6, label="target")


def plot_standoff(results: Mapping[str, SimulationResult], path: str | Path, title: str) -> Path:
    """Figs 10/11: (a) trajectories, (b) distance error r - r_d, (c) course rate, one line per
    law and vehicle; the first result is drawn on top. Returns the written path."""
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2), constrained_layout=True)
    ax_xy, ax_err, ax_rate = axes
    first_label, first = next(iter(results.items()))
    _circle(ax_xy, first)
    lines = [
        (label if res.n_vehicles == 1 else f"{label} UAV{i + 1}", res, i, label == first_label)
        for label, res in results.items()
        for i in range(res.n_vehicles)
    ]
    for k, (label, res, i, primary) in enumerate(lines):
        colour = _COLOURS[k % len(_COLOURS)]
        z = 3 if primary else 2
        ax_xy.plot(res.east_m[:, i], res.north_m[:, i], color=colour, lw=1.4, label=label, zorder=z)
        ax_xy.plot(res.east_m[0, i], res.north_m[0, i], "o", color=colour, ms=4)
        ax_err.plot(res.t_s, res.distance_error_m()[:, i], color=colour, lw=1.3, label=label)
        ax_rate.plot(res.t_s, res.course_rate_rad_s[:, i], color=colour, lw=1.1, label=label)
    ax_xy.set_aspect("equal", adjustable="datalim")
    ax_xy.set(xlabel="east (m)", ylabel="north (m)", title="(a) trajectories")
    ax_xy.legend(loc="best", fontsize=8)
    ax_err.axhline(0.0, color="k", lw=0.8)
    ax_err.axhspan(-3.0, 3.0, color="0.85", zorder=0)
    ax_err.set(xlabel="time (s)", ylabel="r - r_d (m)", title="(b) distance error")
    t_end = float(first.t_s[-1])
    ax_err.set_xlim(0.0, min(t_end, 250.0))
    ax_err.legend(loc="best", fontsize=8)
    ax_rate.set(
        xlabel="time (s)", ylabel="course rate (rad/s, clockwise +)", title="(c) course rate"
    )
    ax_rate.set_xlim(0.0, min(t_end, 250.0))
    ax_rate.legend(loc="best", fontsize=8)
    for ax in axes:
        ax.grid(True, lw=0.4)
    fig.suptitle(title)
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def plot_phase(result: SimulationResult, path: str | Path, title: str) -> Path:
    """Fig. 15: (a) trajectories (dot: start, square: end), (b) speeds, (c) the gaps between
    adjacent vehicles (deg) with the 2-degree band around 360 / n. Returns the written path."""
    n = result.n_vehicles
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2), constrained_layout=True)
    ax_xy, ax_v, ax_ph = axes
    _circle(ax_xy, result)
    for i in range(n):
        colour = _COLOURS[i % len(_COLOURS)]
        ax_xy.plot(
            result.east_m[:, i], result.north_m[:, i], color=colour, lw=1.2, label=f"UAV{i + 1}"
        )
        ax_xy.plot(result.east_m[0, i], result.north_m[0, i], "o", color=colour, ms=4)
        ax_xy.plot(result.east_m[-1, i], result.north_m[-1, i], "s", color=colour, ms=7)
        ax_v.plot(result.t_s, result.speed_m_s[:, i], color=colour, lw=1.2, label=f"UAV{i + 1}")
    gaps = np.degrees(adjacent_phase_differences(result.phases_rad()))
    for k in range(n):
        # a gap passes from 360 to 0 when two vehicles pass each other: broken there, not drawn
        # as a vertical line across the panel
        t, gap = broken_at_wraps(list(zip(result.t_s.tolist(), gaps[:, k].tolist(), strict=True)))
        ax_ph.plot(t, gap, color=_COLOURS[k % len(_COLOURS)], lw=1.2, label=f"gap {k + 1}")
    ideal = 360.0 / n
    ax_ph.axhspan(ideal - 2.0, ideal + 2.0, color="0.85", zorder=0)
    ax_xy.set_aspect("equal", adjustable="datalim")
    ax_xy.set(xlabel="east (m)", ylabel="north (m)", title="(a) trajectories")
    ax_v.set(xlabel="time (s)", ylabel="speed (m/s)", title="(b) speeds")
    ax_ph.set(
        xlabel="time (s)", ylabel="adjacent phase difference (deg)", title="(c) phase differences"
    )
    t_end = float(result.t_s[-1])
    ax_v.set_xlim(0.0, min(t_end, 250.0))
    ax_ph.set_xlim(0.0, min(t_end, 250.0))
    for ax in axes:
        ax.grid(True, lw=0.4)
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(title)
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
