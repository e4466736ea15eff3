"""The phase actuator in mission and scenario files: ``phase.actuator`` auto|speed|radius and
``phase.radius_band_m``, and the fast simulation flying the radius actuator."""

import math

import numpy as np
import pytest

from app.config import load_config, validate_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.config.scenario import ScenarioConfig, build_setup
from app.config.schema import PhaseConfig
from app.core.mission.stage import adjacent_phase_differences
from app.errors import ConfigError
from app.runtime.fastsim import run_simulation

MISSIONS = ("hil", "px4-sitl", "ardupilot-sitl", "phase-mission")
SCENARIOS = ("sim-a", "sim-b", "phase", "phase-gather")
BASE = load_config("hil", MissionConfig).model_dump()


@pytest.mark.parametrize("name", MISSIONS)
def test_shipped_missions_ask_for_auto_and_the_plan_flies_speed(name):
    plan = build_plan(load_config(name, MissionConfig))
    assert plan.phase_actuator == "auto"
    for agent in plan.agents:
        assert agent.agent.phase.actuator == "speed"
        assert agent.track is not None
        assert agent.track.phase.actuator == "speed"


@pytest.mark.parametrize("name", SCENARIOS)
def test_shipped_scenarios_fly_speed(name):
    setup = build_setup(load_config(name, ScenarioConfig))
    assert all(a.phase.actuator == "speed" for a in setup.agents)


def test_auto_resolves_per_vehicle_and_the_band_reaches_the_core():
    phase = PhaseConfig(actuator="auto", radius_band_m=12.0)
    assert phase.build(honours_speed=True).actuator == "speed"
    built = phase.build(honours_speed=False)
    assert (built.actuator, built.radius_band_m) == ("radius", 12.0)
    assert PhaseConfig(actuator="speed").build(honours_speed=False).actuator == "speed"
    assert PhaseConfig(actuator="radius").build(honours_speed=True).actuator == "radius"


def test_a_radius_mission_flies_radius_in_every_stage_but_standby():
    config = validate_config(
        {**BASE, "phase": {"actuator": "radius", "radius_band_m": 10.0}},
        MissionConfig,
        source="m.toml",
    )
    plan = build_plan(config)
    assert plan.phase_actuator == "radius"
    for agent in plan.agents:
        assert agent.agent.phase.actuator == "radius"
        assert agent.agent.phase.radius_band_m == 10.0
        assert agent.track is not None
        assert agent.track.phase.actuator == "radius"
        assert agent.standby.phase.law == "none"


@pytest.mark.parametrize(
    ("phase", "needle"),
    [
        ({"actuator": "throttle"}, "phase.actuator"),
        ({"radius_band_m": 0.0}, "phase.radius_band_m"),
        ({"radius_band_m": math.nan}, "phase.radius_band_m"),
        ({"actuator": "radius", "radius_band_m": 90.0}, "radius_band_m"),
        ({"actuator": "auto", "radius_band_m": 120.0}, "radius_band_m"),
    ],
)
def test_bad_phase_actuator_settings_are_refused_with_the_field(phase, needle):
    with pytest.raises(ConfigError, match=needle):
        validate_config({**BASE, "phase": phase}, MissionConfig, source="m.toml")


def test_a_speed_mission_may_have_any_band():
    config = validate_config(
        {**BASE, "phase": {"actuator": "speed", "radius_band_m": 500.0}},
        MissionConfig,
        source="m.toml",
    )
    build_plan(config)


def test_a_scenario_refuses_a_band_wider_than_its_circle():
    data = load_config("phase-radius", ScenarioConfig).model_dump()
    data["phase"]["radius_band_m"] = 95.0
    with pytest.raises(ConfigError, match="radius_band_m"):
        validate_config(data, ScenarioConfig, source="s.toml")


# ---------------------------------------------------------------- the fast simulation


def _fly(law: str, duration_s: float):
    scenario = load_config("phase-radius", ScenarioConfig)
    assert scenario.phase.actuator == "radius"
    phase = scenario.phase.model_copy(update={"law": law})
    setup = build_setup(scenario.model_copy(update={"phase": phase, "duration_s": duration_s}))
    assert all(a.phase.actuator == "radius" for a in setup.agents)
    return run_simulation(setup)


@pytest.mark.slow
def test_the_radius_actuator_spaces_a_bunched_team_at_cruise_speed():
    result = _fly("paper", 200.0)
    # the speed never left cruise: the radius did the spacing
    assert np.all(result.speed_m_s == pytest.approx(14.0))
    late = result.t_s >= 150.0
    gaps = np.degrees(adjacent_phase_differences(result.phases_rad()))
    assert np.all(np.abs(gaps[late] - 120.0) < 5.0)
    # and back on the circle r_d
    assert np.all(np.abs(result.distance_error_m()[late]) < 3.0)
    # it used the band, and no more
    error = result.distance_error_m()
    assert error.max() > 10.0
    assert error.min() > -15.5
    assert np.abs(result.course_rate_rad_s).max() <= 0.2 + 1e-9


@pytest.mark.slow
def test_without_phase_keeping_the_same_start_stays_bunched():
    result = _fly("none", 100.0)
    gaps = np.degrees(adjacent_phase_differences(result.phases_rad()))
    assert np.abs(gaps[-1] - 120.0).max() > 90.0
    assert np.abs(result.distance_error_m()[-1]).max() < 3.0
