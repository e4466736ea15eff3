"""The operator's terminal view: mission stage, a table of vehicles and a progress bar.

On a terminal it redraws in place (rich); elsewhere (CI, a pipe) it prints one plain line at
most every ``plain_interval_s`` of mission time, so logs stay readable. Vehicles are numbered
from 1 (their MAVLink system ids), as the operator's ``resume N`` / ``hold N`` take them.

The time left is wall time, estimated from how fast mission time has gone by since the first
snapshot (the simulator's speed-up, slowed by a loaded machine): mission seconds left divided
by mission seconds per wall second.
"""

import math
import time
from collections.abc import Callable
from types import TracebackType
from typing import Self

from rich.console import Console, Group
from rich.live import Live
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from app.runtime.ports.view import MissionSnapshot


def _fmt(value: float, spec: str) -> str:
    return format(value, spec) if math.isfinite(value) else "-"


def _fmt_left(seconds: float | None) -> str:
    if seconds is None or not math.isfinite(seconds):
        return "-:--"
    whole = max(0, round(seconds))
    if whole >= 3600:
        return f"{whole // 3600}:{whole // 60 % 60:02d}:{whole % 60:02d}"
    return f"{whole // 60}:{whole % 60:02d}"


class LiveView:
    """Shows mission snapshots; use as a context manager around the mission."""

    def __init__(
        self,
        console: Console | None = None,
        plain_interval_s: float = 10.0,
        wall_clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._console = console or Console()
        self._interval = plain_interval_s
        self._wall_clock = wall_clock
        self._first: tuple[float, float] | None = None  # (wall s, mission s) of the first snapshot
        self._last_plain_t: float | None = None
        self._progress = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            TextColumn("{task.completed:>6.0f} / {task.total:.0f} s"),
            TimeElapsedColumn(),
            TextColumn("{task.fields[left]} left"),
            console=self._console,
        )
        self._task = self._progress.add_task("mission", total=1.0, left=_fmt_left(None))
        self._live: Live | None = None
        self._snapshot: MissionSnapshot | None = None

    def __enter__(self) -> Self:
        if self._console.is_terminal:
            self._live = Live(
                get_renderable=self._render, console=self._console, refresh_per_second=4
            )
            self._live.__enter__()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._live is not None:
            self._live.__exit__(exc_type, exc, tb)
            self._live = None

    def wall_left_s(self, snapshot: MissionSnapshot) -> float | None:
        """Wall seconds until the mission's end at the pace mission time has kept since the
        first snapshot; None until it has moved (or when the end is unknown)."""
        now = self._wall_clock()
        if self._first is None:
            self._first = (now, snapshot.t_s)
            return None
        wall_s, mission_s = now - self._first[0], snapshot.t_s - self._first[1]
        if not (wall_s > 0.0 and mission_s > 0.0 and math.isfinite(snapshot.end_t_s)):
            return None
        return max(snapshot.end_t_s - snapshot.t_s, 0.0) * wall_s / mission_s

    def update(self, snapshot: MissionSnapshot) -> None:
        self._snapshot = snapshot
        left = self.wall_left_s(snapshot)
        self._progress.update(
            self._task,
            total=max(snapshot.end_t_s, 1e-9),
            completed=min(snapshot.t_s, snapshot.end_t_s),
            description=f"{snapshot.stage:<7} {snapshot.target_segment:<6}",
            left=_fmt_left(left),
        )
        if self._live is None and (
            self._last_plain_t is None or snapshot.t_s - self._last_plain_t >= self._interval
        ):
            self._last_plain_t = snapshot.t_s
            self._console.print(
                self.plain_line(snapshot, left), highlight=False, markup=False, soft_wrap=True
            )

    @staticmethod
    def plain_line(snapshot: MissionSnapshot, wall_left_s: float | None = None) -> str:
        """One line: time (and the wall time left, when known), stage and per vehicle (from 1)
        distance error / spacing error / speed / link."""
        head = f"t={snapshot.t_s:6.1f}s"
        if wall_left_s is not None:
            head += f" ({_fmt_left(wall_left_s)} left)"
        parts = [f"{head} {snapshot.stage:<7} target {snapshot.target_segment}"]
        for row in snapshot.vehicles:
            state = row.link if row.active else f"{row.link},out"
            parts.append(
                f"v{row.vehicle + 1}: dr={_fmt(row.distance_error_m, '+.1f')}m"
                f" dphi={_fmt(row.spacing_error_deg, '+.1f')}deg"
                f" s={_fmt(row.speed_m_s, '.1f')}m/s [{state}]"
            )
        return " | ".join(parts)

    def _render(self) -> Group:
        table = Table(expand=False)
        for column in ("vehicle", "distance error (m)", "spacing error (deg)", "speed (m/s)"):
            table.add_column(column, justify="right")
        table.add_column("link")
        snapshot = self._snapshot
        title = "waiting for vehicles"
        if snapshot is not None:
            title = f"stage: {snapshot.stage}   target: {snapshot.target_segment}"
            for row in snapshot.vehicles:
                table.add_row(
                    str(row.vehicle + 1),
                    _fmt(row.distance_error_m, "+.1f"),
                    _fmt(row.spacing_error_deg, "+.1f"),
                    _fmt(row.speed_m_s, ".1f"),
                    row.link if row.active else f"{row.link} (left formation)",
                )
        table.title = title
        return Group(table, self._progress)
