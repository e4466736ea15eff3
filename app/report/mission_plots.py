"""PNG figures of a mission run like the paper's Figs 20-22: trajectories, distance error and
phase difference, one panel per part of the run (gather, adjust, and track per target segment).
"""

import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import Circle

from app.core.mission.team import TeamSample
from app.report.summary import phase_key

PART_TITLES = {"gather": "gather", "adjust": "adjust phase"}


def _parts(samples: Sequence[TeamSample]) -> dict[str, list[TeamSample]]:
    parts: dict[str, list[TeamSample]] = {}
    for s in sorted(samples, key=lambda s: s.t_s):
        if s.stage != "standby":
            parts.setdefault(phase_key(s), []).append(s)
    return parts


def _grid(count: int) -> tuple[int, int]:
    cols = min(count, 3)
    return max(1, math.ceil(count / cols)), max(1, cols)


def _title(key: str) -> str:
    return PART_TITLES.get(key, key.replace("track:", "track, target "))


def plot_mission(samples: Sequence[TeamSample], radius_m: float, out_dir: Path) -> list[Path]:
    """Write trajectories.png, distance_error.png and phase_difference.png; return their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    parts = _parts(samples)
    if not parts:
        return []
    rows, cols = _grid(len(parts))
    vehicles = sorted({v.vehicle for s in samples for v in s.vehicles})
    written = []

    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 4.6 * rows), squeeze=False)
    for ax, (key, group) in zip(axes.flat, parts.items(), strict=False):
        ax.plot(
            [s.target_east_m for s in group],
            [s.target_north_m for s in group],
            "k-",
            lw=2,
            label="target",
        )
        for vehicle in vehicles:
            pts = [
                (v.east_m, v.north_m)
                for s in group
                for v in s.vehicles
                if v.vehicle == vehicle and v.active
            ]
            if pts:
                (line,) = ax.plot(*zip(*pts, strict=True), lw=1, label=f"UAV {vehicle + 1}")
                ax.plot(*pts[-1], "o", ms=4, color=line.get_color())
        last = group[-1]
        circle = Circle(
            (last.target_east_m, last.target_north_m), radius_m, fill=False, ls="--", color="grey"
        )
        ax.add_patch(circle)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(_title(key))
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
    for ax in list(axes.flat)[len(parts) :]:
        ax.axis("off")
    axes.flat[0].legend(loc="best", fontsize=8)
    fig.tight_layout()
    path = out_dir / "trajectories.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path)

    for name, ylabel, series in (
        ("distance_error", "distance error r - r_d (m)", lambda s: s.distance_errors(radius_m)),
        (
            "phase_difference",
            "phase difference to next UAV (deg)",
            lambda s: {
                k: math.degrees(e) + 360.0 / max(1, sum(v.active for v in s.vehicles))
                for k, e in s.spacing_errors().items()
            },
        ),
    ):
        fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 3.4 * rows), squeeze=False)
        for ax, (key, group) in zip(axes.flat, parts.items(), strict=False):
            for vehicle in vehicles:
                pts = [
                    (s.t_s, value) for s in group for k, value in series(s).items() if k == vehicle
                ]
                if pts:
                    ax.plot(*zip(*pts, strict=True), lw=1, label=f"UAV {vehicle + 1}")
            if name == "distance_error":
                ax.axhline(0.0, color="grey", lw=0.8)
            else:
                active = max(1, sum(v.active for v in group[-1].vehicles))
                ax.axhline(360.0 / active, color="grey", lw=0.8, ls="--")
            ax.set_title(_title(key))
            ax.set_xlabel("time (s)")
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
        for ax in list(axes.flat)[len(parts) :]:
            ax.axis("off")
        axes.flat[0].legend(loc="best", fontsize=8)
        fig.tight_layout()
        path = out_dir / f"{name}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written
