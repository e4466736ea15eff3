"""Keeping the team apart while it forms up (issue #13, 2b): no two vehicles closer than a
stated distance, in three dimensions, at any time.

Two vehicles are separated when they are ``min_distance_m`` apart vertically or horizontally;
either is enough for a 3-D distance of at least that. Each agent, on every tick, looks
``look_ahead_s`` ahead along its teammates' last reported courses (straight, at their speed):

- **Horizontally**, a teammate less than ``min_distance_m`` above or below whose straight-line
  closest approach to the course the agent wants comes within ``min_distance_m + margin_m``
  is a threat. The agent then flies the course nearest to the wanted one (in steps of
  ``course_step_rad``, turning at its course-rate limit to get there) whose predicted closest
  approach keeps the guard, turning right at a tie (both vehicles of a head-on pair turn right
  and pass left to left, as on a runway's circuit); if no course keeps it, the course that
  passes farthest.
- **Vertically**, a teammate horizontally near (the same prediction, on the wanted course) is
  never climbed or descended into: the lower vehicle of the pair climbs at most to
  ``min_distance_m + vertical_margin_m`` below the upper, the upper descends at most to as far
  above the lower, and neither moves toward the other if it is already closer. So a vehicle
  climbing to its place in the altitude stack waits below a teammate it would climb through
  until they are clear horizontally, and stacked vehicles (at least the minimum apart) keep
  their horizontal freedom.

The teammates' positions are their agents' statuses (10 Hz on the bus); a teammate without an
altitude is taken to be at the agent's own. The agent's own altitude is needed: without it
(the 2-D fast simulation) nothing is resolved.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.core.frames import wrap_pi

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class SeparationParams:
    """See the module: the minimum distance (m), the horizontal margin the prediction keeps on
    top of it, the vertical margin of a held altitude, how much farther a teammate acted on
    the tick before must be predicted to pass for it to be let go (m: no flicker at the
    guard's edge), how far ahead (s, in steps of
    ``step_s``), the candidate courses (steps of ``course_step_rad`` up to ``max_offset_rad``
    either side of the wanted one), and how old a teammate's status may be (s)."""

    min_distance_m: float = 30.0
    margin_m: float = 15.0
    vertical_margin_m: float = 2.0
    hysteresis_m: float = 10.0
    look_ahead_s: float = 12.0
    step_s: float = 0.5
    course_step_rad: float = math.radians(15.0)
    max_offset_rad: float = math.radians(150.0)
    max_age_s: float = 3.0

    def __post_init__(self) -> None:
        for name in ("min_distance_m", "look_ahead_s", "step_s", "course_step_rad", "max_age_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"separation {name} must be finite and > 0, got {value!r}")
        for name in ("margin_m", "vertical_margin_m", "hysteresis_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"separation {name} must be finite and >= 0, got {value!r}")
        if not (math.isfinite(self.max_offset_rad) and 0.0 <= self.max_offset_rad <= math.pi):
            raise ValueError(
                f"separation max_offset_rad must be in [0, pi], got {self.max_offset_rad!r}"
            )

    @property
    def guard_m(self) -> float:
        return self.min_distance_m + self.margin_m


@dataclass(frozen=True, slots=True)
class Traffic:
    """A teammate where it is now (dead-reckoned to the tick): m east/north of the origin and
    up about it (None: not known), course rad clockwise from north, ground speed m/s."""

    vehicle: int
    east_m: float
    north_m: float
    up_m: float | None
    course_rad: float
    speed_m_s: float


@dataclass(frozen=True, slots=True)
class Resolution:
    """What the agent flies for separation: the course (the wanted one when nothing threatens),
    the band of heights (up about the origin) it may fly in (None: no bound), the teammate
    that set the course (None: none did), the least predicted closest approach (m, 3-D) on
    the wanted course (inf: no teammate near), and every teammate acted on (by course or
    height)."""

    course_rad: float
    min_up_m: float | None = None
    max_up_m: float | None = None
    threat: int | None = None
    closest_m: float = math.inf
    near: frozenset[int] = frozenset()

    @property
    def acted(self) -> bool:
        return self.threat is not None or self.min_up_m is not None or self.max_up_m is not None


def _offsets(params: SeparationParams) -> FloatArray:
    """0, +step, -step, +2 step, ... up to the largest offset: right (clockwise) first."""
    n = int(params.max_offset_rad / params.course_step_rad + 1e-9)
    out = [0.0]
    for k in range(1, n + 1):
        out += [k * params.course_step_rad, -k * params.course_step_rad]
    return np.asarray(out)


def _own_paths(
    east_m: float,
    north_m: float,
    course_rad: float,
    speed_m_s: float,
    targets_rad: FloatArray,
    max_rate_rad_s: float,
    params: SeparationParams,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Own positions (k courses, s steps) turning from ``course_rad`` toward each target course
    at the rate limit, then straight; and the times of the steps."""
    steps = np.arange(1, int(params.look_ahead_s / params.step_s) + 1, dtype=np.float64)
    t: FloatArray = steps * params.step_s
    turn = np.angle(np.exp(1j * (targets_rad - course_rad)))  # wrapped, (k,)
    swept = np.minimum(max_rate_rad_s * t[None, :], np.abs(turn)[:, None])
    heading = course_rad + np.sign(turn)[:, None] * swept  # (k, s), at each step's end
    # mid-step heading for the step's displacement
    mid = np.concatenate([np.full((heading.shape[0], 1), course_rad), heading[:, :-1]], axis=1)
    mid = 0.5 * (mid + heading)
    d = speed_m_s * params.step_s
    east = east_m + np.cumsum(d * np.sin(mid), axis=1)
    north = north_m + np.cumsum(d * np.cos(mid), axis=1)
    return east, north, t


def _closest(
    start: tuple[float, float], east: FloatArray, north: FloatArray, t: FloatArray, other: Traffic
) -> FloatArray:
    """Each own path's least horizontal distance to ``other`` flying straight (k,), from
    ``start``, where the paths begin."""
    oe = other.east_m + other.speed_m_s * math.sin(other.course_rad) * t
    on = other.north_m + other.speed_m_s * math.cos(other.course_rad) * t
    d: FloatArray = np.hypot(east - oe[None, :], north - on[None, :]).min(axis=1)
    now = math.hypot(start[0] - other.east_m, start[1] - other.north_m)
    return np.minimum(d, now)


def resolve(
    east_m: float,
    north_m: float,
    up_m: float | None,
    course_rad: float,
    speed_m_s: float,
    wanted_course_rad: float,
    traffic: Sequence[Traffic],
    max_rate_rad_s: float,
    params: SeparationParams,
    acted_on: frozenset[int] = frozenset(),
) -> Resolution:
    """The course and the height band that keep the agent separated from ``traffic`` (see the
    module); the wanted course and no band when nothing is near. ``acted_on``: the teammates
    the tick before acted on (``Resolution.near``), held to the guard plus the hysteresis."""
    if up_m is None or not traffic:
        return Resolution(wanted_course_rad)
    guard = params.guard_m
    keep = params.min_distance_m + params.vertical_margin_m
    # stacked at least ``keep`` apart: separated, and kept so (a climb toward the other is
    # held as soon as it is less than ``keep`` away); out of reach in the look-ahead: clear
    near = [
        t
        for t in traffic
        if (t.up_m is None or abs(t.up_m - up_m) < keep)
        and math.hypot(t.east_m - east_m, t.north_m - north_m)
        < guard + params.hysteresis_m + (speed_m_s + t.speed_m_s) * params.look_ahead_s
    ]
    if not near:
        return Resolution(wanted_course_rad)
    offsets = _offsets(params)
    east, north, t = _own_paths(
        east_m,
        north_m,
        course_rad,
        max(speed_m_s, 0.0),
        wanted_course_rad + offsets,
        max_rate_rad_s,
        params,
    )
    horizontal = np.full(offsets.shape, math.inf)
    min_up = max_up = None
    threat: int | None = None
    closest = math.inf
    worst_on_wanted = math.inf
    acted: set[int] = set()
    for other in near:
        d = _closest((east_m, north_m), east, north, t, other)
        dz = 0.0 if other.up_m is None else other.up_m - up_m
        wanted = float(d[0])
        closest = min(closest, math.hypot(wanted, dz))
        if wanted >= guard + (params.hysteresis_m if other.vehicle in acted_on else 0.0):
            continue
        acted.add(other.vehicle)
        # horizontally near on the wanted course: never climb or descend into it
        if other.up_m is not None:
            if dz > 0.0:  # it is above: climb at most to ``keep`` below it
                cap = max(up_m, other.up_m - keep)
                max_up = cap if max_up is None else min(max_up, cap)
            else:
                floor = min(up_m, other.up_m + keep)
                min_up = floor if min_up is None else max(min_up, floor)
        if abs(dz) >= params.min_distance_m:
            continue  # vertically separated, and kept so by the band
        horizontal = np.minimum(horizontal, d)
        if wanted < worst_on_wanted:
            worst_on_wanted, threat = wanted, other.vehicle
    near_ids = frozenset(acted)
    if threat is None:
        return Resolution(wanted_course_rad, min_up, max_up, None, closest, near_ids)
    clear = np.flatnonzero(horizontal >= guard)
    k = int(clear[0]) if clear.size else int(np.argmax(horizontal))
    course = wrap_pi(wanted_course_rad + float(offsets[k]))
    return Resolution(course, min_up, max_up, threat, closest, near_ids)
