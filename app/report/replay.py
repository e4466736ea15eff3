"""A flown mission re-run offline from its run folder: estimation and the mission's decisions.

``observations.jsonl`` (``app.adapters.observations_log``) holds, in the order the mission's
loops consumed them, every observation each agent fed its local filter, every fused estimate it
applied, every status and every local estimate the ground station took. ``replay`` pumps the
same core steps in that order: each agent's ``Observed`` and ``HeardFused``
(``app.core.mission.agent.step``: the local IMM-UKF and the federated feedback), the ground's
``HeardStatuses`` and ``HeardLocal`` (``app.core.mission.ground.step``: the main filter, the
active team, the stage logic and the recorded samples). The local estimates and the fused
estimates are not read from the file: they are computed again, passed through the bus's
conversions as in the run, and handed over where the file says they were taken. So the figures
it scores (``summarize``) come from the estimator and stage logic of this code, fed the run's
inputs; for an unchanged code they are the run's own figures.

A record that names an estimate the replay did not produce (a different estimator, or a
recording cut short) is counted in ``ReplayResult.unmatched`` and skipped.
"""

import json
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from app.config.estimator import EstimatorConfig
from app.config.mission import MissionConfig
from app.config.plan import MissionPlan, build_plan
from app.core.estimation.messages import GlobalEstimate, LocalEstimate, Observation
from app.core.mission import agent as agent_logic
from app.core.mission import ground as ground_logic
from app.core.mission.team import TeamSample
from app.errors import InputError
from app.report.summary import summarize
from app.runtime import wire
from app.runtime.agent import AgentRuntimeParams
from app.runtime.ground import GroundRuntimeParams

OBSERVATIONS_SCHEMA = 1
KINDS = ("observation", "fused", "status", "local")


@dataclass(frozen=True, slots=True)
class Recording:
    """``observations.jsonl`` read and checked: the header's vehicle count and whether the run
    was scored against the scripted target, then the records in order (dicts as in the file)."""

    vehicles: int
    truth: bool
    records: tuple[Mapping[str, Any], ...]

    def count(self, kind: str) -> int:
        return sum(1 for r in self.records if r["kind"] == kind)


def _number(record: Mapping[str, Any], name: str, where: str) -> float:
    value = record.get(name)
    if value is None:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where}: {name!r} is not a number: {value!r}")
    return float(value)


def _lines(path: Path) -> Iterator[tuple[int, str]]:
    try:
        with path.open(encoding="utf-8") as handle:
            yield from enumerate(handle, start=1)
    except FileNotFoundError:
        raise InputError(
            f"{path}: no such file (runs flown before observations were recorded cannot be "
            "replayed)"
        ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read: {exc}") from exc


def read_recording(path: Path) -> Recording:
    """Read and check ``observations.jsonl``; ``InputError`` names the file and line of the
    first bad record. A last line cut short (a run killed while writing) is ignored."""
    header: Mapping[str, Any] | None = None
    records: list[Mapping[str, Any]] = []
    lines = list(_lines(path))
    for number, text in lines:
        where = f"{path}:{number}"
        try:
            record = json.loads(text)
        except json.JSONDecodeError:
            if number == len(lines) and not text.endswith("\n"):
                break  # cut short
            raise InputError(f"{where}: not JSON") from None
        if not isinstance(record, dict):
            raise InputError(f"{where}: not a JSON object")
        if header is None:
            if record.get("kind") != "header" or record.get("schema") != OBSERVATIONS_SCHEMA:
                raise InputError(f"{where}: not an observations header of schema 1")
            vehicles = record.get("vehicles")
            if not isinstance(vehicles, int) or vehicles < 1:
                raise InputError(f"{where}: 'vehicles' must be a count, got {vehicles!r}")
            header = record
            continue
        kind = record.get("kind")
        if kind not in KINDS:
            raise InputError(f"{where}: unknown kind {kind!r}")
        vehicle = record.get("vehicle")
        if not isinstance(vehicle, int) or not 0 <= vehicle < header["vehicles"]:
            raise InputError(f"{where}: 'vehicle' must be 0..{header['vehicles'] - 1}")
        if not math.isfinite(_number(record, "t_s", where)):
            raise InputError(f"{where}: 't_s' must be a finite number")
        for name in ("east_m", "north_m", "sigma_m", "course_rad", "speed_m_s"):
            _number(record, name, where)
        records.append(record)
    if header is None:
        raise InputError(f"{path}: empty (no header)")
    return Recording(header["vehicles"], bool(header.get("truth")), tuple(records))


def replay_plan(mission: MissionConfig, estimator: EstimatorConfig) -> MissionPlan:
    """The plan of a recorded config, with the recorded estimator (not the one the mission
    file names today, which may have changed or gone)."""
    plan = build_plan(
        mission.model_copy(
            update={"estimator": mission.estimator.model_copy(update={"config": "estimator"})}
        )
    )
    federated = estimator.build()
    main = federated.main
    agents = tuple(
        replace(a, local=federated.local, main=main if main.feedback != "none" else None)
        for a in plan.agents
    )
    return replace(plan, agents=agents, ground=replace(plan.ground, main=main))


@dataclass
class ReplayResult:
    """The ground's samples, its events (stage changes, vehicles leaving and joining), the
    scored figures (``summarize``'s dict, like ``summary.json``'s) and what was fed."""

    samples: list[TeamSample]
    events: list[ground_logic.GroundEvent]
    summary: dict[str, Any]
    fed: dict[str, int] = field(default_factory=dict)
    unmatched: dict[str, int] = field(default_factory=dict)

    @property
    def stages(self) -> list[tuple[float, str]]:
        """The stage changes: (mission time, new stage)."""
        return [(e.t_s, e.detail) for e in self.events if e.kind == "stage"]


def _observation(record: Mapping[str, Any], sensor: str) -> Observation:
    sigma = record.get("sigma_m")
    return Observation(
        float(record["t_s"]),
        sensor,
        _number(record, "east_m", ""),
        _number(record, "north_m", ""),
        None if sigma is None else float(sigma),
    )


def _report(record: Mapping[str, Any]) -> ground_logic.VehicleReport:
    return ground_logic.VehicleReport(
        float(record["t_s"]),
        _number(record, "east_m", ""),
        _number(record, "north_m", ""),
        _number(record, "course_rad", ""),
        _number(record, "speed_m_s", ""),
        link_ok=bool(record.get("link_ok", True)),
        healthy=bool(record.get("healthy", True)),
    )


def replay(
    plan: MissionPlan,
    recording: Recording,
    agent_runtime: AgentRuntimeParams | None = None,
    ground_runtime: GroundRuntimeParams | None = None,
) -> ReplayResult:
    """Re-run every agent's local filter and the ground's fusion and stages on the recorded
    inputs (the module docstring); the loops' periods are those the live mission runs with."""
    if recording.vehicles != plan.count:
        raise InputError(
            f"the recording has {recording.vehicles} vehicles, its config {plan.count}"
        )
    aruntime = agent_runtime or AgentRuntimeParams()
    gruntime = ground_runtime or GroundRuntimeParams(end_t_s=plan.end_t_s)
    agents = {a.vehicle: a for a in plan.agents}
    states = {
        v: agent_logic.initial_agent_state(a, aruntime.estimate_period_s, aruntime.status_period_s)
        for v, a in agents.items()
    }
    gstate = ground_logic.initial_ground_state(gruntime.tick_period_s, gruntime.mission_period_s)
    truth = plan.target if recording.truth else None
    locals_: dict[tuple[int, float], LocalEstimate] = {}
    fused: dict[float, GlobalEstimate] = {}
    samples: list[TeamSample] = []
    events: list[ground_logic.GroundEvent] = []
    fed = dict.fromkeys(KINDS, 0)
    unmatched = dict.fromkeys(("local", "fused"), 0)
    done = False
    for record in recording.records:
        kind, v = record["kind"], int(record["vehicle"])
        t = float(record["t_s"])
        if kind == "observation":
            obs = _observation(record, agents[v].sensor)
            states[v], out = agent_logic.step(states[v], agent_logic.Observed(obs), agents[v])
            if out.estimate is not None:
                # what the ground receives: the live mission's own bus conversion
                sent = wire.local_to_bus(out.estimate, v, f"agent-{v}")
                locals_[(v, sent.t_s)] = wire.local_to_core(sent)
        elif kind == "fused":
            estimate = fused.get(t)
            if estimate is None:
                unmatched["fused"] += 1
                continue
            states[v], _ = agent_logic.step(states[v], agent_logic.HeardFused(estimate), agents[v])
        elif done:
            continue  # the station stopped at the end; the agents ran on a little
        elif kind == "local":
            local = locals_.pop((v, t), None)
            if local is None:
                unmatched["local"] += 1
                continue
            gstate, _ = ground_logic.step(gstate, ground_logic.HeardLocal(local), plan.ground)
        else:  # status
            heard = ground_logic.HeardStatuses(((v, _report(record)),))
            gstate, gout = ground_logic.step(gstate, heard, plan.ground, truth)
            events.extend(gout.events)
            if gout.fused is not None:
                fused[gout.fused.t_s] = wire.global_to_core(
                    wire.global_to_bus(gout.fused, "ground")
                )
            if gout.sample is not None:
                samples.append(gout.sample)
            if gout.tick_t_s is not None and gout.tick_t_s >= gruntime.end_t_s:
                done = True
        fed[kind] += 1
    ground = plan.ground
    summary = summarize(
        samples,
        plan.config.radius_m,
        plan.config.tracking_command_s,
        ground.stages.radius_tolerance_m,
        ground.stages.spacing_tolerance_rad,
    )
    return ReplayResult(samples, events, summary, fed, unmatched)


def recorded_stages(events_path: Path) -> list[tuple[float, str]]:
    """The stage changes a run's ``events.jsonl`` holds: (mission time, stage)."""
    out = []
    for _, text in _lines(events_path):
        try:
            event = json.loads(text)
        except json.JSONDecodeError:
            continue  # a line cut short; the event log is not what is checked here
        if isinstance(event, dict) and event.get("kind") == "stage":
            t = event.get("t_s")
            out.append(
                (float(t) if isinstance(t, int | float) else math.nan, str(event.get("detail")))
            )
    return out


def figures(summary: Mapping[str, Any]) -> dict[str, float | None]:
    """The headline figures of a summary as a flat dict (``part.figure``: number or None):
    per part the team's distance and spacing RMS and max and the estimation RMSE, then the
    convergence times; what ``standoff replay`` sets beside the run's."""
    out: dict[str, float | None] = {}
    parts = summary.get("parts")
    if isinstance(parts, Mapping):
        for key, part in parts.items():
            team = part.get("team", {}) if isinstance(part, Mapping) else {}
            for name, group, stat in (
                ("distance RMS (m)", "distance_error_m", "rms"),
                ("distance max (m)", "distance_error_m", "max_abs"),
                ("spacing RMS (deg)", "spacing_error_deg", "rms"),
                ("spacing max (deg)", "spacing_error_deg", "max_abs"),
                ("estimate RMSE (m)", "estimation_rmse", "position_m"),
                ("estimate vel. RMSE (m/s)", "estimation_rmse", "velocity_m_s"),
            ):
                value = team.get(group, {}).get(stat)
                out[f"{key}: {name}"] = float(value) if isinstance(value, int | float) else None
    conv = summary.get("convergence")
    if isinstance(conv, Mapping):
        for name in ("time_to_circle_s", "time_to_spacing_s", "time_to_formation_s"):
            value = conv.get(name)
            out[name] = float(value) if isinstance(value, int | float) else None
    return out


def same_figures(
    a: Mapping[str, float | None], b: Mapping[str, float | None], tolerance: float
) -> list[str]:
    """The names of the figures that differ between ``a`` and ``b`` by more than ``tolerance``
    (relative, and absolute near 0), or that only one of them has."""
    differ = []
    for name in dict.fromkeys([*a, *b]):
        x, y = a.get(name), b.get(name)
        if x is None or y is None:
            if x is not y:
                differ.append(name)
        elif abs(x - y) > tolerance * max(1.0, abs(x), abs(y)):
            differ.append(name)
    return differ


def stage_names(stages: Sequence[tuple[float, str]]) -> list[str]:
    return [s for _, s in stages]
