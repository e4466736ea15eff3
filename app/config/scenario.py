"""Scenario files: ``standoff simulate``'s numerical experiments (``configs/sim-*.toml``,
``phase*.toml``) and ``standoff estimate``'s estimation scenarios (``configs/est-*.toml``).

A scenario names the standoff radius and orbit, the vehicles' limits and starts
(``LimitsConfig``, ``VehicleStartConfig``: metres east/north of the origin, course in degrees
clockwise from north), the target (``TargetConfig``), the guidance and phase laws, and the run's
step and duration. ``build_setup`` turns it into a ``SimulationSetup`` for the fast simulation.
"""

import math
from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from app.config.loading import load_config
from app.config.schema import (
    GuidanceConfig,
    LimitsConfig,
    PhaseConfig,
    Positive,
    StationaryTargetConfig,
    StrictModel,
    TargetConfig,
    VehicleStartConfig,
)
from app.core.agent import AgentParams, GuidanceParams
from app.runtime.fastsim import SimulationSetup
from sitl.fixes import ScenarioData, SensorSpec, generate


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

    @model_validator(mode="after")
    def _phase_band_fits(self) -> "ScenarioConfig":
        self.phase.check_band(self.radius_m)
        return self


def build_setup(scenario: ScenarioConfig) -> SimulationSetup:
    """The ``SimulationSetup`` a scenario describes (raises ValueError on inconsistent values)."""
    lim = scenario.limits
    envelope = lim.build()
    g = scenario.guidance
    guidance = GuidanceParams(
        radius_m=scenario.radius_m,
        orbit=scenario.orbit,
        law=g.law,
        c=g.c,
        feed_forward=g.feed_forward,
        curvature_margin=g.curvature_margin,
    )
    # the fast simulation flies the commanded speed: ``auto`` is ``speed``
    phase = scenario.phase.build(honours_speed=True)
    agents = tuple(
        AgentParams(index=i, envelope=envelope, guidance=guidance, phase=phase)
        for i in range(len(scenario.vehicles))
    )
    return SimulationSetup(
        starts=tuple(v.build() for v in scenario.vehicles),
        agents=agents,
        limits=envelope,
        target=scenario.target.build(dt_s=min(scenario.dt_s, 0.01)),
        dt_s=scenario.dt_s,
        duration_s=scenario.duration_s,
    )


class SensorsConfig(StrictModel):
    n_sensors: int = Field(default=3, ge=1)
    rate_hz: float = Field(default=10.0, gt=0.0, allow_inf_nan=False)
    sigma_m: float = Field(default=math.sqrt(10.0), gt=0.0, allow_inf_nan=False)
    stagger: bool = True

    def build(self) -> SensorSpec:
        return SensorSpec(self.n_sensors, self.rate_hz, self.sigma_m, self.stagger)


class EstimationScenarioConfig(StrictModel):
    """configs/est-*.toml: a target path and how the vehicles see it."""

    sensors: SensorsConfig = SensorsConfig()
    target: TargetConfig
    duration_s: float | None = Field(default=None, gt=0.0, allow_inf_nan=False)


def generate_scenario(name_or_path: str | Path, seed: int) -> ScenarioData:
    """Seeded data of a scenario config (``est-fig12``, ``est-fig12-sigma10``, ``est-hil``)."""
    scenario = load_config(name_or_path, EstimationScenarioConfig)
    path = scenario.target.build()
    return generate(path, scenario.sensors.build(), seed, scenario.duration_s)
