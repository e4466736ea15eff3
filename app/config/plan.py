"""A mission file built into the core parameters of every part of the mission, before any I/O.

``build_plan`` turns a validated ``MissionConfig`` into the agents' and the ground station's
parameters, the target's path, the end time and the setpoint limits; ``team_starts`` is where
the team is launched (bunched on the standby circle); ``sim_config`` is the built-in simulator
that flies a plan.
"""

import math
from dataclasses import dataclass, replace

from app.adapters.vehicle.autopilots.limits import SetpointLimits
from app.config.estimator import load_estimator
from app.config.mission import MissionConfig
from app.core.agent import ActuatorChoice, AgentParams, GuidanceParams, PhaseParams
from app.core.guidance import course_id
from app.core.guidance.horizon import HorizonParams
from app.core.guidance.wind import WindParams
from app.core.mission.agent import MissionAgentParams
from app.core.mission.ground import GroundParams
from app.core.mission.stage import StageParams
from app.core.plant import FixedWingState
from app.errors import ConfigError
from sitl.config import SimConfig, VehicleConfig
from sitl.target import TargetPath

#: the angle between two neighbours on the standby circle at launch (rad)
LAUNCH_SPACING_RAD = math.radians(25.0)


@dataclass(frozen=True, slots=True)
class MissionPlan:
    """Everything built from the config, before any I/O."""

    config: MissionConfig
    target: TargetPath
    end_t_s: float
    agents: tuple[MissionAgentParams, ...]
    ground: GroundParams
    setpoint_limits: SetpointLimits

    @property
    def count(self) -> int:
        return len(self.agents)

    @property
    def phase_actuator(self) -> ActuatorChoice:
        """The phase actuator the file asks for (``auto``, ``speed`` or ``radius``); the plan's
        agents fly ``auto`` as ``speed``. The runtime resolves it per vehicle from what its
        autopilot honours: ``app.core.agent.resolve_actuator`` and ``with_phase_actuator``."""
        return self.config.phase.actuator


def build_plan(config: MissionConfig, vehicles: int | None = None) -> MissionPlan:
    """Core parameters of every part; raises ConfigError when they do not fit together."""
    n = vehicles or config.vehicles
    lim = config.limits
    try:
        target = config.target.build()
        envelope = lim.build()
        g = config.guidance
        guidance = GuidanceParams(
            radius_m=config.radius_m,
            orbit=config.orbit,
            law=g.law,
            c=g.c,
            feed_forward=g.feed_forward,
            curvature_margin=g.curvature_margin,
        )
        # ``auto`` is ``speed`` here (the built-in simulator and the fast simulation honour a
        # speed command); the runtime resolves it per vehicle (``phase_actuator``)
        track_phase = config.phase.build(honours_speed=True)
        phase = replace(
            track_phase,
            lead_speed_m_s=config.phase.gather_lead_speed_m_s,
            held_lead_turn_share=config.phase.adjust_lead_turn_share,
        )
        track_gain = config.phase.track_gain_per_s
        if track_gain is not None:
            track_phase = replace(track_phase, gain_per_s=track_gain)
        track_guidance = replace(
            guidance,
            law=g.law if g.track_law == "paper" else g.track_law,
            c=g.track_c if g.track_law == "fixed" and g.track_c is not None else g.c,
            inverse_field=False,
            orbit_plan=g.track_orbit_plan,
            speed_cap=g.track_speed_cap,
            turn_slow_rad=(
                None
                if g.track_turn_slow_deg is None
                else (
                    math.radians(g.track_turn_slow_deg[0]),
                    math.radians(g.track_turn_slow_deg[1]),
                )
            ),
            planner=g.track_planner,
            horizon=HorizonParams(
                horizon_s=g.track_horizon_s,
                block_s=g.track_block_s,
                replan_s=g.track_replan_s,
                joint_max_vehicles=g.track_joint_max_vehicles,
            ),
        )
        standby = GuidanceParams(radius_m=config.standby.radius_m, orbit=config.orbit)
        estimator = load_estimator(config.estimator.config)
        local, main = estimator.local, estimator.main
        agents = tuple(
            MissionAgentParams(
                vehicle=i,
                agent=AgentParams(i, envelope, guidance, phase),
                standby=AgentParams(0, envelope, standby, PhaseParams("none")),
                standby_east_m=config.standby.east_m,
                standby_north_m=config.standby.north_m,
                local=local,
                main=main if main.feedback != "none" else None,
                track=AgentParams(i, envelope, track_guidance, track_phase),
                use_target_accel=config.estimator.use_target_accel,
                latency_s=g.latency_s,
                hold_s=g.hold_s,
                moving_speed_m_s=config.stages.moving_speed_m_s,
                course_id=(
                    None
                    if g.course_loop_identification == "off"
                    else course_id.params_for(envelope)
                ),
                fly_identified=g.course_loop_identification == "fly",
                wind=None if g.wind == "off" else WindParams(air_frame=g.wind == "estimate"),
                separation=config.separation.build(),
                gather_join=g.gather_join,
            )
            for i in range(n)
        )
        s = config.stages
        ground = GroundParams(
            vehicles=tuple(range(n)),
            radius_m=config.radius_m,
            tracking_command_t_s=config.tracking_command_s,
            main=main,
            fuse_period_s=config.estimator.fuse_period_s,
            feedback_period_s=config.estimator.allocation_period_s,
            stages=StageParams(
                arrive_tolerance_m=s.arrive_tolerance_m,
                radius_tolerance_m=s.radius_tolerance_m,
                spacing_tolerance_rad=math.radians(s.spacing_tolerance_deg),
                dwell_s=s.dwell_s,
                moving_speed_m_s=s.moving_speed_m_s,
            ),
            lost_after_s=max(2.0, 3.0 / config.sim.telemetry_rate_hz),
            prediction_model=agents[0].prediction_model,
        )
        # The agent's command already keeps the implied course rate k (command - course) within
        # the limit (agent_step); the link's own course-change limiter would clip the lag
        # compensation, so the link checks speed and finiteness only.
        limits = SetpointLimits(envelope, limit_course_change=False)
    except ValueError as exc:
        raise ConfigError(str(exc)) from exc
    end = config.end_s if config.end_s is not None else target.duration_s + config.tail_s
    return MissionPlan(config, target, end, agents, ground, limits)


def team_starts(plan: MissionPlan) -> list[FixedWingState]:
    """The team at launch. ``[sim] start = "standby"``: bunched on the standby circle,
    ``LAUNCH_SPACING_RAD`` apart, each flying along the circle in the orbit's direction at
    cruise speed; ``"home"``: in a row ``home_spacing_m`` apart going east from the origin,
    facing north."""
    cfg = plan.config
    if cfg.sim.start == "home":
        return [
            FixedWingState(i * cfg.sim.home_spacing_m, 0.0, 0.0, cfg.limits.cruise_speed_m_s)
            for i in range(plan.count)
        ]
    sign = 1.0 if cfg.orbit == "ccw" else -1.0
    out = []
    for i in range(plan.count):
        a = sign * LAUNCH_SPACING_RAD * i
        course = -a if sign > 0 else math.pi - a
        out.append(
            FixedWingState(
                cfg.standby.east_m + cfg.standby.radius_m * math.cos(a),
                cfg.standby.north_m + cfg.standby.radius_m * math.sin(a),
                course,
                cfg.limits.cruise_speed_m_s,
            )
        )
    return out


def sim_config(plan: MissionPlan, base_port: int) -> SimConfig:
    """The built-in simulator for a plan: the team launched where ``team_starts`` puts it."""
    cfg = plan.config
    delays = cfg.sim.link_delays_s
    vehicles = tuple(
        VehicleConfig(
            limits=cfg.limits.build(),
            start=start,
            cruise_speed_m_s=cfg.limits.cruise_speed_m_s,
            altitude_m=cfg.link.vehicle_altitude_m(i),
            link_delay_s=delays[i] if i < len(delays) else 0.0,
        )
        for i, start in enumerate(team_starts(plan))
    )
    try:
        return SimConfig(
            vehicles=vehicles,
            target=plan.target,
            origin_lat_deg=cfg.origin.lat_deg,
            origin_lon_deg=cfg.origin.lon_deg,
            origin_alt_m=cfg.origin.alt_m,
            base_port=base_port,
            speedup=cfg.sim.speedup,
            seed=cfg.sim.seed,
            autopilot=cfg.sim.autopilot,
            physics_dt_s=cfg.sim.physics_dt_s,
            telemetry_rate_hz=cfg.sim.telemetry_rate_hz,
            camera=cfg.sim.camera.build(),
            camera_component_id=cfg.link.camera_component_id,
            wind=cfg.sim.wind.build(),
            boot_spacing_s=cfg.sim.boot_spacing_s,
            takeoff=cfg.sim.takeoff,
            px4_offboard_speed=cfg.sim.px4_offboard_speed,
            px4_trim_airspeed_m_s=cfg.sim.px4_trim_airspeed_m_s,
            px4_curvature_sign=cfg.sim.px4_curvature_sign,
            px4_roll_limit_deg=cfg.sim.px4_roll_limit_deg,
            arduplane_stream_rate_hz=cfg.sim.arduplane_stream_rate_hz,
            arduplane_guided_heading=cfg.sim.arduplane_guided_heading,
            arduplane_turn_efficiency=cfg.sim.arduplane_turn_efficiency,
            arduplane_speed_time_constant_s=cfg.sim.arduplane_speed_time_constant_s,
            arduplane_gcs_seen_at_boot=cfg.sim.arduplane_gcs_seen_at_boot,
            arduplane_guided_rebase=cfg.sim.arduplane_guided_rebase,
            # like PX4's COM_OF_LOSS_T = 1 s: setpoints missing for a second of wall time, not a
            # scheduling hiccup of a loaded machine at a speed-up, trip the offboard failsafe
            offboard_timeout_min_wall_s=1.0,
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from exc
