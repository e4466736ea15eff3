import json
import math

from app.adapters.eventlog import EventLog


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
        "vehicle": 1,
        "reason": "non-finite",
        "value": "nan",
    }
    assert lines[2]["spacing"] == [0.1, "inf"]
    assert log.counts == {"stage": 2, "observation_dropped": 1}
