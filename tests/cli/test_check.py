"""``standoff check CONFIG`` and ``standoff fly --dry-run``: the plan printed, nothing flown."""

from pathlib import Path

import pytest

from app.cli import main


def test_check_prints_the_vehicles_ports_stages_and_nothing_to_set_on_the_simulator(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["check", "test-short", "--base-port", "15000"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("test-short: valid")
    for i in range(3):  # vehicle (system id), agent login, --vehicle, altitude, its port
        row = f"{i + 1:>19}  {f'agent-{i + 1}':>11}  {i + 1:>9}  {100 + 35 * i:>6} m"
        assert f"{row}  udpin://127.0.0.1:{15000 + i}" in out
    assert "until 5 s" in out
    assert "within 15 m of the circle" in out
    assert "velocity:\n    none" in out


def test_check_names_the_parameters_set_on_each_autopilot(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["check", "ardupilot-sitl"]) == 0
    ardupilot = capsys.readouterr().out
    for name in ("SYSID_MYGCS", "FS_LONG_ACTN", "FS_GCS_ENABL", "AIRSPEED_MIN"):
        assert name in ardupilot
    assert main(["check", "px4-sitl"]) == 0
    px4 = capsys.readouterr().out
    assert "COM_OBL_RC_ACT set to 5" in px4
    assert "FW_AIRSPD_MIN..FW_AIRSPD_MAX" in px4
    assert "udpin://0.0.0.0:14540" in px4
    assert "SYSID_MYGCS" not in px4
    # auto against external vehicles: whichever adapter each vehicle turns out to need
    assert main(["check", "px4-sitl", "--connect", "udpin://0.0.0.0:14560"]) == 0
    assert "udpin://0.0.0.0:14560" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ('name = "x"\nvehicles = 0\n', "vehicles"),
        ("not toml [", "x.toml"),
    ],
)
def test_a_bad_file_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, reason: str
) -> None:
    path = tmp_path / "x.toml"
    path.write_text(text)
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("standoff check: error:")
    assert "\n" not in err
    assert reason in err


def test_a_bad_url_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "px4-sitl", "--connect", "bogus://x"]) == 2
    assert "scheme" in capsys.readouterr().err


def test_fly_dry_run_prints_the_plan_and_writes_no_run_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    assert main(["fly", "test-short", "--dry-run", "--out", str(out)]) == 0
    assert "system id" in capsys.readouterr().out
    assert not out.exists()
