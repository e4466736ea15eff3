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
  never climbed or descended into: the lower vehicle of the pair (within ``_TIE_M`` of one
  height, the one sent to the lower level, where both levels are known) climbs at most to
  ``min_distance_m + vertical_margin_m`` below the upper, the upper descends at most to as far
  above the lower, and neither moves toward the other if it is already closer. So a vehicle
  climbing to its place in the altitude stack waits below a teammate it would climb through
  until they are clear horizontally, and stacked vehicles (at least the minimum apart) keep
  their horizontal freedom.
- **A climb that parts the pair** (both heights, climb rates and levels known: the
  teammate's ``Traffic.climb_m_s`` and ``level_up_m``, the agent's own as arguments): where
  the upper vehicle of a pair less than ``min_distance_m`` apart climbs to a level above the
  lower one's, the prediction counts on ``climb_credit`` of that climb, up to its level, less
  whatever climb the lower one still has toward it (the band holds it, but an autopilot takes
  a moment to level off, and one that does not honour the height it is sent would not), and a
  step of the look-ahead is safe once the pair is ``min_distance_m`` apart vertically or
  ``guard`` apart in three dimensions. So a team that took off together and climbs to its
  altitude stack need not turn apart horizontally where the climb alone parts it in time (a
  turn costs a vehicle on its joining path: pushed 40 m off it, one planned a path 81 m
  longer, and its team formed 6 s late). A pair less than ``_TIE_M`` apart in height, or whose
  upper one does not climb to a level above the lower one's, is predicted at its heights of
  now, as before.

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
    climb_credit: float = 0.8

    def __post_init__(self) -> None:
        for name in ("min_distance_m", "look_ahead_s", "step_s", "course_step_rad", "max_age_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"separation {name} must be finite and > 0, got {value!r}")
        for name in ("margin_m", "vertical_margin_m", "hysteresis_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"separation {name} must be finite and >= 0, got {value!r}")
        if not (math.isfinite(self.climb_credit) and 0.0 <= self.climb_credit <= 1.0):
            raise ValueError(
                f"separation climb_credit must be in [0, 1], got {self.climb_credit!r}"
            )
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
    up about it (None: not known), course rad clockwise from north, ground speed m/s; its
    climb rate (m/s, up) and the height about the origin it climbs or descends to (its
    altitude setpoint), where its status says them."""

    vehicle: int
    east_m: float
    north_m: float
    up_m: float | None
    course_rad: float
    speed_m_s: float
    climb_m_s: float | None = None
    level_up_m: float | None = None


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


#: a pair closer than this in height (m) is told apart by the levels they go to (their views of
#: each other, a status apart, may not agree which is higher)
_TIE_M = 0.5


def _horizontal(east: FloatArray, north: FloatArray, t: FloatArray, other: Traffic) -> FloatArray:
    """Each own path's horizontal distance to ``other`` flying straight, at each step (k, s)."""
    oe = other.east_m + other.speed_m_s * math.sin(other.course_rad) * t
    on = other.north_m + other.speed_m_s * math.cos(other.course_rad) * t
    out: FloatArray = np.hypot(east - oe[None, :], north - on[None, :])
    return out


def _above(up_m: float, level_up_m: float | None, other: Traffic) -> bool:
    """Whether ``other`` is the upper one of the pair: the higher, or within ``_TIE_M`` the one
    sent higher (both agents tell a pair climbing side by side apart alike)."""
    assert other.up_m is not None
    dz = other.up_m - up_m
    other_level = other.level_up_m
    if (
        abs(dz) < _TIE_M
        and level_up_m is not None
        and other_level is not None
        and other_level != level_up_m
    ):
        return other_level > level_up_m
    return dz > 0.0


def _parting(
    up_m: float,
    climb_m_s: float | None,
    level_up_m: float | None,
    other: Traffic,
    t: FloatArray,
    params: SeparationParams,
) -> FloatArray | None:
    """The pair's height apart at each step (s,): the upper one climbing on to its level at
    ``climb_credit`` of its climb rate, the lower one at its whole climb rate toward the upper
    (held by the band, it soon has none) up to its own level, and no apart from a predicted
    crossing on; None where no climb parts them: heights, climb rates or levels unknown,
    heights within ``_TIE_M``, the upper one not climbing to a level above the lower's."""
    if other.up_m is None or level_up_m is None or other.level_up_m is None:
        return None
    if climb_m_s is None or other.climb_m_s is None:
        return None
    dz = other.up_m - up_m
    if abs(dz) < _TIE_M:
        return None
    own = (up_m, climb_m_s, level_up_m)
    them = (other.up_m, other.climb_m_s, other.level_up_m)
    (upper, up_climb, up_level), (lower, low_climb, low_level) = (
        (them, own) if dz > 0.0 else (own, them)
    )
    values = (up_climb, up_level, low_climb, low_level)
    if not all(math.isfinite(v) for v in values):
        return None
    if not (up_climb > 0.0 and up_level > upper and up_level > low_level):
        return None
    rise = np.minimum(params.climb_credit * up_climb * t, up_level - upper)
    chase = np.clip(low_climb * t, 0.0, max(low_level - lower, 0.0))
    apart = abs(dz) + rise - chase
    out: FloatArray = np.where(np.minimum.accumulate(apart) <= 0.0, 0.0, apart)
    return out


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
    climb_m_s: float | None = None,
    level_up_m: float | None = None,
) -> Resolution:
    """The course and the height band that keep the agent separated from ``traffic`` (see the
    module); the wanted course and no band when nothing is near. ``acted_on``: the teammates
    the tick before acted on (``Resolution.near``), held to the guard plus the hysteresis;
    ``climb_m_s`` and ``level_up_m``: the agent's own climb rate and the height it climbs to
    (a climb that parts a pair)."""
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
    offsets = _offsets(params)  # offsets[0] == 0: the wanted course first

    def paths(targets_rad: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        return _own_paths(
            east_m, north_m, course_rad, max(speed_m_s, 0.0), targets_rad, max_rate_rad_s, params
        )

    # the wanted course alone decides for a teammate that is far enough on it, or stacked
    # vertically apart (held so by the band); the other courses are flown out only for a
    # teammate that threatens (in a formed team of twenty on a 35 m altitude stack, its
    # neighbours in height are near, but never a threat)
    east_w, north_w, t = paths(wanted_course_rad + offsets[:1])
    every: tuple[FloatArray, FloatArray] | None = None
    horizontal = np.full(offsets.shape, math.inf)
    min_up = max_up = None
    threat: int | None = None
    closest = math.inf
    worst_on_wanted = math.inf
    acted: set[int] = set()
    for other in near:
        now = math.hypot(east_m - other.east_m, north_m - other.north_m)
        dz = 0.0 if other.up_m is None else other.up_m - up_m
        wanted = min(float(_horizontal(east_w, north_w, t, other).min()), now)
        closest = min(closest, math.hypot(wanted, dz))
        hysteresis = params.hysteresis_m if other.vehicle in acted_on else 0.0
        if wanted >= guard + hysteresis:
            continue
        acted.add(other.vehicle)
        # horizontally near on the wanted course: never climb or descend into it
        if other.up_m is not None:
            if _above(up_m, level_up_m, other):  # climb at most to ``keep`` below it
                cap = max(up_m, other.up_m - keep)
                max_up = cap if max_up is None else min(max_up, cap)
            else:
                floor = min(up_m, other.up_m + keep)
                min_up = floor if min_up is None else max(min_up, floor)
        if abs(dz) >= params.min_distance_m:
            continue  # vertically separated, and kept so by the band
        if every is None:
            east, north, _ = paths(wanted_course_rad + offsets)
            every = (east, north)
        apart = _horizontal(every[0], every[1], t, other)
        d = np.minimum(apart.min(axis=1), now)
        parting = _parting(up_m, climb_m_s, level_up_m, other, t, params)
        if parting is not None:
            # in three dimensions, each step safe once the climb has parted the pair
            spread = np.where(
                parting[None, :] >= params.min_distance_m, math.inf, np.hypot(apart, parting)
            )
            d = np.minimum(spread.min(axis=1), math.hypot(now, dz))
            wanted = float(d[0])
            if wanted >= guard + hysteresis:
                continue  # the climb parts them in time: the band alone
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
