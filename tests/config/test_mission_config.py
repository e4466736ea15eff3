import dataclasses
import math

import pytest
from pydantic import ValidationError

from app.config import load_config, validate_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan, sim_config
from app.errors import ConfigError
from sitl.config import SimConfig

MISSIONS = ("hil", "px4-sitl", "ardupilot-sitl", "phase-mission")


@pytest.mark.parametrize("name", MISSIONS)
def test_shipped_missions_validate_and_build(name):
    config = load_config(name, MissionConfig)
    plan = build_plan(config)
    assert plan.count == config.vehicles == 3
    assert plan.end_t_s > config.tracking_command_s
    for i, agent in enumerate(plan.agents):
        assert agent.vehicle == i
        assert agent.agent.guidance.radius_m == config.radius_m
        assert agent.track is not None
        assert not agent.track.guidance.uses_inverse_field


def test_the_default_mission_is_the_papers_section_5_2():
    config = load_config("hil", MissionConfig)
    assert (config.radius_m, config.limits.cruise_speed_m_s) == (90.0, 14.0)
    assert (config.limits.min_speed_m_s, config.limits.max_speed_m_s) == (10.0, 18.0)
    plan = build_plan(config)
    assert plan.target.labels == ("wait", "A-B", "B-C", "C-D")
    times: dict[str, list[float]] = {label: [] for label in plan.target.labels}
    t = 0.0
    while t < plan.target.duration_s:
        times[plan.target.segment_at(t)].append(t)
        t += 0.5
    for label, speed in (("A-B", 7.0), ("B-C", 3.0)):
        middle = times[label][len(times[label]) // 2]
        assert plan.target.state_at(middle).speed_m_s == pytest.approx(speed)
    assert plan.target.state_at(plan.target.duration_s + 1.0).speed_m_s == 0.0  # stopped at D
    standby = math.hypot(config.standby.east_m, config.standby.north_m)
    assert standby == pytest.approx(1000.0)  # the team loiters 1 km from A


def test_the_simulator_launches_the_team_on_the_standby_circle():
    plan = build_plan(load_config("hil", MissionConfig))
    sim = sim_config(plan, base_port=30000)
    assert len(sim.vehicles) == 3
    for v in sim.vehicles:
        r = math.hypot(v.start.east_m + 1000.0, v.start.north_m)
        assert r == pytest.approx(150.0)
    assert sim.target is plan.target


def test_the_team_can_start_from_homes_near_the_origin_as_sitl_instances_do():
    raw = load_config("ardupilot-sitl", MissionConfig).model_dump()
    raw["sim"] |= {"start": "home", "home_spacing_m": 50.0}
    sim = sim_config(build_plan(MissionConfig.model_validate(raw)), base_port=30000)
    assert [(v.start.east_m, v.start.north_m, v.start.course_rad) for v in sim.vehicles] == [
        (0.0, 0.0, 0.0),
        (50.0, 0.0, 0.0),
        (100.0, 0.0, 0.0),
    ]
    raw["sim"]["start"] = "runway"
    with pytest.raises(ValidationError, match="start"):
        MissionConfig.model_validate(raw)


PERSONALITY = (
    "boot_spacing_s",
    "takeoff",
    "px4_offboard_speed",
    "px4_trim_airspeed_m_s",
    "px4_curvature_sign",
    "px4_roll_limit_deg",
    "arduplane_stream_rate_hz",
    "arduplane_guided_heading",
    "arduplane_turn_efficiency",
    "arduplane_speed_time_constant_s",
    "arduplane_gcs_seen_at_boot",
    "arduplane_guided_rebase",
)


def test_the_sim_table_defaults_to_the_simulators_real_autopilot_behaviour():
    # a mission file that says nothing flies the personalities as SimConfig defines them
    plan = build_plan(load_config("hil", MissionConfig))
    sim = sim_config(plan, base_port=30000)
    defaults = {f.name: f.default for f in dataclasses.fields(SimConfig)}
    for name in PERSONALITY:
        assert getattr(sim, name) == defaults[name], name


def test_every_personality_option_is_a_sim_key():
    changed = {
        "boot_spacing_s": 0.0,
        "takeoff": "launch",
        "px4_offboard_speed": "setpoint",
        "px4_trim_airspeed_m_s": 16.0,
        "px4_curvature_sign": "ned",
        "px4_roll_limit_deg": None,
        "arduplane_stream_rate_hz": 4.0,
        "arduplane_guided_heading": "ideal",
        "arduplane_turn_efficiency": 0.9,
        "arduplane_speed_time_constant_s": 0.0,
        "arduplane_gcs_seen_at_boot": False,
        "arduplane_guided_rebase": False,
    }
    assert set(changed) == set(PERSONALITY)
    raw = load_config("hil", MissionConfig).model_dump()
    raw["sim"] |= changed
    sim = sim_config(build_plan(MissionConfig.model_validate(raw)), base_port=30000)
    assert {name: getattr(sim, name) for name in PERSONALITY} == changed


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("takeoff", "catapult"),
        ("arduplane_turn_efficiency", 1.5),
        ("arduplane_turn_efficiency", 0.0),
        ("boot_spacing_s", -1.0),
        ("px4_offboard_speed", "fast"),
        ("px4_roll_limit_deg", 90.0),
    ],
)
def test_a_bad_personality_key_is_refused_by_name(key, value):
    raw = load_config("hil", MissionConfig).model_dump()
    raw["sim"][key] = value
    with pytest.raises(ValidationError, match=key):
        MissionConfig.model_validate(raw)


BASE = load_config("hil", MissionConfig).model_dump()


@pytest.mark.parametrize(
    ("patch", "needle"),
    [
        ({"standby": {"east_m": 0.0, "north_m": 0.0, "radius_m": 20.0}}, "standby.radius_m"),
        ({"guidance": {"law": "fixed"}}, "needs c"),
        ({"observations": {"source": "replay"}}, "replay_file"),
        ({"vehicles": 0}, "vehicles"),
        ({"radius_m": -5.0}, "radius_m"),
        ({"colour": "red"}, "colour"),
        ({"link": {"autopilot": "betaflight"}}, "link.autopilot"),
        ({"estimator": {"allocation_period_s": 0.0}}, "estimator.allocation_period_s"),
    ],
)
def test_bad_missions_are_refused_with_the_field(patch, needle):
    with pytest.raises(ConfigError, match=needle):
        validate_config({**BASE, **patch}, MissionConfig, source="m.toml")


def test_track_stage_settings_reach_only_the_track_parameters():
    base = load_config("hil", MissionConfig)
    config = base.model_copy(
        update={
            "phase": base.phase.model_copy(update={"track_gain_per_s": 0.3}),
            "guidance": base.guidance.model_copy(
                update={"track_speed_cap": True, "latency_s": 0.08, "hold_s": 0.2}
            ),
        }
    )
    for agent in build_plan(config).agents:
        assert agent.track is not None
        assert agent.track.phase.gain_per_s == 0.3
        assert agent.agent.phase.gain_per_s == config.phase.gain_per_s
        assert agent.track.guidance.speed_cap
        assert not agent.agent.guidance.speed_cap
        assert (agent.latency_s, agent.hold_s) == (0.08, 0.2)


def test_the_track_stages_c_is_its_own_and_a_fixed_track_law_needs_one():
    base = load_config("hil", MissionConfig)
    assert (base.guidance.track_law, base.guidance.track_c) == ("fixed", 1.2)
    for agent in build_plan(base).agents:
        assert agent.track is not None
        assert (agent.track.guidance.law, agent.track.guidance.c) == ("fixed", 1.2)
        # the approach keeps its own law (the optimal c)
        assert (agent.agent.guidance.law, agent.agent.guidance.c) == ("proposed", None)
    frew = base.guidance.model_copy(update={"track_law": "frew"})
    track = build_plan(base.model_copy(update={"guidance": frew})).agents[0].track
    assert track is not None
    assert track.guidance.law == "frew"
    guidance = {**BASE["guidance"], "track_c": None}
    with pytest.raises(ConfigError, match="track_law 'fixed' needs track_c"):
        validate_config({**BASE, "guidance": guidance}, MissionConfig, source="m.toml")
    with pytest.raises(ConfigError, match=r"guidance\.track_c"):
        validate_config(
            {**BASE, "guidance": {**guidance, "track_c": -1.0}}, MissionConfig, source="m.toml"
        )
    # without track_c, a fixed track law flies the approach's c
    fixed = {**guidance, "law": "fixed", "c": 3.0}
    config = validate_config({**BASE, "guidance": fixed}, MissionConfig, source="m.toml")
    track = build_plan(config).agents[0].track
    assert track is not None
    assert track.guidance.c == 3.0


def test_the_receding_horizon_planner_is_a_track_stage_setting():
    base = load_config("hil", MissionConfig)
    for agent in build_plan(base).agents:
        assert agent.track is not None
        assert agent.track.guidance.planner == "field"
    guidance = base.guidance.model_copy(
        update={
            "track_planner": "horizon",
            "track_horizon_s": 30.0,
            "track_block_s": 1.5,
            "track_replan_s": 1.0,
            "track_joint_max_vehicles": 8,
        }
    )
    for agent in build_plan(base.model_copy(update={"guidance": guidance})).agents:
        assert agent.track is not None
        assert agent.track.guidance.planner == "horizon"
        assert agent.track.guidance.horizon.horizon_s == 30.0
        assert agent.track.guidance.horizon.replan_s == 1.0
        assert agent.track.guidance.horizon.block_s == 1.5
        assert agent.track.guidance.horizon.joint_max_vehicles == 8
        assert agent.agent.guidance.planner == "field"
    for key, value in (
        ("track_planner", "mpc"),
        ("track_horizon_s", 31.2),
        ("track_block_s", 0.7),
        ("track_joint_max_vehicles", 1),
    ):
        raw = {**BASE, "guidance": {**BASE["guidance"], key: value}}
        with pytest.raises(ConfigError, match=f"guidance.{key}"):
            validate_config(raw, MissionConfig, source="m.toml")
    # the horizon a whole number of blocks
    raw = {
        **BASE,
        "guidance": {**BASE["guidance"], "track_horizon_s": 31.0, "track_block_s": 2.0},
    }
    with pytest.raises(ConfigError, match="whole number of track_block_s"):
        validate_config(raw, MissionConfig, source="m.toml")


def test_the_slow_turn_is_a_track_stage_setting_in_degrees() -> None:
    raw = {**BASE, "guidance": {**BASE["guidance"], "track_turn_slow_deg": [20.0, 40.0]}}
    config = validate_config(raw, MissionConfig, source="m.toml")
    for agent in build_plan(config).agents:
        assert agent.track is not None
        start, full = agent.track.guidance.turn_slow_rad or (0.0, 0.0)
        assert (start, full) == pytest.approx((math.radians(20.0), math.radians(40.0)))
        assert agent.agent.guidance.turn_slow_rad is None
    for value in ([40.0, 20.0], [20.0, 200.0], [-5.0, 20.0], [20.0]):
        raw = {**BASE, "guidance": {**BASE["guidance"], "track_turn_slow_deg": value}}
        with pytest.raises(ConfigError, match=r"guidance\.track_turn_slow_deg"):
            validate_config(raw, MissionConfig, source="m.toml")


def test_the_gather_lead_speed_reaches_gather_and_adjust_only_and_stays_in_the_envelope() -> None:
    for agent in build_plan(load_config("hil", MissionConfig)).agents:
        assert agent.agent.phase.lead_speed_m_s == 18.0  # the default mission's file
    unset = {k: v for k, v in BASE["phase"].items() if k != "gather_lead_speed_m_s"}
    for agent in build_plan(validate_config({**BASE, "phase": unset}, MissionConfig)).agents:
        assert agent.agent.phase.lead_speed_m_s is None  # off where the file does not set it
    raw = {**BASE, "phase": {**BASE["phase"], "gather_lead_speed_m_s": 17.0}}
    for agent in build_plan(validate_config(raw, MissionConfig, source="m.toml")).agents:
        assert agent.agent.phase.lead_speed_m_s == 17.0
        assert agent.track is not None
        assert agent.track.phase.lead_speed_m_s is None
        assert agent.track.phase.gain_per_s == BASE["phase"]["track_gain_per_s"]
    raw = {**BASE, "phase": {**BASE["phase"], "gather_lead_speed_m_s": 19.0}}
    with pytest.raises(ConfigError, match="gather_lead_speed_m_s"):
        validate_config(raw, MissionConfig, source="m.toml")


def test_the_adjust_lead_turn_share_reaches_the_agents_and_is_a_fraction() -> None:
    for agent in build_plan(load_config("hil", MissionConfig)).agents:
        assert agent.agent.phase.held_lead_turn_share == 0.9  # the default
    raw = {**BASE, "phase": {**BASE["phase"], "adjust_lead_turn_share": 0.8}}
    for agent in build_plan(validate_config(raw, MissionConfig, source="m.toml")).agents:
        assert agent.agent.phase.held_lead_turn_share == 0.8
    for bad in (0.0, 1.2, "nan"):
        raw = {**BASE, "phase": {**BASE["phase"], "adjust_lead_turn_share": bad}}
        with pytest.raises(ConfigError, match="adjust_lead_turn_share"):
            validate_config(raw, MissionConfig, source="m.toml")


def test_the_ground_fuses_and_allocates_at_the_missions_periods():
    default = build_plan(load_config("hil", MissionConfig)).ground
    assert (default.fuse_period_s, default.feedback_period_s) == (0.2, 1.0)
    patched = validate_config(
        {**BASE, "estimator": {"fuse_period_s": 0.5, "allocation_period_s": 2.5}},
        MissionConfig,
        source="m.toml",
    )
    ground = build_plan(patched).ground
    assert (ground.fuse_period_s, ground.feedback_period_s) == (0.5, 2.5)


def test_steering_px4s_airspeed_through_its_trim_is_opt_in_and_reaches_the_link():
    from app.compose.parts import link_config

    raw = load_config("px4-sitl", MissionConfig).model_dump()
    assert not link_config(
        build_plan(MissionConfig.model_validate(raw)), False
    ).px4_airspeed_via_trim
    raw["link"]["px4_airspeed_via_trim"] = True
    config = link_config(build_plan(MissionConfig.model_validate(raw)), False)
    assert config.px4_airspeed_via_trim


def test_px4_is_asked_for_the_mission_rates_unless_told_to_keep_its_own() -> None:
    from app.adapters.vehicle.autopilots.px4 import px4_mission_rates
    from app.compose.parts import link_config

    raw = load_config("px4-sitl", MissionConfig).model_dump()
    default = link_config(build_plan(MissionConfig.model_validate(raw)), False)
    assert default.px4_telemetry_rates_hz == px4_mission_rates(10.0)
    raw["link"]["px4_telemetry_rate_hz"] = 5.0
    slower = link_config(build_plan(MissionConfig.model_validate(raw)), False)
    assert slower.px4_telemetry_rates_hz == px4_mission_rates(5.0)
    raw["link"]["px4_telemetry_rate_hz"] = None
    own = link_config(build_plan(MissionConfig.model_validate(raw)), False)
    assert own.px4_telemetry_rates_hz is None
    raw["link"]["px4_telemetry_rate_hz"] = 0.0
    with pytest.raises(ValidationError, match="px4_telemetry_rate_hz"):
        MissionConfig.model_validate(raw)


def test_link_delays_reach_the_simulator_and_timesync_the_links():
    from app.compose.parts import link_config

    raw = load_config("hil", MissionConfig).model_dump()
    plan = build_plan(MissionConfig.model_validate(raw))
    assert [v.link_delay_s for v in sim_config(plan, base_port=30000).vehicles] == [0.0] * 3
    assert link_config(plan, True).timesync_period_s == 1.0
    raw["sim"]["link_delays_s"] = [0.3, 0.1]
    raw["link"]["timesync_period_s"] = 0.0
    plan = build_plan(MissionConfig.model_validate(raw))
    delays = [v.link_delay_s for v in sim_config(plan, base_port=30000).vehicles]
    assert delays == [0.3, 0.1, 0.0]
    assert link_config(plan, True).timesync_period_s == 0.0
    raw["sim"]["link_delays_s"] = [-0.1]
    with pytest.raises(ValidationError, match="link_delays_s"):
        MissionConfig.model_validate(raw)
