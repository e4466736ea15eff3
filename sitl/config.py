"""Plain, validated settings of the built-in simulator: vehicles, camera, wind, ports, time."""

import math
from dataclasses import dataclass, field
from typing import Literal

from app.core.plant import FixedWingState, VehicleEnvelope
from sitl.target import Maneuver, TargetPath


def _finite(name: str, value: float) -> None:
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")


def _positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")


def _non_negative(name: str, value: float) -> None:
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")


def _probability(name: str, value: float) -> None:
    if not (math.isfinite(value) and 0.0 <= value <= 1.0):
        raise ValueError(f"{name} must be in [0, 1], got {value!r}")


@dataclass(frozen=True, slots=True)
class CameraConfig:
    """The simulated tracking camera: geolocation noise, dropouts and outliers.

    The target's reported position is its true position plus Gaussian noise of variance
    ``sigma2_m2 + (range_sigma_per_m * range_m)**2`` per horizontal axis. Each sample is
    dropped (not sent) with probability ``dropout_probability``; a sent sample is an outlier
    with probability ``outlier_probability``, with ``outlier_sigma_m`` of extra noise.
    Beyond ``max_range_m`` (if set) the camera sees nothing.
    """

    enabled: bool = True
    rate_hz: float = 10.0
    sigma2_m2: float = 10.0
    range_sigma_per_m: float = 0.0
    dropout_probability: float = 0.0
    outlier_probability: float = 0.0
    outlier_sigma_m: float = 50.0
    max_range_m: float | None = None

    def __post_init__(self) -> None:
        _positive("camera rate_hz", self.rate_hz)
        _non_negative("camera sigma2_m2", self.sigma2_m2)
        _non_negative("camera range_sigma_per_m", self.range_sigma_per_m)
        _probability("camera dropout_probability", self.dropout_probability)
        _probability("camera outlier_probability", self.outlier_probability)
        _non_negative("camera outlier_sigma_m", self.outlier_sigma_m)
        if self.max_range_m is not None:
            _positive("camera max_range_m", self.max_range_m)

    def sigma_m(self, range_m: float) -> float:
        """Standard deviation of the geolocation error per axis at a slant range."""
        return math.sqrt(self.sigma2_m2 + (self.range_sigma_per_m * range_m) ** 2)


@dataclass(frozen=True, slots=True)
class WindConfig:
    """Steady wind plus gusts: a first-order Gauss-Markov process per axis (sigma, tau)."""

    east_m_s: float = 0.0
    north_m_s: float = 0.0
    gust_sigma_m_s: float = 0.0
    gust_tau_s: float = 5.0

    def __post_init__(self) -> None:
        _finite("wind east_m_s", self.east_m_s)
        _finite("wind north_m_s", self.north_m_s)
        _non_negative("wind gust_sigma_m_s", self.gust_sigma_m_s)
        _positive("wind gust_tau_s", self.gust_tau_s)


@dataclass(frozen=True, slots=True)
class VehicleConfig:
    """One simulated aircraft: its envelope, where it is launched, how it holds and loiters.

    ``cruise_speed_m_s`` is flown in hold, return and toward a position setpoint. The loiter
    radius defaults to 1.5 times the tightest turn at cruise speed; a radius tighter than that
    turn (times 1.05) is refused: the airframe could not fly it.
    """

    limits: VehicleEnvelope
    start: FixedWingState
    cruise_speed_m_s: float
    altitude_m: float = 100.0
    loiter_radius_m: float | None = None
    loiter_clockwise: bool = True
    #: how long before the simulation started this vehicle's autopilot booted (s): its
    #: ``time_boot_ms`` starts there; None: ``SimConfig.boot_spacing_s`` times its index
    boot_offset_s: float | None = None
    #: the one-way transport delay of its link (simulated s), in each direction: every
    #: datagram it sends reaches the ground station, and every one it is sent reaches it, this
    #: much later (a telemetry radio or a cellular modem; 0: loopback)
    link_delay_s: float = 0.0

    def __post_init__(self) -> None:
        _positive("cruise_speed_m_s", self.cruise_speed_m_s)
        _finite("altitude_m", self.altitude_m)
        _non_negative("link_delay_s", self.link_delay_s)
        if self.link_delay_s > 5.0:
            raise ValueError(f"link_delay_s must be at most 5 s, got {self.link_delay_s}")
        if self.boot_offset_s is not None:
            _non_negative("boot_offset_s", self.boot_offset_s)
        lim = self.limits
        if not lim.min_speed_m_s <= self.cruise_speed_m_s <= lim.max_speed_m_s:
            raise ValueError(
                f"cruise_speed_m_s {self.cruise_speed_m_s} is outside "
                f"[{lim.min_speed_m_s}, {lim.max_speed_m_s}]"
            )
        if self.loiter_radius_m is not None:
            _positive("loiter_radius_m", self.loiter_radius_m)
            if self.loiter_radius_m < 1.05 * self.min_turn_radius_m:
                raise ValueError(
                    f"loiter_radius_m {self.loiter_radius_m} is tighter than the vehicle can "
                    f"turn at cruise speed (needs >= {1.05 * self.min_turn_radius_m:.1f} m)"
                )

    @property
    def min_turn_radius_m(self) -> float:
        return self.cruise_speed_m_s / self.limits.max_course_rate_rad_s

    @property
    def effective_loiter_radius_m(self) -> float:
        if self.loiter_radius_m is not None:
            return self.loiter_radius_m
        return 1.5 * self.min_turn_radius_m


def default_limits() -> VehicleEnvelope:
    """The paper's vehicle: 18 m/s cruise within [12, 24] m/s, 0.2 rad/s course rate."""
    return VehicleEnvelope(
        cruise_speed_m_s=18.0,
        min_speed_m_s=12.0,
        max_speed_m_s=24.0,
        max_accel_m_s2=2.0,
        max_course_rate_rad_s=0.2,
    )


def default_vehicles(
    count: int,
    limits: VehicleEnvelope | None = None,
    cruise_speed_m_s: float = 18.0,
    altitude_m: float = 100.0,
    spacing_m: float = 100.0,
) -> tuple[VehicleConfig, ...]:
    """``count`` vehicles (the paper's by default) launched in a row west to east, 100 m
    apart, 600 m south of the origin, flying north at cruise speed."""
    if count < 1:
        raise ValueError(f"need at least one vehicle, got {count}")
    half = 0.5 * (count - 1) * spacing_m
    return tuple(
        VehicleConfig(
            limits=limits or default_limits(),
            start=FixedWingState(
                east_m=i * spacing_m - half,
                north_m=-600.0,
                course_rad=0.0,
                speed_m_s=cruise_speed_m_s,
            ),
            cruise_speed_m_s=cruise_speed_m_s,
            altitude_m=altitude_m,
        )
        for i in range(count)
    )


def stationary_target(east_m: float = 0.0, north_m: float = 0.0) -> TargetPath:
    """A target standing at a point."""
    return TargetPath.from_maneuvers(east_m, north_m, 0.0, 0.0, [Maneuver(1.0)])


FailsafeAction = Literal["hold", "return"]
Autopilot = Literal["px4", "arduplane"]
GcsFailsafe = Literal["off", "continue", "return"]
#: how a take-off is flown: "runway" (the real ones: a ground roll from rest, rotation at the
#: minimum airspeed, a climb to the vehicle's altitude) or "launch" (into the air at the start
#: state and altitude at once, as a catapult would)
Takeoff = Literal["runway", "launch"]
#: PX4's airspeed in OFFBOARD: "trim" (v1.16: FW_AIRSPD_TRIM, DO_CHANGE_SPEED applied only in
#: AUTO modes) or "setpoint" (the setpoint velocity's magnitude, DO_CHANGE_SPEED in any mode)
Px4OffboardSpeed = Literal["trim", "setpoint"]
#: the sign PX4 gives the curvature of an offboard acceleration: "v1.16.0" (the release's
#: radius = -sign(v x a) v^2 / a_n: a right-turn acceleration feeds a left turn forward, fixed
#: upstream after the release) or "ned" (a positive radius for a clockwise turn, as documented)
Px4CurvatureSign = Literal["v1.16.0", "ned"]
#: ArduPlane GUIDED's course loop: "pid" (GUIDED_P bank per course error, bank limited by
#: GUIDED_CHANGE_HEADING's param3 and ROLL_LIMIT_DEG) or "ideal" (the airframe's course gain)
GuidedHeadingLoop = Literal["pid", "ideal"]
#: the parameter that names ArduPlane's GCS: SYSID_MYGCS up to ArduPilot 4.6, MAV_GCS_SYSID
#: (with the range's top, MAV_GCS_SYSID_HI) from 4.7
GcsSysidParam = Literal["SYSID_MYGCS", "MAV_GCS_SYSID"]


@dataclass(frozen=True, slots=True)
class SimConfig:
    """Everything the simulator server needs.

    Time: simulated time runs ``speedup`` times faster than wall time and advances in fixed
    physics steps of ``physics_dt_s``; every MAVLink time field is simulated time. Telemetry and
    camera rates are per simulated second.

    Ports: vehicle i (system id i+1) sends to ``gcs_host``:``base_port + i`` and answers whoever
    sends to it. It binds ``bind_host``:``bind_base_port + i``, or an ephemeral port when
    ``bind_base_port`` is None.

    Failsafe: in offboard, when no setpoint has come for ``offboard_timeout_s`` of simulated
    time (and at least ``offboard_timeout_min_wall_s`` of wall time, since clients resend
    setpoints at a wall-clock rate), the vehicle does ``failsafe_action``.

    Autopilot: ``"px4"`` (the default) imitates PX4; ``"arduplane"`` imitates ArduPlane
    (``sitl.arduplane``), whose GCS failsafe is ``gcs_failsafe`` (FS_GCS_ENABL and FS_LONG_ACTN:
    off, as ArduPlane's default; continue; return = RTL) after ``gcs_failsafe_timeout_s``
    (FS_LONG_TIMEOUT) without a HEARTBEAT from system ``gcs_system_id`` (SYSID_MYGCS, or
    MAV_GCS_SYSID when ``gcs_sysid_param`` names ArduPilot 4.7's parameter).

    Boot clocks: vehicle i's autopilot booted ``boot_spacing_s * i`` seconds before the
    simulation started (unless its ``VehicleConfig.boot_offset_s`` says otherwise), so every
    vehicle's ``time_boot_ms`` differs, as real autopilots started one after another do.

    Personalities (``sitl.px4``, ``sitl.arduplane`` document each against the autopilot's
    source): ``takeoff``; ``px4_offboard_speed``, ``px4_trim_airspeed_m_s`` (FW_AIRSPD_TRIM;
    None: each vehicle's cruise speed), ``px4_curvature_sign`` and ``px4_roll_limit_deg``
    (FW_R_LIM, 50 deg: an offboard position setpoint is followed turning at up to
    g tan(FW_R_LIM) / V, not the vehicle's envelope rate; None: the envelope's);
    ``arduplane_stream_rate_hz``
    (the SRn_* stream rates, 1 Hz as shipped), ``arduplane_guided_heading``,
    ``arduplane_turn_efficiency`` (the course rate flown at a bank, as a fraction of the
    coordinated turn's g tan(bank) / V: 0.70 in real ArduPlane 4.6.2 SITL),
    ``arduplane_speed_time_constant_s`` (TECS's lag behind a GUIDED speed, 4 s; 0: none),
    ``arduplane_gcs_seen_at_boot`` (ArduPlane counts its own boot as the GCS's last heartbeat)
    and ``arduplane_guided_rebase`` (GUIDED entered holds the altitude it was entered at).
    Each default is what the real autopilot does.
    """

    vehicles: tuple[VehicleConfig, ...]
    target: TargetPath = field(default_factory=stationary_target)
    origin_lat_deg: float = 47.397742
    origin_lon_deg: float = 8.545594
    origin_alt_m: float = 488.0
    gcs_host: str = "127.0.0.1"
    base_port: int = 14540
    bind_host: str = "127.0.0.1"
    bind_base_port: int | None = None
    speedup: float = 1.0
    seed: int = 0
    physics_dt_s: float = 0.02
    telemetry_rate_hz: float = 10.0
    offboard_timeout_s: float = 1.0
    offboard_timeout_min_wall_s: float = 0.25
    failsafe_action: FailsafeAction = "hold"
    autopilot: Autopilot = "px4"
    gcs_failsafe: GcsFailsafe = "off"
    gcs_failsafe_timeout_s: float = 5.0
    gcs_system_id: int = 255
    gcs_sysid_param: GcsSysidParam = "SYSID_MYGCS"
    camera: CameraConfig = field(default_factory=CameraConfig)
    #: the MAVLink component each vehicle's tracking camera sends from (MAV_COMP_ID_CAMERA)
    camera_component_id: int = 100
    wind: WindConfig = field(default_factory=WindConfig)
    boot_spacing_s: float = 3.7
    takeoff: Takeoff = "runway"
    px4_offboard_speed: Px4OffboardSpeed = "trim"
    px4_trim_airspeed_m_s: float | None = None
    px4_curvature_sign: Px4CurvatureSign = "v1.16.0"
    px4_roll_limit_deg: float | None = 50.0
    arduplane_stream_rate_hz: float = 1.0
    arduplane_guided_heading: GuidedHeadingLoop = "pid"
    arduplane_turn_efficiency: float = 0.70
    arduplane_speed_time_constant_s: float = 4.0
    arduplane_gcs_seen_at_boot: bool = True
    arduplane_guided_rebase: bool = True

    def boot_offset_s(self, index: int) -> float:
        """How long before the simulation started vehicle ``index``'s autopilot booted (s)."""
        own = self.vehicles[index].boot_offset_s
        return self.boot_spacing_s * index if own is None else own

    def __post_init__(self) -> None:
        if not self.vehicles:
            raise ValueError("need at least one vehicle")
        if len(self.vehicles) > 254:
            raise ValueError(f"at most 254 vehicles (system ids 1..254), got {len(self.vehicles)}")
        if not (-90.0 <= self.origin_lat_deg <= 90.0):
            raise ValueError(f"origin_lat_deg must be in [-90, 90], got {self.origin_lat_deg!r}")
        if not (-180.0 <= self.origin_lon_deg <= 180.0):
            raise ValueError(f"origin_lon_deg must be in [-180, 180], got {self.origin_lon_deg!r}")
        _finite("origin_alt_m", self.origin_alt_m)
        for name, port, count in (
            ("base_port", self.base_port, len(self.vehicles)),
            ("bind_base_port", self.bind_base_port, len(self.vehicles)),
        ):
            if port is not None and not (port >= 1 and port + count - 1 <= 65535):
                raise ValueError(f"{name} {port} + {count} vehicles runs outside 1..65535")
        _positive("speedup", self.speedup)
        _positive("physics_dt_s", self.physics_dt_s)
        _positive("telemetry_rate_hz", self.telemetry_rate_hz)
        _positive("offboard_timeout_s", self.offboard_timeout_s)
        _non_negative("offboard_timeout_min_wall_s", self.offboard_timeout_min_wall_s)
        if self.failsafe_action not in ("hold", "return"):
            raise ValueError(
                f"failsafe_action must be 'hold' or 'return', got {self.failsafe_action!r}"
            )
        if self.autopilot not in ("px4", "arduplane"):
            raise ValueError(f"autopilot must be 'px4' or 'arduplane', got {self.autopilot!r}")
        if self.gcs_failsafe not in ("off", "continue", "return"):
            raise ValueError(
                f"gcs_failsafe must be 'off', 'continue' or 'return', got {self.gcs_failsafe!r}"
            )
        _positive("gcs_failsafe_timeout_s", self.gcs_failsafe_timeout_s)
        if not 1 <= self.gcs_system_id <= 255:
            raise ValueError(f"gcs_system_id must be in 1..255, got {self.gcs_system_id!r}")
        _non_negative("boot_spacing_s", self.boot_spacing_s)
        if not 2 <= self.camera_component_id <= 255:
            raise ValueError(
                "camera_component_id must be in 2..255 (1 is the autopilot), got "
                f"{self.camera_component_id!r}"
            )
        for name, value, allowed in (
            ("takeoff", self.takeoff, ("runway", "launch")),
            ("px4_offboard_speed", self.px4_offboard_speed, ("trim", "setpoint")),
            ("px4_curvature_sign", self.px4_curvature_sign, ("v1.16.0", "ned")),
            ("arduplane_guided_heading", self.arduplane_guided_heading, ("pid", "ideal")),
        ):
            if value not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
        if self.px4_trim_airspeed_m_s is not None:
            _positive("px4_trim_airspeed_m_s", self.px4_trim_airspeed_m_s)
        roll = self.px4_roll_limit_deg
        if roll is not None and not (math.isfinite(roll) and 0.0 < roll < 90.0):
            raise ValueError(f"px4_roll_limit_deg must be in (0, 90) or None, got {roll!r}")
        _non_negative("arduplane_stream_rate_hz", self.arduplane_stream_rate_hz)
        _non_negative("arduplane_speed_time_constant_s", self.arduplane_speed_time_constant_s)
        eta = self.arduplane_turn_efficiency
        if not (math.isfinite(eta) and 0.0 < eta <= 1.0):
            raise ValueError(f"arduplane_turn_efficiency must be in (0, 1], got {eta!r}")
        if self.gcs_sysid_param not in ("SYSID_MYGCS", "MAV_GCS_SYSID"):
            raise ValueError(
                "gcs_sysid_param must be 'SYSID_MYGCS' or 'MAV_GCS_SYSID', got "
                f"{self.gcs_sysid_param!r}"
            )
