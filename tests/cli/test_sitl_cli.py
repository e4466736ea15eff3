"""``standoff sitl``: prints the endpoints, runs, stops cleanly on Ctrl-C; scenario files."""

import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.cli import main
from app.config import load_config
from app.config.simulator import SitlScenario
from app.errors import ConfigError
from sitl.ports import find_free_udp_base_port

REPO = Path(__file__).resolve().parents[2]


def _sitl(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "app", "sitl", *args],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.mark.slow
def test_sitl_prints_endpoints_and_stops_cleanly_on_ctrl_c():
    base = find_free_udp_base_port(2)
    proc = _sitl("--vehicles", "2", "--base-port", str(base), "--speedup", "5")
    try:
        assert proc.stdout is not None
        lines = []
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            lines.append(line)
            if "Ctrl-C" in line or not line:
                break
        text = "".join(lines)
        assert f"sends to 127.0.0.1:{base} " in text
        assert f"udpin://0.0.0.0:{base + 1}" in text
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=10.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "stopped at t = " in out
    assert "Traceback" not in err


def test_sitl_runs_for_a_duration(capsys):
    base = find_free_udp_base_port(3)
    code = main(
        [
            "sitl",
            "--scenario",
            "sitl-hil",
            "--base-port",
            str(base),
            "--speedup",
            "50",
            "--duration",
            "2",
            "--seed",
            "3",
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert "3 vehicles, speed-up 50x, seed 3" in out
    stopped_at = float(out.split("stopped at t = ")[1].split(" s")[0])
    assert 2.0 <= stopped_at < 10.0  # at 50x a few wall milliseconds of shutdown are seconds


@pytest.mark.parametrize(
    ("args", "reason"),
    [
        (["--vehicles", "0"], "--vehicles must be >= 1"),
        (["--speedup", "0"], "--speedup must be > 0"),
        (["--base-port", "70000"], "--base-port must be in 1..65535"),
        (["--base-port", "65530", "--vehicles", "10"], "base_port 65530 + 10 vehicles"),
        (["--scenario", "sitl-hil", "--vehicles", "5"], "lists only 3 vehicles"),
        (["--scenario", "no-such-scenario"], "no config file"),
    ],
)
def test_sitl_refuses_bad_input_with_one_line(args, reason, capsys):
    assert main(["sitl", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert reason in err
    assert len(err.splitlines()) == 1


@pytest.mark.parametrize("name", ["sitl-hil", "sitl-noisy"])
def test_shipped_scenarios_build(name):
    config = load_config(name, SitlScenario).build(count=3 if name == "sitl-noisy" else None)
    assert len(config.vehicles) == 3
    assert config.camera.sigma2_m2 == 10.0


def test_hil_scenario_matches_table_2():
    config = load_config("sitl-hil", SitlScenario).build()
    limits = config.vehicles[0].limits
    assert (limits.min_speed_m_s, limits.max_speed_m_s) == (10.0, 18.0)
    assert config.vehicles[0].cruise_speed_m_s == 14.0
    assert config.target.labels == (
        "wait",
        "high speed",
        "low speed",
        "low speed B-C",
        "accelerating",
    )
    end = config.target.state_at(config.target.duration_s + 1.0)
    assert (round(end.east_m, 1), round(end.north_m, 1), end.speed_m_s) == (441.4, 858.6, 0.0)


def test_scenario_errors_name_the_field(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera]\nsigma2_m2 = -1.0\n")
    with pytest.raises(ConfigError, match=r"camera\.sigma2_m2"):
        load_config(bad, SitlScenario)
    tight = tmp_path / "tight.toml"
    tight.write_text(
        "[[vehicles]]\nstart = { east_m = 0, north_m = 0, course_deg = 0, speed_m_s = 18 }\n"
        "loiter_radius_m = 50.0\n"
    )
    with pytest.raises(ConfigError, match=r"loiter_radius_m 50\.0 is tighter"):
        load_config(tight, SitlScenario).build()


def test_wind_is_given_toward_a_direction():
    scenario = SitlScenario.model_validate({"wind": {"speed_m_s": 5.0, "toward_deg": 90.0}})
    wind = scenario.build().wind
    assert wind.east_m_s == pytest.approx(5.0)
    assert wind.north_m_s == pytest.approx(0.0, abs=1e-12)


def test_a_taken_vehicle_port_is_a_one_line_error(tmp_path, capsys):
    base = find_free_udp_base_port(2, host="127.0.0.1")
    scenario = tmp_path / "fixed.toml"
    scenario.write_text(f"[network]\nbind_base_port = {base}\nbase_port = {base + 100}\n")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", base + 1))
        code = main(["sitl", "--scenario", str(scenario), "--vehicles", "2", "--duration", "1"])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert "cannot open the vehicle sockets" in err
    assert len(err.splitlines()) == 1


def test_hosts_from_the_command_line(capsys):
    base = find_free_udp_base_port(1)
    code = main(
        [
            "sitl",
            "--vehicles",
            "1",
            "--base-port",
            str(base),
            "--gcs-host",
            "127.0.0.2",
            "--bind-host",
            "127.0.0.1",
            "--speedup",
            "50",
            "--duration",
            "0.5",
        ]
    )
    assert code == 0
    assert f"sends to 127.0.0.2:{base} from 127.0.0.1:" in capsys.readouterr().out


def test_the_arduplane_personality_is_chosen_by_option_or_scenario(tmp_path, capsys):
    scenario = tmp_path / "ardu.toml"
    scenario.write_text('autopilot = "arduplane"\ngcs_failsafe = "return"\ngcs_system_id = 245\n')
    built = load_config(scenario, SitlScenario).build()
    assert (built.autopilot, built.gcs_failsafe, built.gcs_system_id) == (
        "arduplane",
        "return",
        245,
    )
    assert SitlScenario().build().autopilot == "px4"  # the default is unchanged
    assert SitlScenario().build(autopilot="arduplane").autopilot == "arduplane"
    base = find_free_udp_base_port(1)
    argv = ["sitl", "--vehicles", "1", "--base-port", str(base), "--speedup", "50"]
    assert main([*argv, "--autopilot", "arduplane", "--duration", "0.5"]) == 0
    assert "autopilot arduplane" in capsys.readouterr().out
