"""The schema of a simulator scenario file (``configs/sitl-*.toml``), built into ``SimConfig``.

Angles are degrees in the file; the built ``sitl.config.SimConfig`` holds radians.
"""

import math
from typing import Annotated, Literal

from pydantic import Field

from app.config.schema import (
    Finite,
    LimitsConfig,
    NonNegative,
    Positive,
    Speedup,
    StrictModel,
    TargetConfig,
    VehicleStartConfig,
)
from app.errors import ConfigError
from sitl.config import (
    CameraConfig,
    SimConfig,
    VehicleConfig,
    WindConfig,
    default_vehicles,
    stationary_target,
)

Port = Annotated[int, Field(ge=1, le=65535)]
Probability = Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]

PAPER_LIMITS = LimitsConfig(cruise_speed_m_s=18.0, min_speed_m_s=12.0, max_speed_m_s=24.0)


class SitlVehicleConfig(StrictModel):
    """One vehicle: where it is launched, how high it flies, how it loiters; own limits optional."""

    start: VehicleStartConfig
    altitude_m: Finite = 100.0
    loiter_radius_m: Positive | None = None
    loiter_clockwise: bool = True
    limits: LimitsConfig | None = None


class OriginConfig(StrictModel):
    """The geodetic point that is (0 m east, 0 m north) of the local frame."""

    lat_deg: Annotated[float, Field(ge=-90.0, le=90.0)] = 47.397742
    lon_deg: Annotated[float, Field(ge=-180.0, le=180.0)] = 8.545594
    alt_m: Finite = 488.0


class NetworkConfig(StrictModel):
    """Vehicle i sends to gcs_host:base_port+i from bind_host:bind_base_port+i (or ephemeral)."""

    gcs_host: str = "127.0.0.1"
    base_port: Port = 14540
    bind_host: str = "127.0.0.1"
    bind_base_port: Port | None = None


class CameraModel(StrictModel):
    enabled: bool = True
    rate_hz: Positive = 10.0
    sigma2_m2: NonNegative = 10.0
    range_sigma_per_m: NonNegative = 0.0
    dropout_probability: Probability = 0.0
    outlier_probability: Probability = 0.0
    outlier_sigma_m: NonNegative = 50.0
    max_range_m: Positive | None = None

    def build(self) -> CameraConfig:
        return CameraConfig(**self.model_dump())


class WindModel(StrictModel):
    """Steady wind from the direction it blows toward, plus Gauss-Markov gusts."""

    speed_m_s: NonNegative = 0.0
    toward_deg: Finite = 0.0
    gust_sigma_m_s: NonNegative = 0.0
    gust_tau_s: Positive = 5.0

    def build(self) -> WindConfig:
        toward = math.radians(self.toward_deg)
        return WindConfig(
            east_m_s=self.speed_m_s * math.sin(toward),
            north_m_s=self.speed_m_s * math.cos(toward),
            gust_sigma_m_s=self.gust_sigma_m_s,
            gust_tau_s=self.gust_tau_s,
        )


class SitlScenario(StrictModel):
    """A simulator scenario: vehicles, target path, camera, wind, ports and time.

    With no ``[[vehicles]]`` the vehicles are placed in a row (see ``sitl.config``); with some,
    ``--vehicles N`` may ask for at most as many as are listed.
    """

    limits: LimitsConfig = PAPER_LIMITS
    vehicles: list[SitlVehicleConfig] = Field(default_factory=list)
    vehicle_altitude_m: Finite = 100.0
    target: TargetConfig | None = None
    origin: OriginConfig = OriginConfig()
    network: NetworkConfig = NetworkConfig()
    camera: CameraModel = CameraModel()
    wind: WindModel = WindModel()
    speedup: Speedup = 1.0
    seed: Annotated[int, Field(ge=0)] = 0
    physics_dt_s: Annotated[float, Field(gt=0.0, le=0.1, allow_inf_nan=False)] = 0.02
    telemetry_rate_hz: Positive = 10.0
    offboard_timeout_s: Positive = 1.0
    offboard_timeout_min_wall_s: NonNegative = 0.25
    failsafe_action: Literal["hold", "return"] = "hold"
    autopilot: Literal["px4", "arduplane"] = "px4"
    gcs_failsafe: Literal["off", "continue", "return"] = "off"
    gcs_failsafe_timeout_s: Positive = 5.0
    gcs_system_id: Annotated[int, Field(ge=1, le=255)] = 255
    gcs_sysid_param: Literal["SYSID_MYGCS", "MAV_GCS_SYSID"] = "SYSID_MYGCS"

    def build(
        self,
        count: int | None = None,
        base_port: int | None = None,
        speedup: float | None = None,
        seed: int | None = None,
        autopilot: Literal["px4", "arduplane"] | None = None,
    ) -> SimConfig:
        """The simulator config, with command-line overrides; ConfigError if they do not fit."""
        vehicles = self._vehicles(count)
        try:
            return SimConfig(
                vehicles=vehicles,
                target=self.target.build() if self.target is not None else stationary_target(),
                origin_lat_deg=self.origin.lat_deg,
                origin_lon_deg=self.origin.lon_deg,
                origin_alt_m=self.origin.alt_m,
                gcs_host=self.network.gcs_host,
                base_port=self.network.base_port if base_port is None else base_port,
                bind_host=self.network.bind_host,
                bind_base_port=self.network.bind_base_port,
                speedup=self.speedup if speedup is None else speedup,
                seed=self.seed if seed is None else seed,
                physics_dt_s=self.physics_dt_s,
                telemetry_rate_hz=self.telemetry_rate_hz,
                offboard_timeout_s=self.offboard_timeout_s,
                offboard_timeout_min_wall_s=self.offboard_timeout_min_wall_s,
                failsafe_action=self.failsafe_action,
                autopilot=self.autopilot if autopilot is None else autopilot,
                gcs_failsafe=self.gcs_failsafe,
                gcs_failsafe_timeout_s=self.gcs_failsafe_timeout_s,
                gcs_system_id=self.gcs_system_id,
                gcs_sysid_param=self.gcs_sysid_param,
                camera=self.camera.build(),
                wind=self.wind.build(),
            )
        except ValueError as exc:
            raise ConfigError(str(exc)) from exc

    def _vehicles(self, count: int | None) -> tuple[VehicleConfig, ...]:
        if count is not None and count < 1:
            raise ConfigError(f"--vehicles must be >= 1, got {count}")
        if count is not None and count > 254:
            raise ConfigError(f"--vehicles must be <= 254 (MAVLink system ids), got {count}")
        try:
            if self.vehicles:
                if count is not None and count > len(self.vehicles):
                    raise ConfigError(
                        f"--vehicles {count}: the scenario lists only {len(self.vehicles)} vehicles"
                    )
                chosen = self.vehicles[: count or len(self.vehicles)]
                return tuple(self._vehicle(v) for v in chosen)
            return default_vehicles(
                count or 3,
                limits=self.limits.build(),
                cruise_speed_m_s=self.limits.cruise_speed_m_s,
                altitude_m=self.vehicle_altitude_m,
            )
        except ValueError as exc:
            raise ConfigError(str(exc)) from exc

    def _vehicle(self, v: SitlVehicleConfig) -> VehicleConfig:
        limits = v.limits or self.limits
        return VehicleConfig(
            limits=limits.build(),
            start=v.start.build(),
            cruise_speed_m_s=limits.cruise_speed_m_s,
            altitude_m=v.altitude_m,
            loiter_radius_m=v.loiter_radius_m,
            loiter_clockwise=v.loiter_clockwise,
        )
