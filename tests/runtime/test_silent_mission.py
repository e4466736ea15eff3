"""Every vehicle silenced for good: ``standoff fly``'s mission ends within 60 s with a run folder
that says why (issue #14 item 5), on the built-in simulator in this process."""

from __future__ import annotations

import asyncio
import csv
import json
import time
from pathlib import Path

import pytest

from app.compose.mission import Mission
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan, sim_config
from app.runtime.ports.view import MissionSnapshot
from sitl.ports import find_free_udp_base_port
from sitl.server import SimulatorServer

SILENCED_AT_S = 15.0  # mission time: the team is in gather


@pytest.mark.slow
async def test_a_mission_whose_vehicles_all_fall_silent_ends_within_60_s(tmp_path: Path) -> None:
    config = load_config("test-short", MissionConfig)
    config = config.model_copy(update={"sim": config.sim.model_copy(update={"speedup": 3.0})})
    plan = build_plan(config)
    silenced_wall: list[float] = []
    async with (
        asyncio.timeout(240.0),
        SimulatorServer(sim_config(plan, find_free_udp_base_port(plan.count))) as sim,
    ):
        due = asyncio.Event()

        def on_snapshot(snapshot: MissionSnapshot) -> None:
            if snapshot.t_s >= SILENCED_AT_S:
                due.set()

        mission = Mission(plan, tmp_path, simulator=sim, on_snapshot=on_snapshot)

        async def silence() -> None:
            await due.wait()
            for i in range(plan.count):
                sim.set_link(i, False)
            silenced_wall.append(time.monotonic())

        async with asyncio.TaskGroup() as tg:
            tg.create_task(silence())
            result = await mission.run()
    ended_after_s = time.monotonic() - silenced_wall[0]
    assert ended_after_s < 60.0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert "every vehicle silent" in summary["ground"]["end_reason"]
    assert summary["ground"]["outages"][0]["start_t_s"] >= SILENCED_AT_S
    with (tmp_path / "track.csv").open(encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    # the outage is marked in the track file (from the sample before its start on), and no
    # sample well before it
    reason = summary["ground"]["outages"][0]["reason"]
    assert reason
    assert rows[-1]["outage"] == reason
    assert not any(r["outage"] for r in rows if float(r["t_s"]) < SILENCED_AT_S - 1.0)
    assert result.summary["mission_t_s"] < plan.end_t_s
