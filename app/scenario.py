"""Scenario files for ``standoff simulate``: validated TOML built on the shared config models.

A scenario names the standoff radius and orbit, the vehicles' limits and starts
(``LimitsConfig``, ``VehicleStartConfig``: metres east/north of the origin, course in degrees
clockwise from north), the target (``TargetConfig``), the guidance and phase laws, and the run's
step and duration. ``build_setup`` turns it into a ``SimulationSetup`` for the fast simulation.
"""

from typing import Literal

from pydantic import Field

from app.config_models import (
    LimitsConfig,
    Positive,
    StationaryTargetConfig,
    StrictModel,
    TargetConfig,
    VehicleStartConfig,
)
from app.core.agent import AgentParams, GuidanceParams, PhaseParams
from app.runtime.fastsim import SimulationSetup


class GuidanceConfig(StrictModel):
    """``law``: proposed (optimal c + ILVF), frew (c = 2) or fixed (needs ``c``)."""

    law: Literal["proposed", "frew", "fixed"] = "proposed"
    c: Positive | None = None
    feed_forward: bool = True
    curvature_margin: float = Field(default=1.0, gt=0.0, le=1.0)


class PhaseConfig(StrictModel):
    """``law``: paper (seat law, eq. 24-28), frew (neighbour law) or none; ``gain_per_s`` is k of
    eq. (24); ``predictive`` steers on the phase each vehicle will have on the circle."""

    law: Literal["paper", "frew", "none"] = "paper"
    gain_per_s: float = Field(default=0.05, ge=0.0, allow_inf_nan=False)
    predictive: bool = False


class ScenarioConfig(StrictModel):
    """One numerical experiment (paper section 5.1 and beyond)."""

    description: str = ""
    radius_m: Positive
    orbit: Literal["ccw", "cw"] = "ccw"
    dt_s: Positive = 0.01
    duration_s: Positive = 400.0
    limits: LimitsConfig
    guidance: GuidanceConfig = GuidanceConfig()
    phase: PhaseConfig = PhaseConfig()
    target: TargetConfig = StationaryTargetConfig(kind="stationary")
    vehicles: list[VehicleStartConfig] = Field(min_length=1)


def build_setup(scenario: ScenarioConfig) -> SimulationSetup:
    """The ``SimulationSetup`` a scenario describes (raises ValueError on inconsistent values)."""
    lim = scenario.limits
    envelope = lim.envelope()
    g = scenario.guidance
    guidance = GuidanceParams(
        radius_m=scenario.radius_m,
        orbit=scenario.orbit,
        law=g.law,
        c=g.c,
        feed_forward=g.feed_forward,
        curvature_margin=g.curvature_margin,
    )
    p = scenario.phase
    phase = PhaseParams(law=p.law, gain_per_s=p.gain_per_s, predictive=p.predictive)
    agents = tuple(
        AgentParams(index=i, envelope=envelope, guidance=guidance, phase=phase)
        for i in range(len(scenario.vehicles))
    )
    return SimulationSetup(
        starts=tuple(v.build() for v in scenario.vehicles),
        agents=agents,
        limits=lim.build(),
        target=scenario.target.build(dt_s=min(scenario.dt_s, 0.01)),
        dt_s=scenario.dt_s,
        duration_s=scenario.duration_s,
    )
