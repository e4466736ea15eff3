"""The estimator's parameter file (``configs/estimator.toml``), validated and built into the
core's ``FederatedParams``: the IMM's models and mode transitions, the local filters' rules and
the federated main filter."""

import math
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field

from app.config.loading import load_config
from app.config.schema import StrictModel
from app.core.estimation.federated import FeedbackMode, MainParams
from app.core.estimation.imm import IMMParams
from app.core.estimation.local import LocalParams
from app.core.estimation.models import MotionModel
from app.core.estimation.pipeline import FederatedParams
from app.core.estimation.ukf import SigmaPoints
from app.errors import ConfigError


class ModelConfig(StrictModel):
    kind: Literal["cv", "ca", "turn", "ct"]
    noise_intensity: float = Field(ge=0.0, allow_inf_nan=False)
    turn_rate_rad_s: float = Field(default=0.0, allow_inf_nan=False)

    def build(self) -> MotionModel:
        return MotionModel(self.kind, self.noise_intensity, self.turn_rate_rad_s)


class IMMConfig(StrictModel):
    transition_dt_s: float = Field(default=0.1, gt=0.0, allow_inf_nan=False)
    transition: list[list[float]]
    models: list[ModelConfig] = Field(min_length=1)


class SigmaConfig(StrictModel):
    alpha: float = Field(default=1.0, gt=0.0, allow_inf_nan=False)
    beta: float = Field(default=2.0, allow_inf_nan=False)
    kappa: float = Field(default=0.0, allow_inf_nan=False)


class LocalConfig(StrictModel):
    default_sigma_m: float = Field(default=math.sqrt(10.0), gt=0.0, allow_inf_nan=False)
    gate_nis: float = Field(default=18.42, gt=0.0, allow_inf_nan=False)
    max_consecutive_gated: int = Field(default=10, ge=1)
    max_lag_s: float = Field(default=1.0, ge=0.0, allow_inf_nan=False)
    max_abs_position_m: float = Field(default=1.0e6, gt=0.0, allow_inf_nan=False)
    min_sigma_m: float = Field(default=1e-3, gt=0.0, allow_inf_nan=False)
    max_sigma_m: float = Field(default=1e3, gt=0.0, allow_inf_nan=False)
    init_speed_sigma_m_s: float = Field(default=10.0, gt=0.0, allow_inf_nan=False)
    init_accel_sigma_m_s2: float = Field(default=1.0, gt=0.0, allow_inf_nan=False)


class FederatedConfig(StrictModel):
    feedback: FeedbackMode = "modewise"
    feedback_period_s: float = Field(default=0.0, ge=0.0, allow_inf_nan=False)
    max_age_s: float = Field(default=2.0, gt=0.0, allow_inf_nan=False)
    scale_process_noise: bool = True
    time_update_q: float = Field(default=5e-4, ge=0.0, allow_inf_nan=False)


class EstimatorConfig(StrictModel):
    """configs/estimator.toml: models, IMM, local filter limits, federated design."""

    imm: IMMConfig
    sigma_points: SigmaConfig = SigmaConfig()
    local: LocalConfig = LocalConfig()
    federated: FederatedConfig = FederatedConfig()

    def build(self) -> FederatedParams:
        """The core parameters; a config the core refuses becomes a ConfigError."""
        try:
            imm = IMMParams(
                models=tuple(m.build() for m in self.imm.models),
                transition=np.array(self.imm.transition, dtype=np.float64),
                transition_dt_s=self.imm.transition_dt_s,
                sigma=SigmaPoints(
                    6, self.sigma_points.alpha, self.sigma_points.beta, self.sigma_points.kappa
                ),
            )
            local = LocalParams(imm=imm, **self.local.model_dump())
            main = MainParams(
                imm=imm,
                time_update=MotionModel("ca", self.federated.time_update_q),
                max_age_s=self.federated.max_age_s,
                feedback=self.federated.feedback,
                scale_process_noise=self.federated.scale_process_noise,
            )
            return FederatedParams(local, main, self.federated.feedback_period_s)
        except ValueError as exc:
            raise ConfigError(f"estimator config: {exc}") from exc


def load_estimator(name_or_path: str | Path = "estimator") -> FederatedParams:
    """The estimator parameters of a config name or file."""
    return load_config(name_or_path, EstimatorConfig).build()
