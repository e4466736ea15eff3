"""The mission in the wind, on the fast simulation: the plant holds its ground course as the
autopilots do; the agents fly out a steady wind to the circle and the air mass in track."""

import itertools
import math

import pytest

from app.compose.mission_fastsim import MissionSimSetup, run_mission_sim
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.config.simulator import WindModel
from app.core.plant import FixedWingState
from app.runtime.fastsim import fly_team


def _config(wind: WindModel, mode: str = "estimate") -> MissionConfig:
    config = load_config("hil", MissionConfig)
    sim = config.sim.model_copy(update={"wind": wind})
    guidance = config.guidance.model_copy(update={"wind": mode})
    return config.model_copy(update={"sim": sim, "guidance": guidance})


def test_in_a_cross_wind_the_plant_holds_the_commanded_ground_course_by_crabbing():
    limits = load_config("hil", MissionConfig).limits.build()
    start = FixedWingState(0.0, 0.0, 0.0, 14.0)  # heading north at 14 m/s through the air
    seen: list[FixedWingState] = []
    fly_team(
        [start],
        limits,
        0.02,
        5,
        300,  # 30 s
        lambda t, team: [(0.0, 14.0)],  # hold ground course north, airspeed 14
        stepped=lambda i, team: seen.append(team[0]),
        wind=lambda i: (5.0, 0.0),  # 5 m/s blowing east
    )
    end = seen[-1]
    crab = math.asin(-5.0 / 14.0)
    assert end.course_rad == pytest.approx(crab, abs=1e-3)  # heading into the wind
    late = seen[-1000]  # 20 s earlier: the crab was set up within the first seconds
    assert abs(end.east_m - late.east_m) < 0.05  # no drift across the course
    assert end.north_m - late.north_m == pytest.approx(20.0 * 14.0 * math.cos(crab), rel=1e-3)


@pytest.fixture(scope="module")
def steady():
    """Still air, and a steady 3 m/s wind toward 45 deg with the wind estimate and without,
    flown to the end of A-B (the target leaves A at 130 s and is at B by about 240 s)."""
    still = run_mission_sim(MissionSimSetup(build_plan(_config(WindModel())), end_t_s=240.0))
    wind = WindModel(speed_m_s=3.0, toward_deg=45.0)
    runs = {
        mode: run_mission_sim(MissionSimSetup(build_plan(_config(wind, mode)), end_t_s=240.0))
        for mode in ("estimate", "airspeed", "off")
    }
    return still, runs


@pytest.mark.slow
def test_in_a_steady_wind_the_team_forms_up_as_in_still_air(steady):
    """The airspeed commanded flies the phase law's ground speed (ahead of the speed loop's
    lag): formation as soon as in still air. Flying the ground speed as the airspeed (off),
    the phase rate swings with the wind round the circle and the team does not form before
    the target leaves."""
    still, runs = steady
    base = still.summary["convergence"]["time_to_formation_s"]
    assert base is not None
    formed = runs["estimate"].summary["convergence"]["time_to_formation_s"]
    assert formed is not None
    assert formed <= 1.2 * base
    off = runs["off"].summary["convergence"]["time_to_formation_s"]
    assert off is None or off > 120.0  # (the target leaves A 120 s after the command)
    winds = [e for e in runs["estimate"].events if e[1] == "wind_estimated"]
    assert len(winds) == 3  # each vehicle says so once
    assert all("3.0 m/s toward 45 deg" in e[2] for e in winds)


@pytest.mark.slow
def test_in_the_track_stage_guidance_in_the_air_mass_tracks_closer(steady):
    """Over A-B (7 m/s north) in a wind toward 45 deg, the guidance flown in the air mass
    (the target at 7 m/s north less the wind) keeps closer to the circle than the same
    guidance on the ground velocities with the airspeed converted (``airspeed``)."""
    _, runs = steady
    air = runs["estimate"].part("track:A-B")
    ground = runs["airspeed"].part("track:A-B")
    assert air is not None
    assert ground is not None
    assert air["distance_error_m"]["rms"] < 0.8 * ground["distance_error_m"]["rms"]
    # every command within the airframe's limits: airspeeds 10-18 m/s, finite courses
    commands = runs["estimate"].commands
    assert commands[:, 3].min() >= 10.0 - 1e-9
    assert commands[:, 3].max() <= 18.0 + 1e-9
    assert all(math.isfinite(v) for v in commands[:, 2])


@pytest.mark.slow
def test_the_orbit_flown_round_a_target_too_fast_for_the_circle_is_said(steady):
    """Over A-B the target (7 m/s) is too fast for the circle at these limits: each agent says
    it flies the nearest flyable orbit, over the ground in still air and through the air mass
    in the wind (where the target moves at 7 m/s north less the wind: 5.1 m/s here), and says
    it again only when the plan has moved (here at most every 20 s)."""
    still, runs = steady
    for result, frame in ((still, "over the ground"), (runs["estimate"], "through the air mass")):
        planned = [e for e in result.events if e[1] == "orbit_planned"]
        for vehicle in (1, 2, 3):
            said = [e for e in planned if e[2].startswith(f"vehicle {vehicle}:")]
            assert said, f"vehicle {vehicle} never said its planned orbit"
            assert any(frame in e[2] and "nearest flyable orbit" in e[2] for e in said)
            times = [e[0] for e in said]
            assert all(b - a >= 20.0 - 1e-9 for a, b in itertools.pairwise(times))
            assert len(said) <= 1 + (240.0 - 130.0) / 20.0
