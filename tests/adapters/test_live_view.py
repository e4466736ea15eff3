import io
import math

from rich.console import Console

from app.adapters.live_view import LiveView
from app.runtime.ports.view import MissionSnapshot, VehicleRow

ROWS = (
    VehicleRow(0, 1.25, -0.5, 14.0, "ok", True),
    VehicleRow(1, math.nan, math.nan, 0.0, "lost", False),
)


def test_plain_output_is_throttled_to_mission_time_one_unbroken_line_each():
    out = io.StringIO()
    # a log file or pipe: rich assumes 80 columns there; a line must not be broken at them
    console = Console(file=out, force_terminal=False, width=60)
    with LiveView(console, plain_interval_s=10.0) as view:
        for t in range(25):
            view.update(MissionSnapshot(float(t), 100.0, "adjust", "wait", ROWS))
    lines = out.getvalue().splitlines()
    assert len(lines) == 3  # t = 0, 10, 20
    assert lines[1].startswith("t=  10.0s adjust")
    assert "v0: dr=+1.2m dphi=-0.5deg s=14.0m/s [ok]" in lines[1]
    assert "v1: dr=-m dphi=-deg s=0.0m/s [lost,out]" in lines[1]


def test_terminal_view_renders_a_table_and_progress():
    out = io.StringIO()
    console = Console(file=out, force_terminal=True, width=120)
    with LiveView(console) as view:
        view.update(MissionSnapshot(50.0, 100.0, "track", "A-B", ROWS))
    text = out.getvalue()
    assert "stage: track" in text
    assert "left formation" in text
