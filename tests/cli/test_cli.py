import argparse
import re
import subprocess
import sys

import pytest

from app.cli import COMMAND_MODULES, _reasons, main
from app.cli._options import with_overrides
from app.config import load_config
from app.config.loading import shipped_names
from app.config.mission import MissionConfig
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


def test_unknown_subcommand_exits_nonzero(capsys):
    # argparse's exit, in this process: the code `python -m app` exits with (the interpreter's
    # own path from main to its exit code is run by every subprocess test, test_multiprocess)
    with pytest.raises(SystemExit) as exit_info:
        main(["no-such-command"])
    assert exit_info.value.code != 0
    assert "invalid choice" in capsys.readouterr().err


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


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--vehicles", "0"], "vehicles"),
        (["--vehicles", "1000"], "vehicles"),
        (["--speedup", "-1"], "sim.speedup"),
        (["--speedup", "nan"], "sim.speedup"),
        (["--seed", "-5"], "sim.seed"),
        (["--base-port", "70000"], "sim.base_port"),
    ],
)
def test_fly_validates_its_options_like_the_config_file(args, field, tmp_path, capsys):
    # --vehicles 0 used to fly the config's 3, the others to fail later as "the built-in
    # simulator did not start: no output"
    out = tmp_path / "run"
    assert main(["fly", "--quiet", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith(f"standoff fly: error: command line: {field}: ")
    assert not out.exists()


@pytest.mark.parametrize(
    "command",
    [["ground", "--broker", "mqtt://127.0.0.1:1"], ["agent", "--vehicle", "1"]],
)
@pytest.mark.parametrize(
    ("args", "field"),
    [(["--vehicles", "0"], "vehicles"), (["--base-port", "70000"], "sim.base_port")],
)
def test_ground_and_agent_check_the_shared_options_like_fly(command, args, field, tmp_path, capsys):
    out = tmp_path / "run"
    argv = [*command, "--out", str(out), *args]
    if command[0] == "agent":
        argv += ["--broker", "mqtt://127.0.0.1:1"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith(f"standoff {command[0]}: error: command line: {field}: ")
    assert not out.exists()


def test_fly_options_override_the_config_and_keep_the_rest():
    # hil: no vehicle URLs, so that 2 vehicles is a valid team (px4-sitl lists 3 URLs)
    config = load_config("hil", MissionConfig)
    args = argparse.Namespace(speedup=2.0, seed=7, base_port=15000, vehicles=2)
    got = with_overrides(config, args)
    assert (got.sim.speedup, got.sim.seed, got.sim.base_port, got.vehicles) == (2.0, 7, 15000, 2)
    back = got.model_copy(
        update={
            "vehicles": config.vehicles,
            "sim": got.sim.model_copy(
                update={
                    "speedup": config.sim.speedup,
                    "seed": config.sim.seed,
                    "base_port": config.sim.base_port,
                }
            ),
        }
    )
    assert back == config


# the imports that made `standoff --help` take 1.1-1.6 s here: registering the subcommands
# must not pull them in (each handler imports what it needs)
HEAVY_MODULES = ("mavsdk", "numpy", "scipy", "matplotlib", "pydantic", "rich", "pymavlink")


def test_building_the_parser_imports_nothing_heavy():
    probe = (
        "import sys; from app.cli import build_parser; build_parser();"
        f" print(','.join(m for m in {HEAVY_MODULES!r} if m in sys.modules))"
    )
    result = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True
    )
    assert result.stdout.strip() == ""


def test_help_runs_in_a_fresh_interpreter_without_the_heavy_imports():
    probe = (
        "import sys, runpy; sys.argv = ['standoff', '--help']\n"
        "try:\n    runpy.run_module('app', run_name='__main__')\n"
        "except SystemExit as exit:\n"
        f"    print('exit', exit.code, [m for m in {HEAVY_MODULES!r} if m in sys.modules])"
    )
    result = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True
    )
    assert "usage: standoff" in result.stdout
    assert result.stdout.strip().endswith("exit 0 []")
    for name in COMMAND_MODULES:
        assert name.replace("_", "-") in result.stdout


def test_configs_lists_every_shipped_file_with_a_description(capsys):
    assert main(["configs"]) == 0
    lines = capsys.readouterr().out.splitlines()
    # name, the command that takes it, its description: columns two or more spaces apart
    rows = [re.split(r"\s{2,}", line, maxsplit=2) for line in lines]
    listed = {name: (command, text) for name, command, text in rows}
    assert set(listed) == set(shipped_names())
    assert listed["sim-a"] == (
        "simulate",
        "Simulation A: start far outside the circle, flying at the target",
    )
    assert listed["hil"][0] == "fly"
    assert listed["hil"][1].startswith("The paper's hardware-in-the-loop mission (section 5.2")
    assert listed["sitl-hil"][0] == "sitl --scenario"
    assert listed["est-hil"][0] == "estimate --generate"
    assert listed["estimator"][0] == "estimate --config"
    assert all(len(text) <= 100 for _, text in listed.values())


def test_configs_prints_a_shipped_file_that_loads_back(capsys, tmp_path):
    assert main(["configs", "test-short"]) == 0
    copy = tmp_path / "mine.toml"
    copy.write_text(capsys.readouterr().out, encoding="utf-8")
    assert load_config(copy, MissionConfig) == load_config("test-short", MissionConfig)


def test_configs_refuses_an_unknown_name_in_one_line(capsys):
    assert main(["configs", "no-such"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("standoff configs: error: no shipped config 'no-such' (known names:")
