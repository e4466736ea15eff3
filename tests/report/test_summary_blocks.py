"""The summary's blocks beside the figures: the agents' counters of a multi-process run merged
into the ground's summary, vehicles keyed from 1, and how the run was made."""

import json
import logging

from app.adapters.eventlog import EventLog
from app.compose.distributed import agent_files
from app.compose.parts import write_outputs
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.report.provenance import run_block


def _agent_file(out, i, ticks):
    counters = {"bus": {"malformed": 0}, "agent": {"ticks": ticks}, "link": {"setpoints": ticks}}
    document = {"vehicle": i, "reason": "shutdown", "counters": counters}
    (out / f"agent-{i + 1}.json").write_text(json.dumps(document))


def test_the_agents_files_in_the_run_folder_are_read_and_bad_ones_left_out(tmp_path, caplog):
    _agent_file(tmp_path, 0, 10)
    (tmp_path / "agent-2.json").write_text("{not json")
    _agent_file(tmp_path, 2, 30)
    with caplog.at_level(logging.WARNING):
        found = agent_files(tmp_path, 4)  # vehicle index 3 (agent-4) elsewhere: no file
    assert sorted(found) == [0, 2]
    assert found[2]["agent"] == {"ticks": 30}
    assert "agent-2.json: cannot read the agent's counters" in caplog.text


def test_the_grounds_summary_carries_the_agents_blocks_keyed_from_1(tmp_path):
    plan = build_plan(load_config("test-short", MissionConfig))
    _agent_file(tmp_path, 0, 10)
    _agent_file(tmp_path, 2, 30)
    run = run_block(plan.config, started_epoch_s=0.0, speedup=3.0, process="ground")
    with EventLog(tmp_path / "events.jsonl") as log:
        result = write_outputs(
            plan, tmp_path, None, log, {}, 1.0, False, run=run, remote=agent_files(tmp_path, 3)
        )
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary == json.loads(json.dumps(result.summary, default=str))
    assert summary["schema_version"] == 2
    assert summary["links"] == {"1": {"setpoints": 10}, "3": {"setpoints": 30}}
    assert summary["agents"] == {"1": {"ticks": 10}, "3": {"ticks": 30}}
    assert set(summary["vehicle_altitudes_m"]) == {"1", "2", "3"}
    assert summary["run"]["process"] == "ground"
    assert summary["run"]["config"]["name"] == "test-short"
