"""The mission-view port: what the ground station shows an observer (the live view) each tick."""

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class VehicleRow:
    """One vehicle: distance error (m), spacing error (deg), speed (m/s), link, in the team."""

    vehicle: int
    distance_error_m: float
    spacing_error_deg: float
    speed_m_s: float
    link: str
    active: bool


@dataclass(frozen=True, slots=True)
class MissionSnapshot:
    """The mission at ``t_s`` of ``end_t_s`` (mission time, s): stage, target segment, team."""

    t_s: float
    end_t_s: float
    stage: str
    target_segment: str
    vehicles: tuple[VehicleRow, ...]
