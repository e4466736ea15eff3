"""What the benchmarks that fly ``standoff fly`` over MAVLink share: one run on the built-in
simulator (its own process, MAVSDK over UDP, the in-process bus), the figures read from its
``summary.json`` and the table cells that compare them."""

import asyncio
from pathlib import Path
from typing import Any

from app.compose.mission import Mission
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from sitl.ports import find_free_udp_base_port

Figures = dict[str, float | None]


def figures_of(summary: dict[str, Any]) -> Figures:
    """Formation time (s after the tracking command) and every track segment's RMS distance
    (m) and spacing (deg) errors."""
    out: Figures = {"formation_s": (summary.get("convergence") or {}).get("time_to_formation_s")}
    for key, part in (summary.get("parts") or {}).items():
        if not key.startswith("track:") or key == "track:wait":
            continue
        label = key.removeprefix("track:")
        out[f"{label} dist"] = part["team"]["distance_error_m"]["rms"]
        out[f"{label} spacing"] = part["team"]["spacing_error_deg"]["rms"]
    return out


def mean(runs: list[Figures]) -> Figures:
    """Each figure's mean over the runs; None where some run has none (e.g. never formed)."""
    out: Figures = {}
    for key in runs[0]:
        values = [v for r in runs if (v := r.get(key)) is not None]
        out[key] = sum(values) / len(values) if len(values) == len(runs) else None
    return out


def cell(value: float | None, base: float | None) -> str:
    """A figure with its ratio to ``base``."""
    if value is None:
        return "   never     "
    if base is None or not base > 0.0:
        return f"{value:7.1f}      "
    return f"{value:7.1f} {value / base:4.2f}x"


async def fly_mavlink(config: MissionConfig, out_dir: Path) -> dict[str, Any]:
    """``standoff fly`` on the built-in simulator on free UDP ports; the run's summary."""
    plan = build_plan(config)
    port = find_free_udp_base_port(plan.count)
    async with asyncio.timeout(20 * 60):
        result = await Mission(plan, out_dir, base_port=port).run()
    return result.summary
