"""``standoff estimate``: generate scenario data, estimate, report, and refuse bad input."""

import csv
from pathlib import Path

import pytest

from app.cli import main

SHORT_SCENARIO = """
[sensors]
n_sensors = 3
rate_hz = 10.0
sigma_m = 3.1622776601683795

[target]
kind = "maneuvers"
start_course_deg = 45.0
start_speed_m_s = 6.0
maneuvers = [
    { duration_s = 20.0, label = "straight 1" },
    { duration_s = 10.0, turn_rate_deg_s = 3.0, label = "turn 1" },
]
"""


@pytest.fixture
def generated(tmp_path: Path) -> Path:
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    out = tmp_path / "data"
    assert (
        main(["estimate", "--generate", str(scenario), "--seed", "4", "--out-dir", str(out)]) == 0
    )
    return out


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


@pytest.mark.slow
def test_generate_then_estimate_with_truth_and_plots(generated: Path, capsys):
    measurements = generated / "measurements.csv"
    truth = generated / "truth.csv"
    assert _rows(measurements)[0].keys() >= {"t_s", "sensor", "east_m", "north_m", "sigma_m"}
    assert _rows(truth)[0].keys() >= {"t_s", "east_m", "north_m", "v_east_m_s", "v_north_m_s"}
    out = generated / "estimates.csv"
    plots = generated / "plots"
    code = main(
        [
            "estimate",
            "--measurements",
            str(measurements),
            "--truth",
            str(truth),
            "--out",
            str(out),
            "--plots",
            str(plots),
        ]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "estimate RMSE: position" in text
    assert "turn 1" in text
    assert "(all turns)" in text
    rows = _rows(out)
    assert len(rows) == len(_rows(measurements))
    assert list(rows[0])[:5] == ["t_s", "east_m", "north_m", "v_east_m_s", "v_north_m_s"]
    for name in ("fig12_trajectory.png", "fig13_position_error.png", "fig14_velocity_error.png"):
        assert (plots / name).stat().st_size > 1000
    position_rmse = float(text.split("estimate RMSE: position ")[1].split(" m")[0])
    assert position_rmse < 1.5  # 30 s with a start from an unknown velocity


def test_centralised_option(generated: Path, capsys):
    out = generated / "central.csv"
    args = ["estimate", "--measurements", str(generated / "measurements.csv"), "--out", str(out)]
    assert main([*args, "--centralised"]) == 0
    assert "sensor all" in capsys.readouterr().out


def test_bad_rows_are_rejected_counted_and_logged(tmp_path: Path, capsys, caplog):
    path = tmp_path / "m.csv"
    lines = ["t_s,sensor,east_m,north_m"]
    lines += [f"{0.1 * k:.1f},1,{k * 0.5:.2f},0.0" for k in range(50)]
    lines += ["5.0,1,nan,0.0", "5.1,1,1e9,0.0", "1.0,1,0.5,0.0"]
    path.write_text("\n".join(lines) + "\n")
    out = tmp_path / "e.csv"
    assert main(["estimate", "--measurements", str(path), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "invalid 2" in text
    assert "stale 1" in text
    assert any("non-finite" in r.getMessage() for r in caplog.records)
    assert any("beyond" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize(
    ("content", "words"),
    [
        ("t_s,sensor,east_m\n0.0,1,0.0\n", "header lacks north_m"),
        ("t_s,sensor,east_m,north_m\n0.0,1,abc,0.0\n", ":2: east_m is not a number"),
        ("t_s,sensor,east_m,north_m\n0.0,1,0.0\n", ":2: 3 fields"),
        ("", "empty file"),
        ("t_s,sensor,east_m,north_m\n", "no measurement rows"),
    ],
)
def test_malformed_measurement_files_exit_2_with_one_line(tmp_path: Path, capsys, content, words):
    path = tmp_path / "m.csv"
    path.write_text(content)
    code = main(["estimate", "--measurements", str(path), "--out", str(tmp_path / "e.csv")])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert words in err
    assert "\n" not in err


def test_argument_and_config_errors(tmp_path: Path, generated: Path, capsys):
    m = str(generated / "measurements.csv")
    assert main(["estimate", "--measurements", m]) == 2
    assert "--out" in capsys.readouterr().err
    assert main(["estimate", "--measurements", m, "--out", "x.csv", "--plots", "p"]) == 2
    assert "--truth" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text(
        '[imm]\ntransition = [[0.5]]\n[[imm.models]]\nkind = "cv"\nnoise_intensity = 1.0\n'
    )
    code = main(
        ["estimate", "--measurements", m, "--out", str(tmp_path / "e.csv"), "--config", str(bad)]
    )
    assert code == 2
    assert "sum to 1" in capsys.readouterr().err
    assert main(["estimate", "--generate", "no-such-scenario", "--out-dir", str(tmp_path)]) == 2
    assert "no config file" in capsys.readouterr().err
    truth = tmp_path / "t.csv"
    truth.write_text("t_s,east_m,north_m,v_east_m_s,v_north_m_s\n1.0,0,0,0,0\n0.5,0,0,0,0\n")
    out = str(tmp_path / "e.csv")
    assert main(["estimate", "--measurements", m, "--out", out, "--truth", str(truth)]) == 2
    assert "does not increase" in capsys.readouterr().err
