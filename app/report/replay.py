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
from app.runtime.ports import topics

OBSERVATIONS_SCHEMA = 1
KINDS = ("observation", "fused", "status", "local")
AGENT_KINDS = ("observation", "fused")  # what an agent was fed; the others the ground took


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
        for name in ("east_m", "north_m", "sigma_m", "course_rad", "speed_m_s", "clock_t_s"):
            _number(record, name, where)
        records.append(record)
    if header is None:
        raise InputError(f"{path}: empty (no header)")
    return Recording(header["vehicles"], bool(header.get("truth")), tuple(records))


def read_run_recording(run_dir: Path) -> Recording:
    """A run folder's recording: ``observations.jsonl`` (one process: ``standoff fly``), or the
    ground's and each agent's (``observations-<role>.jsonl`` of ``standoff ground`` and
    ``standoff agent`` writing to one folder), merged. Each part of the mission must be in one
    file only."""
    paths = sorted(run_dir.glob("observations*.jsonl"))
    if not paths:
        raise InputError(
            f"{run_dir}: no observations.jsonl (runs flown before observations were recorded "
            "cannot be replayed)"
        )
    parts = [read_recording(path) for path in paths]
    vehicles = {part.vehicles for part in parts}
    if len(vehicles) != 1:
        raise InputError(f"{run_dir}: recordings of different teams ({sorted(vehicles)} vehicles)")
    owners: dict[tuple[str, int], Path] = {}
    for path, part in zip(paths, parts, strict=True):
        for record in part.records:
            actor = ("agent", record["vehicle"]) if record["kind"] in AGENT_KINDS else ("ground", 0)
            if owners.setdefault(actor, path) != path:
                raise InputError(
                    f"{run_dir}: {path.name} and {owners[actor].name} both hold the "
                    f"{actor[0]}{'' if actor[0] == 'ground' else f' {actor[1]}'}'s inputs"
                )
    return Recording(
        vehicles.pop(),
        any(part.truth for part in parts),
        tuple(record for part in parts for record in part.records),
    )


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


def _clock(record: Mapping[str, Any]) -> float | None:
    """The ground's clock when it took the record (None: it had none)."""
    value = record.get("clock_t_s")
    return None if value is None else float(value)


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


class _Replay:
    """The replay's state: each agent's and the ground's, and the estimates they passed."""

    def __init__(
        self,
        plan: MissionPlan,
        truth: bool,
        aruntime: AgentRuntimeParams,
        gruntime: GroundRuntimeParams,
    ) -> None:
        self.plan = plan
        self.agents = {a.vehicle: a for a in plan.agents}
        self.states = {
            v: agent_logic.initial_agent_state(
                a, aruntime.estimate_period_s, aruntime.status_period_s
            )
            for v, a in self.agents.items()
        }
        self.gstate = ground_logic.initial_ground_state(
            gruntime.tick_period_s, gruntime.mission_period_s
        )
        self.end_t_s = gruntime.end_t_s
        self.truth = plan.target if truth else None
        self.locals: dict[tuple[int, float], LocalEstimate] = {}
        self.fused: dict[float, GlobalEstimate] = {}
        self.samples: list[TeamSample] = []
        self.events: list[ground_logic.GroundEvent] = []
        self.fed = dict.fromkeys(KINDS, 0)
        self.unmatched = dict.fromkeys(("local", "fused"), 0)
        self.done = False

    def agent(self, v: int, record: Mapping[str, Any]) -> None:
        """One of agent ``v``'s records: an observation into its filter, a fused estimate
        applied; a local estimate it makes is kept for the ground as the bus would carry it."""
        params = self.agents[v]
        clock = _clock(record)
        if clock is not None:  # the agent's own clock, which it judges message times by
            self.states[v] = replace(self.states[v], now_t_s=clock)
        if record["kind"] == "observation":
            obs = agent_logic.Observed(_observation(record, params.sensor))
            self.states[v], out = agent_logic.step(self.states[v], obs, params)
            if out.estimate is not None:
                sent = wire.local_to_bus(out.estimate, v, topics.agent(v))
                self.locals[(v, sent.t_s)] = wire.local_to_core(sent)
        else:
            estimate = self.fused.get(float(record["t_s"]))
            if estimate is None:
                self.unmatched["fused"] += 1
                return
            heard = agent_logic.HeardFused(estimate)
            self.states[v], _ = agent_logic.step(self.states[v], heard, params)
        self.fed[record["kind"]] += 1

    def ground(self, record: Mapping[str, Any], local: LocalEstimate | None) -> None:
        """One of the ground's records: a status (which may tick: fusion, stage, sample), or
        the local estimate ``local`` (None: the agent made none such, counted)."""
        if self.done:
            return  # the station stopped at the end
        v, params = int(record["vehicle"]), self.plan.ground
        if record["kind"] == "local":
            if local is None:
                self.unmatched["local"] += 1
                return
            heard_local = ground_logic.HeardLocal(local, _clock(record))
            self.gstate, _ = ground_logic.step(self.gstate, heard_local, params)
        else:
            heard = ground_logic.HeardStatuses(((v, _report(record)),), _clock(record))
            self.gstate, out = ground_logic.step(self.gstate, heard, params, self.truth)
            self.events.extend(out.events)
            if out.fused is not None:
                bus = wire.global_to_bus(out.fused, "ground")
                self.fused[out.fused.t_s] = wire.global_to_core(bus)
            if out.sample is not None:
                self.samples.append(out.sample)
            if out.tick_t_s is not None and out.tick_t_s >= self.end_t_s:
                self.done = True
        self.fed[record["kind"]] += 1


def replay(
    plan: MissionPlan,
    recording: Recording,
    agent_runtime: AgentRuntimeParams | None = None,
    ground_runtime: GroundRuntimeParams | None = None,
) -> ReplayResult:
    """Re-run every agent's local filter and the ground's fusion and stages on the recorded
    inputs (the module docstring); the loops' periods are those the live mission runs with.

    Each agent's records and the ground's are replayed in their own order; across them the
    replay follows the data: the ground's record of a local estimate first runs that agent's
    records until it has made the estimate. In one process's recording this is the order the
    file has; across processes (one file each) it is the order causality allows, and the
    result is the same, since an agent only waits for fused estimates the ground made before
    it took the agent's next local estimate."""
    if recording.vehicles != plan.count:
        raise InputError(
            f"the recording has {recording.vehicles} vehicles, its config {plan.count}"
        )
    run = _Replay(
        plan,
        recording.truth,
        agent_runtime or AgentRuntimeParams(),
        ground_runtime or GroundRuntimeParams(end_t_s=plan.end_t_s),
    )
    pending: dict[int, Iterator[Mapping[str, Any]]] = {
        v: iter([r for r in recording.records if r["vehicle"] == v and r["kind"] in AGENT_KINDS])
        for v in run.agents
    }
    for record in recording.records:
        if record["kind"] in AGENT_KINDS:
            continue
        local = None
        if record["kind"] == "local":
            key = (int(record["vehicle"]), float(record["t_s"]))
            agent_records = pending[key[0]]
            while key not in run.locals:
                nxt = next(agent_records, None)
                if nxt is None:
                    break
                run.agent(key[0], nxt)
            local = run.locals.pop(key, None)
        run.ground(record, local)
    for v, rest in pending.items():  # what the agents were fed after the ground's last need
        for record in rest:
            run.agent(v, record)
    summary = summarize(
        run.samples,
        plan.config.radius_m,
        plan.config.tracking_command_s,
        plan.ground.stages.radius_tolerance_m,
        plan.ground.stages.spacing_tolerance_rad,
    )
    return ReplayResult(run.samples, run.events, summary, run.fed, run.unmatched)


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
