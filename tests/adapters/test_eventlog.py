import json
import logging
import math

import pytest

from app.adapters.eventlog import EventLog
from app.runtime.events import LoggingSink


def test_events_are_json_lines_with_counts(tmp_path):
    path = tmp_path / "events.jsonl"
    with EventLog(path) as log:
        log.emit("stage", 12.5, stage="adjust")
        log.emit("observation_dropped", 13.0, vehicle=1, reason="non-finite", value=math.nan)
        log.emit("stage", 40.0, stage="track", spacing=(0.1, math.inf))
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert [e["kind"] for e in lines] == ["stage", "observation_dropped", "stage"]
    assert lines[1] == {
        "t_s": 13.0,
        "kind": "observation_dropped",
        "vehicle": 2,  # index 1: written as users number vehicles, from 1
        "reason": "non-finite",
        "value": "nan",
    }
    assert lines[2]["spacing"] == [0.1, "inf"]
    assert log.counts == {"stage": 2, "observation_dropped": 1}


def test_repeated_drops_are_written_once_per_window_with_a_count(tmp_path):
    path = tmp_path / "events.jsonl"
    with EventLog(path) as log:
        for k in range(100):  # 10 s of one vehicle's camera at 10 Hz, all invalid
            reason = f"position ({k}e6, 0) m is beyond 1e6 m of the origin"
            log.emit("observation_dropped", 0.1 * k, vehicle=0, outcome="invalid", reason=reason)
        log.emit("observation_dropped", 9.95, vehicle=1, outcome="invalid", reason="x")
        log.emit("stage", 5.0, stage="track")  # other kinds are never held back
        log.emit("stage", 5.1, stage="track")
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    drops = [(e["t_s"], e["vehicle"], e.get("repeats")) for e in lines if e["kind"] != "stage"]
    # the first, the first after 5 s (49 held back before it), vehicle 2's own, and on closing
    # the last one held back (t = 9.9 s, with the 48 before it); vehicles numbered from 1
    assert drops[:3] == [(0.0, 1, None), (5.0, 1, 49), (9.95, 2, None)]
    assert drops[3][1:] == (1, 48)
    assert drops[3][0] == pytest.approx(9.9)
    assert sum(e["kind"] == "stage" for e in lines) == 2
    # the counts count every event, written or held back
    assert log.counts == {"observation_dropped": 101, "stage": 2}


def test_held_back_repeats_are_written_before_the_next_other_event(tmp_path):
    # an agent's last event must be its file's last line (the multi-process tests read it so):
    # repeats held back are written before it, not after it when the log closes
    path = tmp_path / "events.jsonl"
    with EventLog(path) as log:
        for k in range(30):
            log.emit("telemetry_rejected", 0.1 * k, vehicle=0, reason="non-finite position")
        log.emit("agent_stop", 3.0, vehicle=0)
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert [e["kind"] for e in lines] == ["telemetry_rejected"] * 2 + ["agent_stop"]
    assert lines[1]["repeats"] == 28
    assert lines[1]["t_s"] == pytest.approx(2.9)
    times = [e["t_s"] for e in lines]
    assert times == sorted(times)
    assert log.counts == {"telemetry_rejected": 30, "agent_stop": 1}


def test_vehicles_are_numbered_from_1_in_the_file_and_on_the_terminal(tmp_path, caplog):
    path = tmp_path / "events.jsonl"
    with EventLog(path) as log, caplog.at_level(logging.INFO, logger="standoff.events"):
        sink = LoggingSink(log)
        sink.emit("mission_start", 0.0, vehicles=3)  # a count, not vehicles
        sink.emit("pilot_took_over", 1.0, vehicle=0, flight_mode="HOLD")
        sink.emit("operator_command", 2.0, command="resume", vehicles=(2,))
        sink.emit("operator_command", 2.5, command="resume", vehicles=None)
        sink.emit("fused", 3.0, active=(0, 2))
        sink.emit("shutdown_sent", 4.0, agents=[0, 1, 2])
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert lines[0]["vehicles"] == 3
    assert lines[1]["vehicle"] == 1
    assert lines[2]["vehicles"] == [3]
    assert lines[3]["vehicles"] is None
    assert lines[4]["active"] == [1, 3]
    assert lines[5]["agents"] == [1, 2, 3]
    assert "t=1.00 pilot_took_over vehicle=1 flight_mode=HOLD" in caplog.text
    assert "vehicles=[3]" in caplog.text
