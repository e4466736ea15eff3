"""A ground target moving along a scripted path: timed manoeuvres or waypoint legs.

The path is integrated once, at construction, on a fine time grid; ``state_at(t)`` then
interpolates, so the target's state is a pure function of time (deterministic, any query order).
Course is clockwise from north (MAVLink); positions are metres east/north of the mission origin.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.core.frames import wrap_pi

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class TargetState:
    """Where the target is at ``t_s``, how fast it goes and how it accelerates (m, m/s, m/s^2)."""

    t_s: float
    east_m: float
    north_m: float
    v_east_m_s: float
    v_north_m_s: float
    a_east_m_s2: float
    a_north_m_s2: float

    @property
    def speed_m_s(self) -> float:
        return math.hypot(self.v_east_m_s, self.v_north_m_s)


@dataclass(frozen=True, slots=True)
class Maneuver:
    """A stretch of constant inputs: along-track acceleration and turn rate (clockwise > 0)."""

    duration_s: float
    accel_m_s2: float = 0.0
    turn_rate_rad_s: float = 0.0
    label: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.duration_s) and self.duration_s > 0.0):
            raise ValueError(f"maneuver duration_s must be finite and > 0, got {self.duration_s!r}")
        if not (math.isfinite(self.accel_m_s2) and math.isfinite(self.turn_rate_rad_s)):
            raise ValueError("maneuver accel_m_s2 and turn_rate_rad_s must be finite")


@dataclass(frozen=True, slots=True)
class Leg:
    """Drive in a straight line to a waypoint.

    The target turns sharply (at once) onto the leg. Along the leg its speed moves toward
    ``speed_m_s`` at ``accel_m_s2``; with ``speed_m_s=None`` it keeps accelerating at
    ``accel_m_s2`` up to ``max_speed_m_s``. With ``stop`` it brakes at ``brake_m_s2`` so as to
    stand still at the waypoint.
    """

    to_east_m: float
    to_north_m: float
    speed_m_s: float | None
    accel_m_s2: float = 1.0
    max_speed_m_s: float = 30.0
    stop: bool = False
    brake_m_s2: float = 3.0
    label: str = ""

    def __post_init__(self) -> None:
        values = (self.to_east_m, self.to_north_m, self.accel_m_s2, self.max_speed_m_s)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"leg {self.label!r}: coordinates and rates must be finite")
        if self.speed_m_s is not None and not (
            math.isfinite(self.speed_m_s) and 0.0 <= self.speed_m_s <= self.max_speed_m_s
        ):
            raise ValueError(f"leg {self.label!r}: speed_m_s must be in [0, max_speed_m_s]")
        if self.accel_m_s2 <= 0.0 or self.brake_m_s2 <= 0.0:
            raise ValueError(f"leg {self.label!r}: accel_m_s2 and brake_m_s2 must be > 0")


class TargetPath:
    """A target trajectory sampled on a fine grid; build it with ``from_maneuvers`` or
    ``from_waypoints``. Before the start the target stands at the first sample; after the end it
    stands at the last position (waypoint paths) or coasts on at its last velocity (manoeuvres).
    """

    __slots__ = ("_coast", "_dt", "_labels", "_segment", "_table")

    def __init__(
        self,
        table: FloatArray,
        segment: NDArray[np.int64],
        labels: Sequence[str],
        dt_s: float,
        coast: bool,
    ) -> None:
        if table.ndim != 2 or table.shape[1] != 6 or table.shape[0] < 2:
            raise ValueError("table must have shape (n >= 2, 6): east, north, ve, vn, ae, an")
        self._table = table.copy()
        self._table.setflags(write=False)
        self._segment = segment.copy()
        self._segment.setflags(write=False)
        self._labels = tuple(labels)
        self._dt = dt_s
        self._coast = coast

    @property
    def duration_s(self) -> float:
        """Time from the start of the path to its end."""
        return float(self._table.shape[0] - 1) * self._dt

    @property
    def labels(self) -> tuple[str, ...]:
        """The segment labels, in the order the path runs through them."""
        return self._labels

    def state_at(self, t_s: float) -> TargetState:
        """The target's state at time ``t_s`` (linear interpolation between fine samples)."""
        if not math.isfinite(t_s):
            raise ValueError(f"t_s must be finite, got {t_s!r}")
        last = self._table.shape[0] - 1
        if t_s >= self.duration_s:
            e, n, ve, vn, _, _ = (float(x) for x in self._table[last])
            extra = t_s - self.duration_s
            if self._coast:
                return TargetState(t_s, e + ve * extra, n + vn * extra, ve, vn, 0.0, 0.0)
            return TargetState(t_s, e, n, 0.0, 0.0, 0.0, 0.0)
        x = max(t_s, 0.0) / self._dt
        i = min(int(x), last - 1)
        w = x - i
        row = (1.0 - w) * self._table[i] + w * self._table[i + 1]
        return TargetState(t_s, *(float(v) for v in row))

    def segment_at(self, t_s: float) -> str:
        """Label of the segment the target is in at ``t_s`` (the last one after the end)."""
        i = int(min(max(t_s, 0.0) / self._dt, self._segment.shape[0] - 1))
        return self._labels[int(self._segment[i])]

    def sample(self, times_s: FloatArray) -> FloatArray:
        """States at many times at once: shape (len(times_s), 6): east, north, ve, vn, ae, an."""
        return np.array(
            [
                (s.east_m, s.north_m, s.v_east_m_s, s.v_north_m_s, s.a_east_m_s2, s.a_north_m_s2)
                for s in map(self.state_at, (float(t) for t in times_s))
            ],
            dtype=np.float64,
        ).reshape(-1, 6)

    @classmethod
    def from_maneuvers(
        cls,
        start_east_m: float,
        start_north_m: float,
        start_course_rad: float,
        start_speed_m_s: float,
        maneuvers: Sequence[Maneuver],
        dt_s: float = 0.01,
    ) -> "TargetPath":
        """Integrate timed manoeuvres from a start state (speed never drops below 0)."""
        if not maneuvers:
            raise ValueError("a manoeuvre path needs at least one manoeuvre")
        rows: list[tuple[float, float, float, float, float, float]] = []
        seg: list[int] = []
        east, north, course, speed = start_east_m, start_north_m, start_course_rad, start_speed_m_s
        for index, m in enumerate(maneuvers):
            steps = max(1, round(m.duration_s / dt_s))
            for _ in range(steps):
                accel = m.accel_m_s2 if speed > 0.0 or m.accel_m_s2 > 0.0 else 0.0
                rows.append(_row(east, north, course, speed, accel, m.turn_rate_rad_s))
                seg.append(index)
                new_speed = max(speed + accel * dt_s, 0.0)
                mean = 0.5 * (speed + new_speed)
                mid = course + 0.5 * m.turn_rate_rad_s * dt_s
                east += mean * math.sin(mid) * dt_s
                north += mean * math.cos(mid) * dt_s
                course = wrap_pi(course + m.turn_rate_rad_s * dt_s)
                speed = new_speed
        rows.append(_row(east, north, course, speed, 0.0, 0.0))
        seg.append(len(maneuvers) - 1)
        labels = [m.label or f"segment {i}" for i, m in enumerate(maneuvers)]
        return cls(np.array(rows), np.array(seg, dtype=np.int64), labels, dt_s, coast=True)

    @classmethod
    def from_waypoints(
        cls,
        start_east_m: float,
        start_north_m: float,
        legs: Sequence[Leg],
        wait_s: float = 0.0,
        dt_s: float = 0.01,
    ) -> "TargetPath":
        """Drive leg after leg from a standstill at the start, after waiting ``wait_s``.

        The first segment is labelled ``wait`` (present even when ``wait_s`` is 0); the legs are
        labelled by their ``label``.
        """
        if not legs:
            raise ValueError("a waypoint path needs at least one leg")
        if not (math.isfinite(wait_s) and wait_s >= 0.0):
            raise ValueError(f"wait_s must be finite and >= 0, got {wait_s!r}")
        rows: list[tuple[float, float, float, float, float, float]] = []
        seg: list[int] = []
        east, north, speed = start_east_m, start_north_m, 0.0
        first = legs[0]
        course = math.atan2(first.to_east_m - east, first.to_north_m - north)
        for _ in range(round(wait_s / dt_s)):
            rows.append(_row(east, north, course, 0.0, 0.0, 0.0))
            seg.append(0)
        for index, leg in enumerate(legs, start=1):
            d_east, d_north = leg.to_east_m - east, leg.to_north_m - north
            remaining = math.hypot(d_east, d_north)
            if remaining > 1e-9:
                course = math.atan2(d_east, d_north)
            while remaining > 1e-9:
                accel = _leg_accel(leg, speed, remaining, dt_s)
                rows.append(_row(east, north, course, speed, accel, 0.0))
                seg.append(index)
                new_speed = max(speed + accel * dt_s, 0.0)
                travel = 0.5 * (speed + new_speed) * dt_s
                if travel <= 0.0 and new_speed <= 0.0:
                    # braked to a halt a hair short of the waypoint: creep onto it
                    new_speed, travel = 0.0, remaining
                travel = min(travel, remaining)
                east += travel * math.sin(course)
                north += travel * math.cos(course)
                remaining -= travel
                speed = new_speed
            if leg.stop:
                speed = 0.0
        rows.append(_row(east, north, course, speed, 0.0, 0.0))
        seg.append(len(legs))
        labels = ["wait", *(leg.label or f"leg {i}" for i, leg in enumerate(legs, start=1))]
        return cls(np.array(rows), np.array(seg, dtype=np.int64), labels, dt_s, coast=False)


def _row(
    east: float, north: float, course: float, speed: float, accel: float, turn_rate: float
) -> tuple[float, float, float, float, float, float]:
    sin_c, cos_c = math.sin(course), math.cos(course)
    centripetal = speed * turn_rate  # toward the right of the track for a clockwise turn
    a_east = accel * sin_c + centripetal * cos_c
    a_north = accel * cos_c - centripetal * sin_c
    return east, north, speed * sin_c, speed * cos_c, a_east, a_north


def _leg_accel(leg: Leg, speed: float, remaining_m: float, dt_s: float) -> float:
    """Along-track acceleration on a leg: brake to stop at the waypoint, else seek the leg speed."""
    if (
        leg.stop
        and speed > 0.0
        and remaining_m <= speed * speed / (2.0 * leg.brake_m_s2) + speed * dt_s
    ):
        return -min(leg.brake_m_s2, speed / dt_s)
    if leg.speed_m_s is None:
        return min(leg.accel_m_s2, (leg.max_speed_m_s - speed) / dt_s)
    gap = leg.speed_m_s - speed
    return max(-leg.accel_m_s2, min(leg.accel_m_s2, gap / dt_s))
