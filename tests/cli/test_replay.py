"""``standoff replay`` and ``standoff plot`` on a real run folder: a short mission flown on the
built-in simulator over real UDP MAVLink, MAVSDK links and the in-process bus, then replayed
from the folder alone (estimation, fusion and stages re-run) and re-plotted without flying."""

import asyncio
import json
import math
from pathlib import Path
from typing import Any

import matplotlib.image as mpimg
import pytest

from app.adapters.observations_log import OBSERVATIONS_FILE
from app.cli import main
from app.compose.mission import Mission
from app.config import load_config
from app.config.estimator import EstimatorConfig
from app.config.mission import MissionConfig
from app.config.plan import build_plan, sim_config
from app.report import replay as rp
from app.report.run_folder import read_run_config
from sitl.ports import find_free_udp_base_port
from sitl.server import SimulatorServer

pytestmark = pytest.mark.slow

END_S = 40.0  # standby, then gather: about 15 s of wall time at 3x
SPEEDUP = 3.0  # more starves one process on a 2-core machine (tests/system/test_mission_e2e)


async def _fly(out_dir: Path) -> None:
    config = load_config("test-short", MissionConfig)
    config = config.model_copy(
        update={"end_s": END_S, "sim": config.sim.model_copy(update={"speedup": SPEEDUP})}
    )
    plan = build_plan(config)
    sim = sim_config(plan, find_free_udp_base_port(plan.count))
    async with asyncio.timeout(120.0), SimulatorServer(sim) as server:
        await Mission(plan, out_dir, simulator=server).run()


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("replay") / "run"
    asyncio.run(_fly(out))
    return out


def test_the_run_folder_records_what_the_agents_and_the_ground_were_fed(run_dir: Path) -> None:
    recording = rp.read_recording(run_dir / OBSERVATIONS_FILE)
    assert recording.vehicles == 3
    assert recording.truth
    for kind in rp.KINDS:
        assert recording.count(kind) > 0, kind
    # every vehicle's camera fed its filter, at about the camera's 10 Hz once it saw the target
    per_vehicle = [
        sum(1 for r in recording.records if r["kind"] == "observation" and r["vehicle"] == v)
        for v in range(3)
    ]
    assert min(per_vehicle) > 5.0 * (END_S - 10.0)
    mission, estimator = read_run_config(run_dir)
    assert mission.name == "test-short"
    assert mission.end_s == END_S
    assert estimator.imm.models  # the estimator file itself, not its name


def test_replay_gives_the_run_s_figures_and_stages(
    run_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mission, estimator = read_run_config(run_dir)
    result = rp.replay(
        rp.replay_plan(mission, estimator), rp.read_recording(run_dir / OBSERVATIONS_FILE)
    )
    assert result.unmatched == {"local": 0, "fused": 0}
    flown = json.loads((run_dir / "summary.json").read_text())
    run_figures, replayed = rp.figures(flown), rp.figures(result.summary)
    estimation = [k for k, v in run_figures.items() if "estimate RMSE" in k and v is not None]
    assert estimation, run_figures  # the run scored its estimate
    for key in estimation:
        assert replayed[key] == pytest.approx(run_figures[key], rel=1e-9, abs=1e-9), key
    assert rp.same_figures(run_figures, replayed, 1e-9) == []
    stages = rp.recorded_stages(run_dir / "events.jsonl")
    assert rp.stage_names(stages)[:1] == ["gather"]
    assert result.stages == stages

    assert main(["replay", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert "stages the same, figures the same" in out
    assert "estimate RMSE" in out


def test_replay_with_another_estimator_reruns_the_filters(
    run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A replay computes the estimates again: a filter that trusts its models far less (a
    hundred times the process noise) follows the camera noise on the same observations, so its
    estimate track and its score move. (A hundredth of the noise moved the parked target's score
    by only 0.1-0.4 %, too little to tell from run to run; a hundred times moved it by 8 %.)"""
    _, estimator = read_run_config(run_dir)
    raw = estimator.model_dump()
    for model in raw["imm"]["models"]:
        model["noise_intensity"] *= 100.0
    loose = EstimatorConfig.model_validate(raw)
    mission, _ = read_run_config(run_dir)
    recording = rp.read_recording(run_dir / OBSERVATIONS_FILE)
    same = rp.replay(rp.replay_plan(mission, estimator), recording)
    other = rp.replay(rp.replay_plan(mission, loose), recording)
    apart = [
        math.hypot(x.estimate[0] - y.estimate[0], x.estimate[1] - y.estimate[1])
        for x, y in zip(same.samples, other.samples, strict=True)
        if x.estimate is not None and y.estimate is not None
    ]
    assert len(apart) > 100
    assert max(apart) > 0.2  # measured 0.86 m
    key = "gather: estimate RMSE (m)"
    a, b = rp.figures(same.summary)[key], rp.figures(other.summary)[key]
    assert a is not None
    assert b is not None
    assert math.isfinite(a)
    assert math.isfinite(b)
    assert abs(a - b) > 0.01 * a  # measured 8 %

    toml = tmp_path / "loose.toml"
    toml.write_text(_as_toml(raw))
    assert main(["replay", str(run_dir), "--estimator", str(toml)]) == 0
    assert "figures different" in capsys.readouterr().out


def test_plot_redraws_the_figures_from_the_files(run_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "figures"
    assert main(["plot", str(run_dir), "--out", str(out)]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == [
        "distance_error.png",
        "estimate_error.png",
        "phase_difference.png",
        "trajectories.png",
    ]
    for name in names:
        image = mpimg.imread(out / name)
        assert image.shape[0] > 200
        assert image.std() > 0.01


def _as_toml(raw: dict[str, Any]) -> str:
    """The estimator dict as TOML (just what EstimatorConfig holds: tables of numbers)."""

    def value(v: object) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(float(v)) if isinstance(v, float) else str(v)

    lines = []
    for table, body in raw.items():
        lines.append(f"[{table}]")
        for key, v in body.items():
            if key == "models":
                continue
            lines.append(f"{key} = {value(v)}")
        for model in body.get("models", []) if isinstance(body, dict) else []:
            lines.append(f"[[{table}.models]]")
            lines += [f"{k} = {value(x)}" for k, x in model.items()]
    return "\n".join(lines) + "\n"
