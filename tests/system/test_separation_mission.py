"""Separation while the team forms up (issue #13, 2b), flown on the built-in simulator over real
UDP MAVLink: three vehicles take off side by side from homes 40 m apart, climb together to a
high altitude stack and loiter around a standby point just ahead of them, as a team launched
from one airfield does. Without the guard two of them pass within a few metres of each other
at one height; with it no two come closer than the minimum distance (30 m, 3-D) at any time.
"""

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from app.compose.mission import Mission
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan, sim_config
from app.core.plant import FixedWingState
from sitl.ports import find_free_udp_base_port
from sitl.server import SimulatorServer

pytestmark = [pytest.mark.slow, pytest.mark.asyncio]

HOME_SPACING_M = 40.0


async def _fly(out_dir: Path, guard: bool) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    cfg = load_config("test-short", MissionConfig)
    cfg = cfg.model_copy(
        update={
            "tracking_command_s": 50.0,
            "end_s": 55.0,
            "separation": cfg.separation.model_copy(update={"enabled": guard}),
            # climbing together for a long time: the stack starts 250 m up
            "link": cfg.link.model_copy(update={"altitude_m": 250.0}),
            "standby": cfg.standby.model_copy(update={"east_m": -400.0, "north_m": -100.0}),
        }
    )
    plan = build_plan(cfg)
    sim = sim_config(plan, find_free_udp_base_port(plan.count))
    homes = tuple(
        replace(v, start=FixedWingState(-400.0 + HOME_SPACING_M * (i - 1), -200.0, 0.0, 14.0))
        for i, v in enumerate(sim.vehicles)
    )
    async with SimulatorServer(replace(sim, vehicles=homes)) as server:
        await Mission(plan, out_dir, simulator=server).run()
    summary = json.loads((out_dir / "summary.json").read_text())
    events = [json.loads(line) for line in (out_dir / "events.jsonl").read_text().splitlines()]
    return summary, events


async def test_the_guard_keeps_a_team_climbing_out_side_by_side_apart(tmp_path: Path) -> None:
    """(Measured: 39.98 m, the vehicles' spacing on the runway; 4.6-5.1 m without the guard.)"""
    summary, events = await _fly(tmp_path / "guarded", guard=True)
    closest = summary["separation"]
    assert closest["min_distance_m"] >= 30.0, closest
    assert any(e["kind"] == "separation" for e in events)
    assert any(e["kind"] == "separation_clear" for e in events)


async def test_without_the_guard_the_same_climb_out_comes_too_close(tmp_path: Path) -> None:
    """The scenario is a real conflict: the altitude stack alone does not separate a team that
    climbs together."""
    summary, events = await _fly(tmp_path / "unguarded", guard=False)
    assert summary["separation"]["min_distance_m"] < 30.0, summary["separation"]
    assert not any(e["kind"] == "separation" for e in events)
