"""The scripted target as the core sees it: its state at an instant and its path over time.

``sitl.target.TargetPath`` and its ``TargetState`` are what implement these; the core, the fast
simulation and the ground station's scoring only read them.
"""

from typing import Protocol


class TargetMotionState(Protocol):
    """The target at one instant (m, m/s, m/s^2)."""

    @property
    def east_m(self) -> float: ...
    @property
    def north_m(self) -> float: ...
    @property
    def v_east_m_s(self) -> float: ...
    @property
    def v_north_m_s(self) -> float: ...
    @property
    def a_east_m_s2(self) -> float: ...
    @property
    def a_north_m_s2(self) -> float: ...


class TargetMotion(Protocol):
    """A target's scripted path: its state at any time (after ``duration_s`` it keeps its last
    state) and the name of the segment it is on."""

    @property
    def duration_s(self) -> float: ...
    def state_at(self, t_s: float) -> TargetMotionState: ...
    def segment_at(self, t_s: float) -> str: ...
