"""The fast numerical simulation: ``agent_step`` for n vehicles driving the eq. (2) fixed-wing of
``app.core.plant`` around a ``sitl.target`` path, in fixed steps, no asyncio, no clock.

Each step, every agent sees the team's positions at the start of the step (a synchronous,
loss-free exchange), the true target state and its own telemetry; its command is then held
over the step by ``app.core.plant.step``. Figures of merit (settle time, crossings, phase
spacing) are pure functions of the result.
"""

import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.core.agent import (
    AgentEvent,
    AgentInputs,
    AgentParams,
    AgentState,
    OwnTelemetry,
    TargetInfo,
    agent_step,
)
from app.core.frames import TAU
from app.core.mission.stage import adjacent_phase_differences
from app.core.phase import orbit_order, phase_time_lower_bound
from app.core.plant import FixedWingState, VehicleEnvelope, heading_for_ground_course, step
from app.core.sampled_run import FloatArray, SimulationResult
from app.core.target import TargetMotion
from app.core.values import replace


@dataclass(frozen=True, slots=True)
class SimulationSetup:
    """Everything a run needs: starts and agent parameters per vehicle (same order), the shared
    vehicle limits, the target's path, the step and the duration (s)."""

    starts: tuple[FixedWingState, ...]
    agents: tuple[AgentParams, ...]
    limits: VehicleEnvelope
    target: TargetMotion
    dt_s: float = 0.01
    duration_s: float = 400.0

    def __post_init__(self) -> None:
        if not self.starts:
            raise ValueError("a simulation needs at least one vehicle")
        if len(self.starts) != len(self.agents):
            raise ValueError(
                f"{len(self.starts)} starts but {len(self.agents)} agent parameter sets"
            )
        for i, agent in enumerate(self.agents):
            if agent.index != i:
                raise ValueError(f"agent {i} has index {agent.index}; indices must be 0..n-1")
        if not (math.isfinite(self.dt_s) and self.dt_s > 0.0):
            raise ValueError(f"dt_s must be finite and > 0, got {self.dt_s!r}")
        if not (math.isfinite(self.duration_s) and self.duration_s >= self.dt_s):
            raise ValueError(f"duration_s must be finite and >= dt_s, got {self.duration_s!r}")


Commands = list[tuple[float, float]]
"""One (course rad, speed m/s) command per vehicle."""


def fly_team(
    starts: Sequence[FixedWingState],
    limits: VehicleEnvelope,
    dt_s: float,
    steps_per_tick: int,
    ticks: int,
    control: Callable[[float, Sequence[FixedWingState]], Commands],
    *,
    latency_ticks: int = 0,
    latency_steps: int = 0,
    applied: Callable[[float, Commands, Sequence[FixedWingState]], None] | None = None,
    stepped: Callable[[int, Sequence[FixedWingState]], None] | None = None,
    wind: Callable[[int], tuple[float, float]] | None = None,
) -> list[FixedWingState]:
    """The stepping loop of every fast simulation: ticks 0..``ticks`` at
    ``t = tick * steps_per_tick * dt_s``; at each, ``control(t, team)`` gives the commands,
    which act ``latency_ticks`` ticks plus ``latency_steps`` physics steps later
    (``applied(t sent, commands, team)`` then) and are held until the next ones act, over
    physics steps of ``dt_s`` (eq. 2, ``app.core.plant.step``), after each of which
    ``stepped(step index from 1, team)`` runs. Before the first commands act, each vehicle
    holds its start course and speed. Returns the team at the last tick.

    With ``wind`` (physics step index from 0 -> (east, north) m/s blowing during that step) the
    states are air-relative (heading, airspeed; the position over the ground) and a command is
    (ground course, airspeed): each step flies the heading that holds the commanded course over
    the ground in that step's wind (``heading_for_ground_course``, as NPFG and L1 do with their
    wind estimate), so the ground course follows the command and a cross wind costs a crab."""
    if latency_ticks < 0 or latency_steps < 0:
        raise ValueError("latencies must be >= 0")
    delay = latency_ticks * steps_per_tick + latency_steps
    vehicles = list(starts)
    # (physics step index from which they act, time sent, commands)
    pending: deque[tuple[int, float, Commands]] = deque()
    held = [(v.course_rad, v.speed_m_s) for v in vehicles]
    step_index = 0
    for tick in range(ticks + 1):
        t = tick * steps_per_tick * dt_s
        pending.append((step_index + delay, t, control(t, vehicles)))
        for _ in range(steps_per_tick):
            while pending and pending[0][0] <= step_index:
                _, sent_t, held = pending.popleft()
                if len(held) != len(vehicles):
                    raise ValueError(f"{len(held)} commands for {len(vehicles)} vehicles")
                if applied is not None:
                    applied(sent_t, held, vehicles)
            if tick == ticks:  # the last tick: what acts now is applied, nothing is flown
                break
            if wind is None:
                vehicles = [
                    step(v, c, s, limits, dt_s) for v, (c, s) in zip(vehicles, held, strict=False)
                ]
            else:
                w_e, w_n = wind(step_index)
                vehicles = [
                    step(
                        v,
                        heading_for_ground_course(c, v.speed_m_s, w_e, w_n),
                        s,
                        limits,
                        dt_s,
                        w_e,
                        w_n,
                    )
                    for v, (c, s) in zip(vehicles, held, strict=False)
                ]
            step_index += 1
            if stepped is not None:
                stepped(step_index, vehicles)
    return vehicles


def run_simulation(
    setup: SimulationSetup, states: Sequence[AgentState] | None = None
) -> SimulationResult:
    """Run ``setup`` to its duration and record every step.

    ``states`` are the agents' initial states (default ``AgentState()`` each). The target's state
    is taken from its path at each step's start; once the path has ended with the target at rest
    it is held (the path's own semantics), which keeps a long run cheap.
    """
    n = len(setup.starts)
    dt = setup.dt_s
    steps = round(setup.duration_s / dt)
    agents = setup.agents
    agent_states = list(states) if states is not None else [AgentState() for _ in range(n)]
    rows = steps + 1
    events: list[tuple[int, AgentEvent]] = []

    path = setup.target
    rest_after = path.duration_s
    end_state = path.state_at(rest_after)
    at_rest = end_state.v_east_m_s == 0.0 and end_state.v_north_m_s == 0.0
    rest_info = TargetInfo(end_state.east_m, end_state.north_m)
    team_phase = n > 1

    rec: list[float] = []  # per step: t, target east, north, then 8 values per vehicle

    def control(t: float, vehicles: Sequence[FixedWingState]) -> list[tuple[float, float]]:
        if at_rest and t >= rest_after:
            info = rest_info
        else:
            ts = path.state_at(t)
            info = TargetInfo(
                ts.east_m,
                ts.north_m,
                ts.v_east_m_s,
                ts.v_north_m_s,
                ts.a_east_m_s2,
                ts.a_north_m_s2,
            )
        team = tuple((v.east_m, v.north_m) for v in vehicles) if team_phase else ()
        rec.extend((t, info.east_m, info.north_m))
        commands = []
        for i, v in enumerate(vehicles):
            own = OwnTelemetry(v.east_m, v.north_m, v.course_rad, v.speed_m_s)
            state, command, evs = agent_step(
                agent_states[i], AgentInputs(t, own, info, team), agents[i]
            )
            agent_states[i] = state
            rec.extend(
                (
                    v.east_m,
                    v.north_m,
                    v.course_rad,
                    v.speed_m_s,
                    v.course_rate_rad_s,
                    v.accel_m_s2,
                    command.c,
                    1.0 if command.inverse else 0.0,
                )
            )
            if evs:
                events.extend((i, e) for e in evs)
            commands.append((command.course_rad, command.speed_m_s))
        return commands

    fly_team(setup.starts, setup.limits, dt, 1, steps, control)

    g = agents[0].guidance
    table = np.asarray(rec, dtype=np.float64).reshape(rows, 3 + 8 * n)
    per_vehicle = table[:, 3:].reshape(rows, n, 8)
    return SimulationResult(
        t_s=table[:, 0].copy(),
        east_m=per_vehicle[:, :, 0].copy(),
        north_m=per_vehicle[:, :, 1].copy(),
        course_rad=per_vehicle[:, :, 2].copy(),
        speed_m_s=per_vehicle[:, :, 3].copy(),
        course_rate_rad_s=per_vehicle[:, :, 4].copy(),
        accel_m_s2=per_vehicle[:, :, 5].copy(),
        c=per_vehicle[:, :, 6].copy(),
        inverse=per_vehicle[:, :, 7] > 0.5,
        target_east_m=table[:, 1].copy(),
        target_north_m=table[:, 2].copy(),
        radius_m=g.radius_m,
        orbit_sign=g.orbit_sign,
        events=tuple(events),
    )


# --------------------------------------------------------------------------------------------
# figures of merit


def settle_time_s(t_s: FloatArray, error: FloatArray, tolerance: float) -> float:
    """First time after which |error| < tolerance holds to the end of the run (inf if it does
    not hold at the end). ``error`` shape (m,) or (m, n) (then all columns must hold)."""
    bad: NDArray[np.bool_] = np.asarray(np.abs(error) >= tolerance)
    if bad.ndim == 2:
        bad = np.asarray(bad.any(axis=1))
    if bad[-1]:
        return math.inf
    idx = np.flatnonzero(bad)
    return float(t_s[0]) if idx.size == 0 else float(t_s[idx[-1] + 1])


def circle_crossings(error: FloatArray, depth_m: float = 0.5) -> int:
    """Times a vehicle enters the circle by more than ``depth_m`` after having been outside it
    (r - r_d >= 0). Summed over vehicles for shape (m, n)."""
    cols = error[:, None] if error.ndim == 1 else error
    total = 0
    for col in cols.T:
        outside = col[0] >= 0.0
        for value in col:
            if outside and value < -depth_m:
                total += 1
                outside = False
            elif not outside and value >= 0.0:
                outside = True
    return total


def phase_settle_time_s(
    t_s: FloatArray, phases_rad: FloatArray, tolerance_rad: float = math.radians(2.0)
) -> float:
    """First time after which every adjacent gap is within ``tolerance_rad`` of 2 pi / n."""
    n = phases_rad.shape[1]
    gaps = adjacent_phase_differences(phases_rad)
    return settle_time_s(t_s, gaps - TAU / n, tolerance_rad)


@dataclass(frozen=True, slots=True)
class StandoffFigures:
    """What ``standoff simulate`` prints for distance keeping, over all vehicles.

    ``settle_s``: time after which |r - r_d| < 3 m holds to the end (inf: never);
    ``min_distance_error_m``: smallest r - r_d (negative: inside the circle);
    ``crossings``: entries into the circle deeper than 0.5 m (``circle_crossings``);
    ``peak_course_rate_rad_s``: largest |course rate| flown.
    """

    settle_s: float
    min_distance_error_m: float
    crossings: int
    peak_course_rate_rad_s: float


def standoff_figures(
    result: SimulationResult, settle_tolerance_m: float = 3.0, crossing_depth_m: float = 0.5
) -> StandoffFigures:
    """The distance-keeping figures of a run (see ``StandoffFigures``)."""
    error = result.distance_error_m()
    return StandoffFigures(
        settle_s=settle_time_s(result.t_s, error, settle_tolerance_m),
        min_distance_error_m=float(error.min()),
        crossings=circle_crossings(error, crossing_depth_m),
        peak_course_rate_rad_s=float(np.abs(result.course_rate_rad_s).max()),
    )


@dataclass(frozen=True, slots=True)
class PhaseFigures:
    """Spacing figures: when every adjacent gap is within tolerance of 2 pi / n for good (s),
    and the speed range (m/s) and largest |acceleration| (m/s^2) flown."""

    settle_s: float
    min_speed_m_s: float
    max_speed_m_s: float
    max_abs_accel_m_s2: float


def phase_figures(
    result: SimulationResult, tolerance_rad: float = math.radians(2.0)
) -> PhaseFigures:
    """The phase-keeping figures of a run (see ``PhaseFigures``)."""
    return PhaseFigures(
        settle_s=phase_settle_time_s(result.t_s, result.phases_rad(), tolerance_rad),
        min_speed_m_s=float(result.speed_m_s.min()),
        max_speed_m_s=float(result.speed_m_s.max()),
        max_abs_accel_m_s2=float(np.abs(result.accel_m_s2).max()),
    )


def phase_lower_bound_s(setup: SimulationSetup, tolerance_rad: float = math.radians(2.0)) -> float:
    """Speed-limited lower bound on the spacing time of ``setup`` (any speed-based controller).

    Runs the team at cruise speed with no phase keeping for at least 400 s, takes each vehicle's
    phase at the end (all on the circle by then; phases at cruise keep their differences), asks
    ``phase.phase_time_lower_bound`` how soon speed changes within the limits could bring the
    offsets together. Speed changes made before a vehicle reaches the circle move its phase less
    than on the circle, and the path's shape is taken as the cruise path, so this is a lower bound
    up to that small approximation.
    """
    cruise_agents = tuple(replace(a, phase=replace(a.phase, law="none")) for a in setup.agents)
    # long enough for every vehicle to be on the circle; a coarse step is plenty for phases
    cruise = replace(
        setup,
        agents=cruise_agents,
        dt_s=max(setup.dt_s, 0.05),
        duration_s=max(setup.duration_s, 400.0),
    )
    result = run_simulation(cruise)
    phases = [float(p) for p in result.phases_rad()[-1]]
    order = orbit_order(phases)
    ref = phases[order[0]]
    n = len(phases)
    offsets = [(phases[i] - ref) % TAU - TAU * rank / n for rank, i in enumerate(order)]
    env = setup.agents[0].envelope
    return phase_time_lower_bound(
        offsets,
        setup.agents[0].guidance.radius_m,
        env.cruise_speed_m_s,
        env.min_speed_m_s,
        env.max_speed_m_s,
        env.max_accel_m_s2,
        tolerance_rad,
    )
