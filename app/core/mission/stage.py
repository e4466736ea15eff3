"""Mission stages (standby -> gather -> adjust -> track) and the team-spacing figures they use.

The ground station drives ``next_stage`` once per tick with what it knows of the team: each
active vehicle's distance to the standoff circle and polar angle about the estimated target.
Pure: time is an argument, the state is a frozen value.
"""

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from numpy.typing import NDArray

from app.core.frames import TAU
from app.core.values import replace


class Stage(StrEnum):
    """Where the mission is. ``standby``: loitering until the tracking command."""

    STANDBY = "standby"
    GATHER = "gather"
    ADJUST = "adjust"
    TRACK = "track"


def adjacent_phase_gaps(polar_angles_rad: Sequence[float]) -> list[float]:
    """Angular gaps between neighbours around the circle, counter-clockwise, in [0, 2 pi).

    The gaps sum to 2 pi for two or more vehicles; a lone vehicle has one gap of 2 pi.
    """
    if not polar_angles_rad:
        return []
    ordered = sorted(a % TAU for a in polar_angles_rad)
    gaps = [b - a for a, b in itertools.pairwise(ordered)]
    gaps.append(ordered[0] + TAU - ordered[-1])
    return gaps


def spacing_errors(polar_angles_rad: Sequence[float]) -> list[float]:
    """Each adjacent gap minus the desired 2 pi / n (radians, signed)."""
    n = len(polar_angles_rad)
    if n == 0:
        return []
    return [gap - TAU / n for gap in adjacent_phase_gaps(polar_angles_rad)]


def vehicle_spacing_errors(polar_angles_rad: Mapping[int, float]) -> dict[int, float]:
    """``spacing_errors`` by vehicle: each one's counter-clockwise gap to its neighbour minus
    2 pi / n (radians, signed); empty for fewer than two vehicles."""
    if len(polar_angles_rad) < 2:
        return {}
    ordered = sorted((a % TAU, v) for v, a in polar_angles_rad.items())
    errors = spacing_errors([a for a, _ in ordered])
    return {v: e for (_, v), e in zip(ordered, errors, strict=True)}


def adjacent_phase_differences(phases_rad: NDArray[np.float64]) -> NDArray[np.float64]:
    """For each sample, the n gaps (rad, in [0, 2 pi)) between each vehicle and the next one
    ahead along the orbit, in orbit order starting from the vehicle at rank 0; shape (m, n)."""
    sorted_rel = np.sort((phases_rad - phases_rad[:, :1]) % TAU, axis=1)
    ahead = np.roll(sorted_rel, -1, axis=1)
    ahead[:, -1] += TAU
    return ahead - sorted_rel


@dataclass(frozen=True, slots=True)
class StageParams:
    """When to move on.

    gather -> adjust once every active vehicle is within ``arrive_tolerance_m`` of the circle,
    or gather -> track once the target has been seen moving faster than ``moving_speed_m_s``
    for ``dwell_s`` (a team still gathering when the target leaves, e.g. a large one still
    climbing to its altitude stack, flies the track stage's guidance for a moving target
    rather than the stationary-target approach; the dwell keeps one noisy estimate early in
    gather from starting it). adjust -> track once every vehicle is within
    ``radius_tolerance_m`` and every adjacent gap within ``spacing_tolerance_rad`` of 2 pi / n
    for ``dwell_s``, or as soon as the target is seen moving faster than ``moving_speed_m_s``
    (tracking a moving target cannot wait).
    """

    arrive_tolerance_m: float = 15.0
    radius_tolerance_m: float = 3.0
    spacing_tolerance_rad: float = math.radians(2.0)
    dwell_s: float = 5.0
    moving_speed_m_s: float = 1.5

    def __post_init__(self) -> None:
        for name in (
            "arrive_tolerance_m",
            "radius_tolerance_m",
            "spacing_tolerance_rad",
            "moving_speed_m_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if not (math.isfinite(self.dwell_s) and self.dwell_s >= 0.0):
            raise ValueError(f"dwell_s must be finite and >= 0, got {self.dwell_s!r}")


@dataclass(frozen=True, slots=True)
class StageState:
    """The current stage, when it began, since when the team has been in formation, and since
    when the target has been seen moving (None: not now)."""

    stage: Stage = Stage.STANDBY
    since_t_s: float = 0.0
    formed_since_t_s: float | None = None
    moving_since_t_s: float | None = None


@dataclass(frozen=True, slots=True)
class TeamView:
    """What the ground station knows of the active team at one instant."""

    distance_errors_m: tuple[float, ...]
    polar_angles_rad: tuple[float, ...]
    target_speed_m_s: float

    def in_formation(self, params: StageParams) -> bool:
        """Every vehicle near the circle and every adjacent gap near 2 pi / n."""
        if not self.distance_errors_m:
            return False
        near = all(abs(e) <= params.radius_tolerance_m for e in self.distance_errors_m)
        spaced = all(
            abs(e) <= params.spacing_tolerance_rad for e in spacing_errors(self.polar_angles_rad)
        )
        return near and spaced


def next_stage(
    state: StageState,
    t_s: float,
    tracking_commanded: bool,
    team: TeamView,
    params: StageParams,
) -> StageState:
    """Advance the stage machine to time ``t_s``; stages only move forward."""
    if state.stage is Stage.STANDBY:
        if tracking_commanded:
            return StageState(Stage.GATHER, t_s)
        return state
    formed = team.in_formation(params)
    formed_since = _since(state.formed_since_t_s, t_s) if formed else None
    moving = team.target_speed_m_s > params.moving_speed_m_s
    moving_since = _since(state.moving_since_t_s, t_s) if moving else None
    state = replace(state, formed_since_t_s=formed_since, moving_since_t_s=moving_since)
    if state.stage is Stage.GATHER:
        arrived = bool(team.distance_errors_m) and all(
            abs(e) <= params.arrive_tolerance_m for e in team.distance_errors_m
        )
        if arrived:
            return StageState(Stage.ADJUST, t_s, formed_since, moving_since)
        if moving_since is not None and t_s - moving_since >= params.dwell_s:
            return StageState(Stage.TRACK, t_s, formed_since, moving_since)
        return state
    if state.stage is Stage.ADJUST:
        dwelt = formed_since is not None and t_s - formed_since >= params.dwell_s
        if dwelt or moving:
            return StageState(Stage.TRACK, t_s, formed_since, moving_since)
    return state


def _since(since_t_s: float | None, t_s: float) -> float:
    return since_t_s if since_t_s is not None else t_s
