"""``standoff simulate``: outputs, printed figures and one-line errors."""

import csv

import pytest

from app.cli import main
from app.report.track import TRACK_COLUMNS, TrackRow, write_track_csv


def test_simulate_writes_track_and_plots_and_prints_the_figures(tmp_path, capsys):
    code = main(["simulate", "sim-b", "--out", str(tmp_path), "--duration", "60"])
    assert code == 0
    out = capsys.readouterr().out
    for phrase in (
        "settle time",
        "minimum distance error",
        "circle crossings (deeper than 0.5 m): 0",
        "peak course rate: 0.200 rad/s",
        "inverse field used: 1 time(s)",
    ):
        assert phrase in out
    with (tmp_path / "track.csv").open(encoding="utf-8") as handle:
        rows = list(csv.reader(handle))
    assert tuple(rows[0][: len(TRACK_COLUMNS)]) == TRACK_COLUMNS
    assert len(rows) == 1 + 601  # every 0.1 s over 60 s, one vehicle
    assert float(rows[1][2]) == pytest.approx(300.0)  # starts 300 m east
    assert (tmp_path / "standoff.png").stat().st_size > 10_000


@pytest.mark.slow
def test_simulate_team_prints_phase_figures_and_the_bound(tmp_path, capsys):
    args = ["simulate", "phase", "--out", str(tmp_path), "--duration", "30", "--dt", "0.05"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "phase spacing within 2 deg" in out
    assert "speed-limited lower bound for that" in out
    assert (tmp_path / "phase.png").exists()


def test_overrides_reach_the_run(capsys):
    args = ["simulate", "sim-a", "--law", "fixed", "--c", "2.0", "--duration", "20", "--k", "2"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "law fixed c=2.0" in out
    assert "k 2.0" in out


@pytest.mark.parametrize(
    ("args", "reason"),
    [
        (["simulate", "no-such-scenario"], "no config file"),
        (["simulate", "sim-a", "--law", "fixed"], "--law fixed needs --c"),
        (["simulate", "sim-a", "--dt", "-1"], "--dt must be"),
        (["simulate", "sim-a", "--phase-gain", "nan"], "--phase-gain"),
    ],
)
def test_bad_input_is_a_one_line_error(args, reason, capsys):
    assert main(args) == 2
    err = capsys.readouterr().err
    assert reason in err
    assert len(err.strip().splitlines()) == 1


def test_bad_scenario_file_names_the_field(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("radius_m = -3\n[limits]\ncruise_speed_m_s = 20\n", encoding="utf-8")
    assert main(["simulate", str(bad)]) == 2
    assert "radius_m" in capsys.readouterr().err


def test_track_writer_checks_extras(tmp_path):
    row = TrackRow(0.0, 0, 1.0, 2.0, 0.1, 20.0, 0.0, 0.0, (1.0,))
    with pytest.raises(ValueError, match="extras"):
        write_track_csv(tmp_path / "t.csv", [row], ())
    assert write_track_csv(tmp_path / "t.csv", [row], ("x",)) == 1
    text = (tmp_path / "t.csv").read_text(encoding="utf-8").splitlines()
    assert text[0] == ",".join((*TRACK_COLUMNS, "x"))
