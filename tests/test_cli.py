import subprocess
import sys

import pytest

from app.cli import COMMAND_MODULES, _reasons, main
from app.errors import ConfigError


def test_top_level_help_lists_every_subcommand(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for name in COMMAND_MODULES:
        assert name.replace("_", "-") in out


@pytest.mark.parametrize("name", COMMAND_MODULES)
def test_every_subcommand_has_help(name, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([name.replace("_", "-"), "--help"])
    assert exit_info.value.code == 0
    assert "usage:" in capsys.readouterr().out


def test_unknown_subcommand_exits_nonzero():
    result = subprocess.run(
        [sys.executable, "-m", "app", "no-such-command"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode != 0
    assert "invalid choice" in result.stderr


@pytest.mark.parametrize(
    ("args", "reason"),
    [
        (["--broker", "http://x"], "bad broker URL 'http://x'"),
        (["--connect", "udp://x"], "vehicle URL 'udp://x'"),
    ],
)
def test_fly_refuses_a_bad_url_in_one_line_before_starting_anything(args, reason, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["fly", "--quiet", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("standoff fly: error: ")
    assert reason in err[0]
    assert not out.exists()  # no simulator, no vehicle, no run folder


def test_grouped_errors_are_reasons_only_when_every_one_is_ours():
    ours = ExceptionGroup("g", [ConfigError("a"), ExceptionGroup("h", [ConfigError("b")])])
    assert _reasons(ours) == ["a", "b"]
    assert _reasons(ExceptionGroup("g", [ConfigError("a"), ValueError("bug")])) is None
