"""PNG figures of a mission run like the paper's Figs 20-22: trajectories, distance error and
phase difference, one panel per part of the run (gather, adjust, and track per target segment),
each figure headed by the run's name and what it draws.

The phase difference is drawn as the spacing error, the gap to the next vehicle (counter-
clockwise) minus 360 / n, wrapped into (-180, 180] degrees: 0 when the team is evenly spaced,
never jumping between 0 and 360 as the raw gap does when two vehicles pass each other; where
the wrapped value still jumps (a gap of 360 / n +- 180) the line is broken, not drawn across.
"""

import math
from collections.abc import Callable, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import Circle

from app.core.frames import wrap_pi
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


def spacing_error_deg(sample: TeamSample) -> dict[int, float]:
    """Each active vehicle's gap to its counter-clockwise neighbour minus 360 / n, in
    (-180, 180] degrees."""
    return {k: -math.degrees(wrap_pi(-e)) for k, e in sample.spacing_errors().items()}


def broken_at_wraps(
    points: Sequence[tuple[float, float]], jump: float = 180.0
) -> tuple[list[float], list[float]]:
    """The (t, value) points as two lists, with a NaN between two neighbours whose values differ
    by more than ``jump`` (matplotlib leaves a gap there instead of a vertical line)."""
    ts: list[float] = []
    values: list[float] = []
    for t, value in points:
        if values and abs(value - values[-1]) > jump:
            ts.append(math.nan)
            values.append(math.nan)
        ts.append(t)
        values.append(value)
    return ts, values


def plot_mission(
    samples: Sequence[TeamSample], radius_m: float, out_dir: Path, *, title: str = ""
) -> list[Path]:
    """Write trajectories.png, distance_error.png, phase_difference.png and, when the samples
    carry the fused estimate, estimate_error.png; return their paths. ``title`` (the run's
    name, say) heads each figure, before what it draws."""
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
    fig.suptitle(_heading(title, f"trajectories about the target (circle: r_d = {radius_m:g} m)"))
    fig.tight_layout()
    path = out_dir / "trajectories.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path)

    figures: tuple[tuple[str, str, str, Callable[[TeamSample], dict[int, float]]], ...] = (
        (
            "distance_error",
            "distance error r - r_d (m)",
            "distance to the circle, r - r_d",
            lambda s: s.distance_errors(radius_m),
        ),
        (
            "phase_difference",
            "gap to next UAV - 360/n (deg)",
            "phase spacing error: gap to the next UAV minus 360/n, in (-180, 180]",
            spacing_error_deg,
        ),
    )
    for name, ylabel, what, series in figures:
        fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 3.4 * rows), squeeze=False)
        for ax, (key, group) in zip(axes.flat, parts.items(), strict=False):
            for vehicle in vehicles:
                pts = [
                    (s.t_s, value) for s in group for k, value in series(s).items() if k == vehicle
                ]
                if pts:
                    # a part of a few samples (an adjust that lasts a tick) shows as dots
                    marker = "o" if len(pts) < 10 else None
                    ax.plot(
                        *broken_at_wraps(pts), lw=1, ms=3, marker=marker, label=f"UAV {vehicle + 1}"
                    )
            ax.axhline(0.0, color="grey", lw=0.8)
            ax.set_title(_title(key))
            ax.set_xlabel("time (s)")
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
        for ax in list(axes.flat)[len(parts) :]:
            ax.axis("off")
        if axes.flat[0].get_legend_handles_labels()[0]:  # a lone vehicle has no spacing
            axes.flat[0].legend(loc="best", fontsize=8)
        fig.suptitle(_heading(title, what))
        fig.tight_layout()
        path = out_dir / f"{name}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    if any(s.estimate is not None for s in samples):
        written.append(_plot_estimate(parts, rows, cols, out_dir, title))
    return written


def estimate_error_m(sample: TeamSample) -> float | None:
    """How far the fused estimate is from the true target (m); None with no estimate (or no
    truth: a run scored about its estimate has none to compare)."""
    if sample.estimate is None:
        return None
    e, n = sample.estimate[:2]
    return math.hypot(e - sample.target_east_m, n - sample.target_north_m)


def _plot_estimate(
    parts: dict[str, list[TeamSample]], rows: int, cols: int, out_dir: Path, title: str
) -> Path:
    """estimate_error.png: the fused estimate's position error per part, its RMS in the title."""
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 3.4 * rows), squeeze=False)
    for ax, (key, group) in zip(axes.flat, parts.items(), strict=False):
        pts = [(s.t_s, e) for s in group if (e := estimate_error_m(s)) is not None]
        if pts:
            rms = math.sqrt(sum(e * e for _, e in pts) / len(pts))
            ax.plot(*zip(*pts, strict=True), "r-", lw=1, marker="o" if len(pts) < 10 else None)
            ax.set_title(f"{_title(key)}: RMS {rms:.2f} m")
        else:
            ax.set_title(f"{_title(key)}: no estimate")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("estimate error (m)")
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(parts) :]:
        ax.axis("off")
    fig.suptitle(_heading(title, "fused target estimate: position error against the truth"))
    fig.tight_layout()
    path = out_dir / "estimate_error.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _heading(title: str, what: str) -> str:
    return f"{title}: {what}" if title else what
