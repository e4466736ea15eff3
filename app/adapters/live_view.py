"""The operator's terminal view: mission stage, a table of vehicles and a progress bar.

On a terminal it redraws in place (rich); elsewhere (CI, a pipe) it prints one plain line at
most every ``plain_interval_s`` of mission time, so logs stay readable.
"""

import math
from types import TracebackType
from typing import Self

from rich.console import Console, Group
from rich.live import Live
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from app.runtime.ports.view import MissionSnapshot


def _fmt(value: float, spec: str) -> str:
    return format(value, spec) if math.isfinite(value) else "-"


class LiveView:
    """Shows mission snapshots; use as a context manager around the mission."""

    def __init__(self, console: Console | None = None, plain_interval_s: float = 10.0) -> None:
        self._console = console or Console()
        self._interval = plain_interval_s
        self._last_plain_t: float | None = None
        self._progress = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            TextColumn("{task.completed:>6.0f} / {task.total:.0f} s"),
            TimeElapsedColumn(),
            console=self._console,
        )
        self._task = self._progress.add_task("mission", total=1.0)
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

    def update(self, snapshot: MissionSnapshot) -> None:
        self._snapshot = snapshot
        self._progress.update(
            self._task,
            total=max(snapshot.end_t_s, 1e-9),
            completed=min(snapshot.t_s, snapshot.end_t_s),
            description=f"{snapshot.stage:<7} {snapshot.target_segment:<6}",
        )
        if self._live is None and (
            self._last_plain_t is None or snapshot.t_s - self._last_plain_t >= self._interval
        ):
            self._last_plain_t = snapshot.t_s
            self._console.print(
                self.plain_line(snapshot), highlight=False, markup=False, soft_wrap=True
            )

    @staticmethod
    def plain_line(snapshot: MissionSnapshot) -> str:
        """One line: time, stage and per vehicle distance error / spacing error / speed / link."""
        parts = [f"t={snapshot.t_s:6.1f}s {snapshot.stage:<7} target {snapshot.target_segment}"]
        for row in snapshot.vehicles:
            state = row.link if row.active else f"{row.link},out"
            parts.append(
                f"v{row.vehicle}: dr={_fmt(row.distance_error_m, '+.1f')}m"
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
                    str(row.vehicle),
                    _fmt(row.distance_error_m, "+.1f"),
                    _fmt(row.spacing_error_deg, "+.1f"),
                    _fmt(row.speed_m_s, ".1f"),
                    row.link if row.active else f"{row.link} (left formation)",
                )
        table.title = title
        return Group(table, self._progress)
