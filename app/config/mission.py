"""The schema of a mission file (``configs/hil.toml`` and friends), built into runtime values.

One file describes a whole mission: the team and its envelope, the guidance and phase laws, the
standby point and the tracking command, the stage thresholds, where observations come from,
the estimator, the vehicle links (the built-in simulator's or ``connect`` URLs), and the bus.
Angles are degrees in the file.
"""

import math
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from app.adapters.vehicle.mavsdk.urls import parse_gcs_endpoint
from app.config.schema import (
    Finite,
    Fraction,
    GuidanceConfig,
    LimitsConfig,
    LocalPosition,
    NonNegative,
    PhaseConfig,
    Positive,
    Speedup,
    StrictModel,
    TargetConfig,
)
from app.config.simulator import CameraModel, OriginConfig, WindModel
from app.core.mission.separation import SeparationParams
from app.errors import ConfigError

Count = Annotated[int, Field(ge=1, le=50)]


class MissionGuidanceConfig(GuidanceConfig):
    """The guidance law (``GuidanceConfig``) flown to the circle (gather, adjust). In the track
    stage the inverse-field switch is off and ``track_law`` / ``track_orbit_plan`` apply:
    ``circle`` is the paper's orbit, ``ellipse`` the flyable orbit planned around a target too
    fast for the circle (docs/guidance.md); ``track_law = "paper"`` flies the track stage
    exactly like the approach; ``track_law = "fixed"`` flies the field with ``track_c`` (or,
    without it, ``c``).
    ``track_speed_cap``: cap the ground speed in the track stage where the orbit around the
    moving target would need more turn rate than the vehicle has (``GuidanceParams.speed_cap``).
    ``track_turn_slow_deg``: (start, full) course errors, deg: in the track stage, where the
    field's course is more than ``start`` from the vehicle's the ground speed is capped on a
    ramp down to the minimum speed at ``full``, so that a long turn is flown on the tightest
    circle the vehicle has (``GuidanceParams.turn_slow_rad``); None: off.
    ``latency_s``: the time from a telemetry frame until its command starts to act on the
    vehicle; ``hold_s``: how long a command acts (the control period, 0.1 s at 10 Hz telemetry).
    Each agent steers on where its vehicle and the target will be in the middle of the hold
    (both 0: the paper's loop). The default latency, 0.01 s, is what setpoints to the built-in
    simulator were measured to take (docs/guidance.md); set it for a slower link.
    ``course_loop_identification``: identify each vehicle's course loop (gain k, delay) in
    flight and fly it (``fly``), only report it in the event log (``report``), or assume the
    envelope's k (``off``); ``app.core.guidance.course_id``.
    ``wind``: fit the wind from each vehicle's ground velocity and airspeed; to the circle
    (gather, adjust) command the airspeed that flies the guidance's ground speed in it, and in
    the track stage fly the guidance in the air mass (``estimate``), or the airspeed conversion
    in every stage (``airspeed``), or command the ground speed as the airspeed (``off``, the
    paper's still-air assumption); ``app.core.guidance.wind``, docs/guidance.md "Wind".
    ``track_planner``: in the track stage fly the field (``field``) or plan the team's course
    rates and speeds ``track_horizon_s`` ahead on the target estimate, piecewise constant over
    blocks of ``track_block_s`` (a whole number of them in the horizon), and fly the plan
    (``horizon``, receding horizon, replanned every ``track_replan_s``; speed-honouring
    autopilots only: a vehicle whose phase actuator is the orbit radius keeps the field); a
    team of up to ``track_joint_max_vehicles`` is planned jointly by every agent, a larger
    one each vehicle alone against its seat (the joint plan's work grows with the square of
    the team); ``app.core.guidance.horizon``, docs/guidance.md "Receding horizon".
    ``gather_join``: in gather, fly each vehicle to a seat of its own on the circle, planned
    for the team at the tracking command so that the slowest arrives as soon as it can
    (``seat``; teams of 2 to 5, larger ones join at one point), or let the field bring the whole
    team to the circle at one point and space it there (``point``, the paper's);
    ``app.core.guidance.dubins``, docs/mission.md "Gather"."""

    track_law: Literal["paper", "proposed", "frew", "fixed"] = "frew"
    track_c: Positive | None = None
    track_orbit_plan: Literal["circle", "ellipse"] = "ellipse"
    track_speed_cap: bool = False
    track_turn_slow_deg: tuple[NonNegative, Annotated[float, Field(gt=0.0, le=180.0)]] | None = (
        20.0,
        40.0,
    )
    latency_s: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)] = 0.01
    hold_s: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)] = 0.1
    course_loop_identification: Literal["fly", "report", "off"] = "fly"
    wind: Literal["estimate", "airspeed", "off"] = "estimate"
    track_planner: Literal["field", "horizon"] = "field"
    track_horizon_s: Annotated[float, Field(ge=4.0, le=120.0, multiple_of=0.5)] = 40.0
    track_block_s: Annotated[float, Field(ge=0.5, le=10.0, multiple_of=0.5)] = 1.0
    track_replan_s: Annotated[float, Field(ge=0.1, le=10.0, allow_inf_nan=False)] = 0.5
    track_joint_max_vehicles: Annotated[int, Field(ge=2, le=100)] = 5
    gather_join: Literal["point", "seat"] = "seat"

    @model_validator(mode="after")
    def _fixed_track_needs_c(self) -> "MissionGuidanceConfig":
        if self.track_law == "fixed" and self.track_c is None and self.c is None:
            raise ValueError("track_law 'fixed' needs track_c (or c)")
        return self

    @model_validator(mode="after")
    def _whole_blocks(self) -> "MissionGuidanceConfig":
        blocks = self.track_horizon_s / self.track_block_s
        if abs(blocks - round(blocks)) > 1e-9:
            raise ValueError(
                f"track_horizon_s ({self.track_horizon_s:g} s) must be a whole number of"
                f" track_block_s ({self.track_block_s:g} s)"
            )
        return self

    @field_validator("track_turn_slow_deg")
    @classmethod
    def _turn_slow_order(cls, value: tuple[float, float] | None) -> tuple[float, float] | None:
        if value is not None and not value[0] < value[1]:
            raise ValueError(f"track_turn_slow_deg needs start < full, got {list(value)}")
        return value


class MissionPhaseConfig(PhaseConfig):
    """Phase keeping (``PhaseConfig``) in gather and adjust; ``track_gain_per_s`` replaces the
    gain in the track stage (None: the same). ``gather_lead_speed_m_s``: in gather and adjust
    the vehicle furthest behind its seat flies this speed and the others slower by the law, so
    that the team closes its gaps at this speed rather than about cruise (None: about cruise,
    the paper's law); within the envelope's speed range. An agent flies it only where the
    circle can be flown all round at it in the wind it knows (docs/guidance.md "Lead speed").
    ``adjust_lead_turn_share``: in adjust, where the team has gathered on the circle, the lead
    is at most this share of W r_d (W the course-rate limit), the speed at which the circle
    takes the whole turn: twenty vehicles at the 18 m/s lead (W r_d) were pushed 3-8 m out
    again and again and did not hold the formation's 3 m for 5 s."""

    track_gain_per_s: NonNegative | None = None
    gather_lead_speed_m_s: Positive | None = None
    adjust_lead_turn_share: Fraction = 0.9


class StandbyConfig(StrictModel):
    """Where the team loiters until the tracking command (metres about the origin)."""

    east_m: LocalPosition
    north_m: LocalPosition
    radius_m: Positive = 150.0


class StagesConfig(StrictModel):
    arrive_tolerance_m: Positive = 15.0
    radius_tolerance_m: Positive = 3.0
    spacing_tolerance_deg: Positive = 2.0
    dwell_s: NonNegative = 5.0
    moving_speed_m_s: Positive = 1.5


class SeparationConfig(StrictModel):
    """Keeping the team apart (``app.core.mission.separation``): no two vehicles closer than
    ``min_distance_m`` in 3-D. Each agent looks ``look_ahead_s`` ahead on its teammates'
    statuses; one closer than ``min_distance_m`` vertically whose predicted closest approach
    comes within ``min_distance_m + margin_m`` horizontally is turned away from (the nearest
    course that keeps the guard, right first), and a teammate horizontally near is never
    climbed or descended into (kept ``min_distance_m + vertical_margin_m`` apart). ``enabled =
    false`` flies the guidance alone (the altitude stack, ``[link] altitude_stack_m``, is then
    the only separation)."""

    enabled: bool = True
    min_distance_m: Positive = 30.0
    margin_m: NonNegative = 15.0
    vertical_margin_m: NonNegative = 5.0
    look_ahead_s: Annotated[float, Field(gt=0.0, le=60.0, allow_inf_nan=False)] = 12.0

    def build(self) -> SeparationParams | None:
        if not self.enabled:
            return None
        return SeparationParams(
            min_distance_m=self.min_distance_m,
            margin_m=self.margin_m,
            vertical_margin_m=self.vertical_margin_m,
            look_ahead_s=self.look_ahead_s,
        )


class ObservationsConfig(StrictModel):
    """Where target observations come from.

    ``camera``: each vehicle's CAMERA_TRACKING_GEO_STATUS (the built-in simulator's camera).
    ``simulated``: the ground station observes the scripted target (``sigma_m``, ``rate_hz``)
    for vehicles that have no camera (PX4 or ArduPilot SITL). ``replay``: a measurements CSV.
    ``external``: observations published on the bus under ``external_topic`` by another program.
    """

    source: Literal["camera", "simulated", "replay", "external"] = "camera"
    sigma_m: Positive = math.sqrt(10.0)
    rate_hz: Positive = 10.0
    seed: Annotated[int, Field(ge=0)] = 1
    replay_file: str | None = None
    external_topic: str | None = None

    @model_validator(mode="after")
    def _source_needs(self) -> "ObservationsConfig":
        if self.source == "replay" and not self.replay_file:
            raise ValueError("source 'replay' needs replay_file")
        if self.source == "external" and not self.external_topic:
            raise ValueError("source 'external' needs external_topic")
        return self


class EstimatorSettings(StrictModel):
    """The target estimator: ``config`` names its parameter file (``configs/estimator.toml``:
    models, mode transitions, gating, federated feedback); ``use_target_accel`` passes the
    estimated acceleration on to the moving-target correction. In a mission the ground station
    fuses every ``fuse_period_s`` and sends the fused information back to the agents (an
    allocation) every ``allocation_period_s``; the file's ``federated.feedback_period_s`` is
    for ``standoff estimate``, where there is no round trip (docs/estimation.md)."""

    config: str = "estimator"
    use_target_accel: bool = False
    fuse_period_s: Positive = 0.2
    allocation_period_s: Positive = 1.0


class LinkSettings(StrictModel):
    """Vehicle links. Empty ``connect``: the built-in simulator on ``[sim]``'s ports.

    ``altitude_m`` + i * ``altitude_stack_m``: vehicle i's altitude above home, from take-off
    to the end (vehicles apart vertically while they form up). Offboard/GUIDED is taken only
    once the vehicle is above ``handover_min_height_m`` and at ``handover_min_airspeed_m_s``
    (None: the envelope's min speed), within ``handover_timeout_s`` of its take-off.
    ``clock_window_s``: the window (mission s) over which each vehicle's boot-clock offset is the
    least host-minus-boot time.
    ``gcs_forward``: where a ground station (QGroundControl, MAVProxy) beside the app sees
    every vehicle, through the relay that records the .tlogs: ``udpout:HOST:PORT`` (sent
    there, as PX4 SITL sends to QGroundControl's 14550), ``udpin:HOST:PORT`` (vehicle i
    listened for on PORT+i), or ``off`` (docs/vehicle-link.md).
    ``camera_component_id``: the MAVLink component whose CAMERA_TRACKING_GEO_STATUS the links
    take (the built-in simulator's cameras send from it).
    ``arduplane_turn_learning``: on ArduPlane, learn in flight how much of the coordinated turn
    the aircraft flies at a bank and size GUIDED_CHANGE_HEADING's turn limit and the heading
    command for it (docs/vehicle-link.md); false: size them on the coordinated turn.
    ``arduplane_speed_learning``: on ArduPlane, learn how far the airspeed lags the speed
    command and lead the command through it (opt-in: in the simulator it helped, on real
    ArduPlane 4.6.2 two runs showed no gain and the learned lag drifted from 4 to 7-8 s;
    docs/vehicle-link.md); false (default): send the speed wanted.
    ``px4_airspeed_via_trim``: on PX4 (which flies no commanded speed in OFFBOARD), fly the
    phase law's airspeed by writing FW_AIRSPD_TRIM: the vehicle then honours speed and the
    ``auto`` phase actuator is ``speed``. Off by default: every change is a parameter write
    (at most one per 5 s, 0.5 m/s deadband), the trim is restored at the end, and an operator
    must accept PX4's cruise airspeed being moved (docs/vehicle-link.md).
    ``px4_telemetry_rate_hz``: on PX4, ask for what the link reads (GLOBAL_POSITION_INT,
    LOCAL_POSITION_NED, ATTITUDE) at this rate and slow PX4's fast streams it never reads
    (HIGHRES_IMU, ATTITUDE_QUATERNION, ODOMETRY, RC_CHANNELS) to 1 Hz, all put back at PX4's own
    rates at the end: PX4's offboard link streams about 410 messages a second, which the
    links decode and record for nothing (docs/vehicle-link.md). None: PX4's own rates.
    ``control_rate_hz``: each agent steers at most this often (vehicle time); telemetry
    arriving faster (PX4 streams position at 50 Hz) is coalesced, the frames between counted
    as ``frames_coalesced``, so an agent's CPU is that of the control rate. 0: steer on every
    frame.
    ``timesync_period_s``: how often (wall s) each link measures its round trip with a
    TIMESYNC request; every frame (and the camera fixes on it) is then stamped when it was
    sampled, its arrival time less half the least round trip, so that vehicles behind links
    of different delays agree on where the team is (docs/vehicle-link.md). 0: not measured,
    frames stamped on arrival.
    """

    connect: list[str] = Field(default_factory=list)
    autopilot: Literal["auto", "velocity", "px4-fixed-wing", "arduplane"] = "auto"
    altitude_m: Finite = 100.0
    altitude_stack_m: NonNegative = 35.0
    link_timeout_s: Positive = 2.0
    connect_timeout_s: Positive = 20.0
    take_off_timeout_s: Positive = 120.0
    handover_min_height_m: NonNegative = 30.0
    handover_min_airspeed_m_s: Positive | None = None
    handover_timeout_s: Positive = 120.0
    clock_window_s: Positive = 10.0
    gcs_forward: str = "udpout:127.0.0.1:14550"
    camera_component_id: Annotated[int, Field(ge=2, le=255)] = 100  # MAV_COMP_ID_CAMERA
    arduplane_turn_learning: bool = True
    arduplane_speed_learning: bool = False
    px4_airspeed_via_trim: bool = False
    px4_telemetry_rate_hz: Positive | None = 10.0
    control_rate_hz: NonNegative = 10.0
    timesync_period_s: Annotated[float, Field(ge=0.0, le=60.0, allow_inf_nan=False)] = 1.0

    @field_validator("gcs_forward")
    @classmethod
    def _gcs_endpoint(cls, value: str) -> str:
        if value.strip() in ("", "off"):
            return "off"
        try:
            return parse_gcs_endpoint(value).spec
        except ConfigError as exc:
            raise ValueError(str(exc)) from exc

    def vehicle_altitude_m(self, vehicle: int) -> float:
        """Vehicle ``vehicle``'s (0-based) altitude above home (m)."""
        return self.altitude_m + vehicle * self.altitude_stack_m


class SimSettings(StrictModel):
    """The built-in simulator when no ``connect`` URLs are given. ``autopilot``: the personality
    its vehicles answer MAVLink with (``px4``: PX4 v1.16 fixed-wing; ``arduplane``: ArduPlane
    4.6; docs/simulator.md). The personality's behaviours are the ``sitl.config.SimConfig``
    fields of the same names, each defaulting to what the real autopilot does (docs/simulator.md
    has the table): ``boot_spacing_s``, ``takeoff``, ``px4_offboard_speed``,
    ``px4_trim_airspeed_m_s``, ``px4_curvature_sign``, ``px4_roll_limit_deg`` (FW_R_LIM: the bank
    PX4 follows an offboard line with), ``arduplane_stream_rate_hz``,
    ``arduplane_guided_heading``, ``arduplane_turn_efficiency`` (the airframe's course rate at a
    bank as a fraction of the coordinated turn's: 0.70, as real ArduPlane 4.6.2 SITL),
    ``arduplane_speed_time_constant_s`` (TECS's lag behind a GUIDED speed: 4 s),
    ``arduplane_gcs_seen_at_boot`` and ``arduplane_guided_rebase``. ``start``: where the team
    takes off: ``standby`` (bunched on the standby circle, the default) or ``home`` (a row of
    homes ``home_spacing_m`` apart going east from the origin, facing north, as three SITL
    instances started with their homes 60 m apart), so that the simulator flies a SITL mission
    file from where the real autopilots start. ``link_delays_s``: each vehicle's one-way link
    delay (simulated s, both directions; vehicle i takes entry i, 0 past the list's end), as
    through a telemetry radio or a cellular modem."""

    autopilot: Literal["px4", "arduplane"] = "px4"
    speedup: Speedup = 3.0
    seed: Annotated[int, Field(ge=0)] = 1
    base_port: Annotated[int, Field(ge=1024, le=65000)] = 14540
    physics_dt_s: Annotated[float, Field(gt=0.0, le=0.1)] = 0.02
    telemetry_rate_hz: Positive = 10.0
    camera: CameraModel = CameraModel()
    wind: WindModel = WindModel()
    boot_spacing_s: NonNegative = 3.7
    takeoff: Literal["runway", "launch"] = "runway"
    px4_offboard_speed: Literal["trim", "setpoint"] = "trim"
    px4_trim_airspeed_m_s: Positive | None = None
    px4_curvature_sign: Literal["v1.16.0", "ned"] = "v1.16.0"
    px4_roll_limit_deg: Annotated[float, Field(gt=0.0, lt=90.0)] | None = 50.0
    arduplane_stream_rate_hz: NonNegative = 1.0
    arduplane_guided_heading: Literal["pid", "ideal"] = "pid"
    arduplane_turn_efficiency: Annotated[float, Field(gt=0.0, le=1.0)] = 0.70
    arduplane_speed_time_constant_s: NonNegative = 4.0
    arduplane_gcs_seen_at_boot: bool = True
    arduplane_guided_rebase: bool = True
    start: Literal["standby", "home"] = "standby"
    home_spacing_m: Positive = 60.0
    link_delays_s: tuple[Annotated[float, Field(ge=0.0, le=5.0, allow_inf_nan=False)], ...] = ()


class BusLoginConfig(StrictModel):
    """How each process of a multi-process mission logs in to the broker: the ``[bus]`` table's
    keys beside ``url`` (``bus = "mqtt://..."`` alone is the URL). The login is the process's
    identity (``ground``, ``agent-1``, ...); ``{client}`` in a path stands for it, so one file
    serves the whole team (``password_file = "secrets/{client}.password"``, as ``standoff
    broker`` writes them). Relative paths are from the working directory. The password comes
    from ``password_file`` (its first line) or the environment variable ``password_env``; TLS
    (``mqtts://``): ``ca_file`` to trust, ``cert_file`` / ``key_file`` a client certificate.
    ``mission_key_file``: the team's shared key (hex); every message is then sealed with it and
    only sealed ones are taken (for a broker the operator does not control)."""

    password_file: str | None = None
    password_env: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")] | None = None
    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None
    mission_key_file: str | None = None

    @model_validator(mode="after")
    def _one_password(self) -> "BusLoginConfig":
        if self.password_file is not None and self.password_env is not None:
            raise ValueError("give password_file or password_env, not both")
        if self.key_file is not None and self.cert_file is None:
            raise ValueError("key_file needs cert_file")
        return self


class MissionConfig(StrictModel):
    name: str = "mission"
    vehicles: Count = 3
    radius_m: Positive = 90.0
    orbit: Literal["ccw", "cw"] = "ccw"
    tracking_command_s: NonNegative = 10.0
    end_s: Positive | None = None
    tail_s: NonNegative = 30.0
    limits: LimitsConfig
    guidance: MissionGuidanceConfig = MissionGuidanceConfig()
    phase: MissionPhaseConfig = MissionPhaseConfig()
    standby: StandbyConfig
    stages: StagesConfig = StagesConfig()
    separation: SeparationConfig = SeparationConfig()
    target: TargetConfig
    observations: ObservationsConfig = ObservationsConfig()
    estimator: EstimatorSettings = EstimatorSettings()
    link: LinkSettings = LinkSettings()
    sim: SimSettings = SimSettings()
    origin: OriginConfig = OriginConfig()
    bus: str | None = None  # the broker's URL (``[bus] url``)
    bus_login: BusLoginConfig = BusLoginConfig()  # the other keys of a ``[bus]`` table

    @model_validator(mode="before")
    @classmethod
    def _bus_table(cls, data: object) -> object:
        """``[bus]`` as a table: its ``url`` is ``bus``, its other keys ``bus_login``."""
        if isinstance(data, dict) and isinstance(data.get("bus"), dict):
            if "bus_login" in data:
                raise ValueError("give the broker's login in the [bus] table only")
            table = dict(data["bus"])
            data = {**data, "bus": table.pop("url", None), "bus_login": table}
        return data

    @model_validator(mode="after")
    def _phase_band_fits(self) -> "MissionConfig":
        self.phase.check_band(self.radius_m)
        lead, lim = self.phase.gather_lead_speed_m_s, self.limits
        if lead is not None and not lim.min_speed_m_s <= lead <= lim.max_speed_m_s:
            raise ValueError(
                f"phase.gather_lead_speed_m_s ({lead} m/s) must be within the speed limits "
                f"[{lim.min_speed_m_s}, {lim.max_speed_m_s}] m/s"
            )
        return self

    @model_validator(mode="after")
    def _standby_flyable(self) -> "MissionConfig":
        turn_m = self.limits.cruise_speed_m_s / self.limits.max_course_rate_rad_s
        if self.standby.radius_m < 1.05 * turn_m:
            raise ValueError(
                f"standby.radius_m {self.standby.radius_m} is tighter than the vehicles can "
                f"turn at cruise speed (needs >= {1.05 * turn_m:.0f} m)"
            )
        return self

    @model_validator(mode="after")
    def _one_url_or_one_each(self) -> "MissionConfig":
        n = len(self.link.connect)
        if n not in (0, 1, self.vehicles):
            raise ValueError(
                f"link.connect lists {n} URLs for {self.vehicles} vehicles: give one URL "
                "that carries them all or one per vehicle"
            )
        return self
