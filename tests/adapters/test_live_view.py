import io
import math

from rich.console import Console

from app.adapters.live_view import LiveView
from app.runtime.ports.view import MissionSnapshot, VehicleRow

ROWS = (
    VehicleRow(0, 1.25, -0.5, 14.0, "ok", True),
    VehicleRow(1, math.nan, math.nan, 0.0, "lost", False),
)


class FakeWallClock:
    def __init__(self) -> None:
        self.now_s = 1000.0

    def __call__(self) -> float:
        return self.now_s


def test_plain_output_is_throttled_to_mission_time_one_unbroken_line_each():
    out = io.StringIO()
    # a log file or pipe: rich assumes 80 columns there; a line must not be broken at them
    console = Console(file=out, force_terminal=False, width=60)
    wall = FakeWallClock()
    with LiveView(console, plain_interval_s=10.0, wall_clock=wall) as view:
        for t in range(25):
            view.update(MissionSnapshot(float(t), 100.0, "adjust", "wait", ROWS))
            wall.now_s += 0.5
    lines = out.getvalue().splitlines()
    assert len(lines) == 3  # t = 0, 10, 20
    assert lines[1].startswith("t=  10.0s (0:45 left) adjust")
    # vehicles numbered from 1, as their system ids and the operator's 'resume N'
    assert "v1: dr=+1.2m dphi=-0.5deg s=14.0m/s [ok]" in lines[1]
    assert "v2: dr=-m dphi=-deg s=0.0m/s [lost,out]" in lines[1]


def test_terminal_view_renders_a_table_and_progress():
    out = io.StringIO()
    console = Console(file=out, force_terminal=True, width=120)
    with LiveView(console) as view:
        view.update(MissionSnapshot(50.0, 100.0, "track", "A-B", ROWS))
    text = out.getvalue()
    assert "stage: track" in text
    assert "left formation" in text


def test_time_left_is_wall_time_at_the_pace_mission_time_has_kept():
    out = io.StringIO()
    wall = FakeWallClock()
    console = Console(file=out, force_terminal=False, width=60)
    with LiveView(console, plain_interval_s=10.0, wall_clock=wall) as view:
        view.update(MissionSnapshot(0.0, 130.0, "gather", "wait", ROWS))
        wall.now_s += 5.0  # 10 mission seconds in 5 wall seconds: a 2x pace
        view.update(MissionSnapshot(10.0, 130.0, "gather", "wait", ROWS))
        assert view.wall_left_s(MissionSnapshot(10.0, 130.0, "gather", "wait", ROWS)) == 60.0
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("t=   0.0s gather")  # no pace yet, no estimate
    assert lines[1].startswith("t=  10.0s (1:00 left) gather")


def test_terminal_progress_shows_the_time_left():
    out = io.StringIO()
    wall = FakeWallClock()
    console = Console(file=out, force_terminal=True, width=120)
    with LiveView(console, wall_clock=wall) as view:
        view.update(MissionSnapshot(0.0, 3700.0, "track", "A-B", ROWS))
        wall.now_s += 100.0
        view.update(MissionSnapshot(100.0, 3700.0, "track", "A-B", ROWS))
        console.print(view._render())
    assert "1:00:00 left" in out.getvalue()
