"""Validated config pieces shared by several files: vehicle limits, starts, target paths, and the
guidance and phase laws.

Angles are degrees in files (as operators write them) and radians once built into core values.
"""

import math
from typing import Annotated, Literal, Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from app.core.agent import PhaseParams, resolve_actuator
from app.core.plant import FixedWingState, VehicleEnvelope
from sitl.target import Leg, Maneuver, TargetPath

Positive = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
MAX_LOCAL_M = 1.0e6
"""How far from the mission's origin a position in the local frame may be, m (1000 km: the
flat local frame means nothing further; the estimators refuse fixes beyond it too)."""
LocalPosition = Annotated[float, Field(ge=-MAX_LOCAL_M, le=MAX_LOCAL_M, allow_inf_nan=False)]
Speedup = Annotated[float, Field(gt=0.0, le=100.0, allow_inf_nan=False)]
"""Simulated seconds per host second: above 100 the 10 Hz telemetry and 50 Hz physics alone
ask for more than one core can give (the loops fall behind and the figures mean nothing)."""


class StrictModel(BaseModel):
    """Frozen, and refusing unknown keys so that a typo in a config file is an error."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class LimitsConfig(StrictModel):
    """A vehicle's envelope (Table 1 / Table 2 of the paper) and its autopilot loop gains."""

    cruise_speed_m_s: Positive
    min_speed_m_s: Positive
    max_speed_m_s: Positive
    max_accel_m_s2: Positive = 2.0
    max_course_rate_rad_s: Positive = 0.2
    course_gain_per_s: Positive = 1.0
    speed_gain_per_s: Positive = 1.0

    @model_validator(mode="after")
    def _speeds_ordered(self) -> Self:
        if not self.min_speed_m_s <= self.cruise_speed_m_s <= self.max_speed_m_s:
            raise ValueError(
                f"need min_speed_m_s <= cruise_speed_m_s <= max_speed_m_s, got "
                f"{self.min_speed_m_s}, {self.cruise_speed_m_s}, {self.max_speed_m_s}"
            )
        return self

    def build(self) -> VehicleEnvelope:
        """The one envelope type of the core and the simulator (``app.core.plant``)."""
        return VehicleEnvelope(
            cruise_speed_m_s=self.cruise_speed_m_s,
            min_speed_m_s=self.min_speed_m_s,
            max_speed_m_s=self.max_speed_m_s,
            max_accel_m_s2=self.max_accel_m_s2,
            max_course_rate_rad_s=self.max_course_rate_rad_s,
            course_gain_per_s=self.course_gain_per_s,
            speed_gain_per_s=self.speed_gain_per_s,
        )


class VehicleStartConfig(StrictModel):
    """Where a vehicle starts: metres east/north of the origin, course in degrees from north."""

    east_m: LocalPosition
    north_m: LocalPosition
    course_deg: Finite
    speed_m_s: Positive

    def build(self) -> FixedWingState:
        return FixedWingState(
            east_m=self.east_m,
            north_m=self.north_m,
            course_rad=math.radians(self.course_deg),
            speed_m_s=self.speed_m_s,
        )


class LegConfig(StrictModel):
    to_east_m: LocalPosition
    to_north_m: LocalPosition
    speed_m_s: NonNegative | None = None
    accel_m_s2: Positive = 1.0
    max_speed_m_s: Positive = 30.0
    stop: bool = False
    brake_m_s2: Positive = 3.0
    label: str = ""

    def build(self) -> Leg:
        return Leg(**self.model_dump())


class ManeuverConfig(StrictModel):
    duration_s: Positive
    accel_m_s2: Finite = 0.0
    turn_rate_deg_s: Finite = 0.0
    label: str = ""

    def build(self) -> Maneuver:
        return Maneuver(
            duration_s=self.duration_s,
            accel_m_s2=self.accel_m_s2,
            turn_rate_rad_s=math.radians(self.turn_rate_deg_s),
            label=self.label,
        )


class WaypointTargetConfig(StrictModel):
    """A target that waits at its start, then drives leg after leg (section 5.2's A-B-C-D)."""

    kind: Literal["waypoints"] = "waypoints"
    start_east_m: LocalPosition = 0.0
    start_north_m: LocalPosition = 0.0
    wait_s: NonNegative = 0.0
    legs: list[LegConfig] = Field(min_length=1)

    def build(self, dt_s: float = 0.01) -> TargetPath:
        return TargetPath.from_waypoints(
            self.start_east_m,
            self.start_north_m,
            [leg.build() for leg in self.legs],
            wait_s=self.wait_s,
            dt_s=dt_s,
        )


class ManeuverTargetConfig(StrictModel):
    """A target that runs timed manoeuvres from a start state (the Fig. 12-like path)."""

    kind: Literal["maneuvers"]
    start_east_m: LocalPosition = 0.0
    start_north_m: LocalPosition = 0.0
    start_course_deg: Finite = 0.0
    start_speed_m_s: NonNegative = 0.0
    maneuvers: list[ManeuverConfig] = Field(min_length=1)

    def build(self, dt_s: float = 0.01) -> TargetPath:
        return TargetPath.from_maneuvers(
            self.start_east_m,
            self.start_north_m,
            math.radians(self.start_course_deg),
            self.start_speed_m_s,
            [m.build() for m in self.maneuvers],
            dt_s=dt_s,
        )


class StationaryTargetConfig(StrictModel):
    """A target that stands still at a point."""

    kind: Literal["stationary"]
    east_m: LocalPosition = 0.0
    north_m: LocalPosition = 0.0

    def build(self, dt_s: float = 0.01) -> TargetPath:
        return TargetPath.from_maneuvers(self.east_m, self.north_m, 0.0, 0.0, [Maneuver(1.0)], dt_s)


TargetConfig = Annotated[
    WaypointTargetConfig | ManeuverTargetConfig | StationaryTargetConfig,
    Field(discriminator="kind"),
]


Fraction = Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)]


class GuidanceConfig(StrictModel):
    """The guidance law flown to the circle: ``proposed`` (optimal c + inverse field), ``frew``
    (c = 2) or ``fixed`` (needs ``c``); ``feed_forward`` adds the field's own course rate;
    ``curvature_margin`` is the share of the turn-rate limit the optimal c may use."""

    law: Literal["proposed", "frew", "fixed"] = "proposed"
    c: Positive | None = None
    feed_forward: bool = True
    curvature_margin: Fraction = 1.0

    @model_validator(mode="after")
    def _fixed_needs_c(self) -> Self:
        if self.law == "fixed" and self.c is None:
            raise ValueError("law 'fixed' needs c")
        return self


class PhaseConfig(StrictModel):
    """Phase keeping (eq. 24-28): ``law`` paper (seat law), frew (neighbour law) or none;
    ``gain_per_s`` is k of eq. (24); ``predictive`` steers on the phase each vehicle will have
    when it reaches the circle (an improvement; false: the paper's literal law).

    ``actuator``: how the law acts. ``speed`` commands the speed it wants; ``radius`` keeps
    cruise speed and flies the field around an effective radius within ``radius_band_m`` of
    ``radius_m`` (for autopilots that hold their own airspeed, e.g. PX4 fixed-wing offboard);
    ``auto`` (default) is ``speed`` where the vehicle honours a speed command and ``radius``
    where it does not (the fast simulation honours it: ``speed``)."""

    law: Literal["paper", "frew", "none"] = "paper"
    gain_per_s: NonNegative = 0.1
    predictive: bool = True
    actuator: Literal["auto", "speed", "radius"] = "auto"
    radius_band_m: Positive = 15.0
    radius_phase: Literal["orbit_time", "polar"] = "orbit_time"

    def build(self, honours_speed: bool = True) -> PhaseParams:
        """The core's phase parameters, ``auto`` resolved for a vehicle that does (default) or
        does not honour a speed command (``app.core.agent.resolve_actuator``)."""
        return PhaseParams(
            law=self.law,
            gain_per_s=self.gain_per_s,
            predictive=self.predictive,
            actuator=resolve_actuator(self.actuator, honours_speed),
            radius_band_m=self.radius_band_m,
            radius_phase=self.radius_phase,
        )

    def check_band(self, radius_m: float) -> None:
        """Raise ValueError when the radius actuator could be flown (``auto`` or ``radius``)
        with a band that does not fit inside the standoff radius."""
        if self.actuator != "speed" and self.radius_band_m >= radius_m:
            raise ValueError(
                f"phase.radius_band_m ({self.radius_band_m} m) must be smaller than radius_m "
                f"({radius_m} m) when phase.actuator is {self.actuator!r}"
            )
