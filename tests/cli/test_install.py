"""A plain (non-editable) install works away from the checkout: the wheel carries the shipped
mission files, and ``standoff fly``, ``simulate`` and ``configs`` find them from any folder.

The wheel is built offline (``pip wheel --no-build-isolation``, from a copy of the sources so
that the checkout gets no ``build/``) and installed with ``--no-deps`` into a fresh virtual
environment under ``tmp_path``; the dependencies come from the project's ``.venv`` through a
``.pth`` line naming its site-packages (a ``.pth`` inside a folder added that way is not run, so
the editable install's finder stays out and the checkout is not importable there).
"""

import datetime as dt
import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(
    args: list[str], cwd: Path, timeout_s: float = 60.0, stdin: str | None = None
) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    result = subprocess.run(
        args,
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout_s,
        input=stdin,
        check=False,
    )
    assert result.returncode == 0, f"{args} exited {result.returncode}:\n{result.stderr[-3000:]}"
    return result


@pytest.fixture(name="installed", scope="module")
def installed_fixture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh venv with the standoff wheel installed; returns its bin folder."""
    base = tmp_path_factory.mktemp("install")
    src = base / "src"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in ("app", "sitl", "configs"):
        shutil.copytree(ROOT / name, src / name, symlinks=True, ignore=ignore)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    wheels = base / "wheels"
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(wheels),
            str(src),
        ],
        cwd=base,
        timeout_s=120.0,
    )
    (wheel,) = wheels.glob("standoff-*.whl")
    venv = base / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=base)
    python = venv / "bin" / "python"
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(python),
            "install",
            "-q",
            "--no-deps",
            "--no-index",
            str(wheel),
        ],
        cwd=base,
        timeout_s=120.0,
    )
    site = Path(
        _run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
            cwd=base,
        ).stdout.strip()
    )
    (site / "standoff-test-dependencies.pth").write_text(
        sysconfig.get_path("purelib") + "\n", encoding="utf-8"
    )
    return venv / "bin"


@pytest.mark.slow
def test_the_installed_package_is_the_wheel_not_the_checkout(installed: Path, tmp_path: Path):
    probe = (
        "import sys, app; print(app.__file__);"
        " print(any('Editable' in getattr(f, '__name__', type(f).__name__) for f in sys.meta_path))"
    )
    lines = _run([str(installed / "python"), "-c", probe], cwd=tmp_path).stdout.split()
    app_file = Path(lines[0]).resolve()
    assert app_file.is_relative_to(installed.parent.resolve())
    assert not app_file.is_relative_to(ROOT)
    assert lines[1] == "False"  # no editable finder in this interpreter


@pytest.mark.slow
def test_configs_lists_and_prints_the_shipped_files(installed: Path, tmp_path: Path):
    listing = _run([str(installed / "standoff"), "configs"], cwd=tmp_path).stdout
    names = [line.split()[0] for line in listing.splitlines()]
    assert {"hil", "test-short", "sim-a", "estimator"} <= set(names)
    printed = _run([str(installed / "standoff"), "configs", "hil"], cwd=tmp_path).stdout
    assert printed == (ROOT / "configs" / "hil.toml").read_text(encoding="utf-8")


@pytest.mark.slow
def test_simulate_finds_its_scenario_from_another_folder(installed: Path, tmp_path: Path):
    out = _run([str(installed / "standoff"), "simulate", "sim-a"], cwd=tmp_path).stdout
    assert out.startswith("sim-a: Simulation A")
    assert "settle time" in out


@pytest.mark.slow
def test_fly_a_copied_mission_file_from_another_folder(installed: Path, tmp_path: Path):
    """The user's path: print a shipped mission, edit it (here: end it at 25 s), fly it; the
    mission file names the shipped estimator, found the same way."""
    standoff = str(installed / "standoff")
    text = _run([standoff, "configs", "test-short"], cwd=tmp_path).stdout
    mission = tmp_path / "my-mission.toml"
    mission.write_text("end_s = 25.0\n" + text, encoding="utf-8")
    out = tmp_path / "run"
    args = [standoff, "fly", str(mission), "--speedup", "5", "--quiet", "--no-stdin"]
    _run([*args, "--out", str(out)], cwd=tmp_path, timeout_s=90.0)
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["mission_t_s"] >= 25.0
    assert (out / "track.csv").is_file()
    # how the run was made; no git commit: the installed package is not a checkout
    assert summary["schema_version"] == 2
    run = summary["run"]
    assert (run["git_commit"], run["git_dirty"], run["process"]) == (None, None, "fly")
    assert (run["speedup"], run["seed"], run["config"]["end_s"]) == (5.0, 1, 25.0)
    assert run["standoff_version"] == "0.1.0"
    started = dt.datetime.fromisoformat(run["started_utc"])
    assert started.utcoffset() == dt.timedelta(0)
    assert abs((dt.datetime.now(dt.UTC) - started).total_seconds()) < 300
    # vehicles numbered from 1, as the tlogs
    assert set(summary["links"]) == {"1", "2", "3"}
    assert {f"vehicle-{n}.tlog" for n in summary["links"]} <= {p.name for p in out.iterdir()}
