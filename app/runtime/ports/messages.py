"""The bus's message schemas (version 2): frozen pydantic models that validate on construction.

Every message carries the schema version ``v``, its ``kind``, the ``sender`` (a client name)
and ``t_s``, the mission time in seconds that its content refers to. Numbers must be finite.
The target state order is [east, v_east, north, v_north, a_east, a_north] (m, m/s, m/s^2).
Version 2 added ``alloc_t_s`` to ``estimate.local`` and ``included_t_s`` to ``estimate.global``
(which allocation a local estimate is built on; docs/bus.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Annotated, Literal, Self, SupportsFloat, SupportsInt

import numpy as np
from numpy.typing import ArrayLike
from pydantic import BaseModel, ConfigDict, Field, model_validator

from app.core.mission.stage import Stage

SCHEMA_VERSION = 2
STATE_DIM = 6
STATE_ORDER = ("east_m", "v_east_m_s", "north_m", "v_north_m_s", "a_east_m_s2", "a_north_m_s2")

Name = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.:-]+$")]
VehicleId = Annotated[int, Field(ge=0, le=254)]  # vehicle i flies as MAVLink system id i + 1
Finite = float  # finiteness is enforced model-wide by allow_inf_nan=False
NonNegative = Annotated[float, Field(ge=0.0)]
Positive = Annotated[float, Field(gt=0.0)]
State = Annotated[tuple[float, ...], Field(min_length=STATE_DIM, max_length=STATE_DIM)]
Row = Annotated[tuple[float, ...], Field(min_length=STATE_DIM, max_length=STATE_DIM)]
Covariance = Annotated[tuple[Row, ...], Field(min_length=STATE_DIM, max_length=STATE_DIM)]
MAX_MODELS = 8
Probabilities = Annotated[
    tuple[Annotated[float, Field(ge=0.0, le=1.0)], ...], Field(max_length=MAX_MODELS)
]
ModelStates = Annotated[tuple[State, ...], Field(max_length=MAX_MODELS)]
ModelCovariances = Annotated[tuple[Covariance, ...], Field(max_length=MAX_MODELS)]

_SYMMETRY_RTOL = 1e-6


class Message(BaseModel):
    """Fields common to every bus message."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    v: Literal[2] = 2
    sender: Name
    t_s: Finite


def _check_covariance(p: tuple[tuple[float, ...], ...]) -> None:
    scale = 1.0 + max(abs(value) for row in p for value in row)
    for i in range(STATE_DIM):
        if p[i][i] < 0.0:
            raise ValueError(f"P[{i}][{i}] = {p[i][i]} is a negative variance")
        for j in range(i):
            if abs(p[i][j] - p[j][i]) > _SYMMETRY_RTOL * scale:
                raise ValueError(f"P is not symmetric: P[{i}][{j}]={p[i][j]} P[{j}][{i}]={p[j][i]}")


def _check_models(
    mu: tuple[float, ...] | None,
    model_x: tuple[tuple[float, ...], ...] | None,
    model_p: tuple[tuple[tuple[float, ...], ...], ...] | None,
) -> None:
    given = [v is not None for v in (mu, model_x, model_p)]
    if any(given) and not all(given):
        raise ValueError("mu, model_x and model_P go together: give all three or none")
    if mu is not None and model_x is not None and model_p is not None:
        if not len(mu) == len(model_x) == len(model_p) >= 1:
            raise ValueError(
                "mu, model_x and model_P disagree on the number of models: "
                f"{len(mu)}, {len(model_x)}, {len(model_p)}"
            )
        if abs(math.fsum(mu) - 1.0) > 1e-6:
            raise ValueError(f"mode probabilities must sum to 1, got {math.fsum(mu)}")
        for p in model_p:
            _check_covariance(p)


def _vector(x: ArrayLike) -> tuple[float, ...]:
    array = np.asarray(x, dtype=float)
    if array.shape != (STATE_DIM,):
        raise ValueError(f"x must have shape ({STATE_DIM},), got {array.shape}")
    return tuple(float(v) for v in array)


def _matrix(p: ArrayLike) -> tuple[tuple[float, ...], ...]:
    array = np.asarray(p, dtype=float)
    if array.shape != (STATE_DIM, STATE_DIM):
        raise ValueError(f"P must have shape ({STATE_DIM}, {STATE_DIM}), got {array.shape}")
    return tuple(tuple(float(v) for v in row) for row in array)


class TargetObservation(Message):
    """One position fix of the target in the local frame, with its 1-sigma error."""

    kind: Literal["observation"] = "observation"
    sensor: Name
    vehicle: VehicleId | None = None  # the vehicle whose sensor made it; None for external ones
    east_m: Finite
    north_m: Finite
    sigma_m: Positive


class LocalEstimate(Message):
    """One agent's local filter output (x_i, P_i) at ``t_s``."""

    kind: Literal["estimate.local"] = "estimate.local"
    vehicle: VehicleId
    x: State
    P: Covariance
    q_scale: Positive = 1.0  # the process-noise multiplier the local filter runs with (beta^-1)
    # per IMM model (optional): mode probabilities, states and covariances (modewise fusion)
    mu: Probabilities | None = None
    model_x: ModelStates | None = None
    model_P: ModelCovariances | None = None
    # the time of the fused estimate whose allocation the local filter last took (None: none)
    alloc_t_s: Finite | None = None

    @model_validator(mode="after")
    def _covariance(self) -> Self:
        _check_covariance(self.P)
        _check_models(self.mu, self.model_x, self.model_P)
        return self

    @classmethod
    def from_arrays(
        cls,
        *,
        sender: str,
        t_s: float,
        vehicle: int,
        x: ArrayLike,
        P: ArrayLike,
        q_scale: float = 1.0,
    ) -> LocalEstimate:
        """Build from numpy arrays or nested sequences of shape (6,) and (6, 6)."""
        return cls(
            sender=sender,
            t_s=t_s,
            vehicle=vehicle,
            x=_vector(x),
            P=_matrix(P),
            q_scale=float(q_scale),
        )


class GlobalEstimate(Message):
    """The main filter's fused estimate and each vehicle's information-sharing factor beta_i."""

    kind: Literal["estimate.global"] = "estimate.global"
    x: State
    P: Covariance
    beta: dict[VehicleId, Annotated[float, Field(gt=0.0, le=1.0)]]
    mu: Probabilities | None = None
    model_x: ModelStates | None = None
    model_P: ModelCovariances | None = None
    # per vehicle given a share: the time of its newest own estimate in the fusion (its
    # observations after it are not in; it replays them on top of the allocation)
    included_t_s: dict[VehicleId, Finite] | None = None

    @model_validator(mode="after")
    def _check(self) -> Self:
        _check_covariance(self.P)
        _check_models(self.mu, self.model_x, self.model_P)
        total = math.fsum(self.beta.values())
        if total > 1.0 + 1e-9:
            raise ValueError(f"the beta factors sum to {total}, more than 1")
        return self

    @classmethod
    def from_arrays(
        cls,
        *,
        sender: str,
        t_s: float,
        x: ArrayLike,
        P: ArrayLike,
        beta: Mapping[SupportsInt, SupportsFloat],
    ) -> GlobalEstimate:
        """Build from numpy arrays of shape (6,) and (6, 6) and a vehicle -> beta mapping."""
        return cls(
            sender=sender,
            t_s=t_s,
            x=_vector(x),
            P=_matrix(P),
            beta={int(k): float(b) for k, b in beta.items()},
        )


class MissionState(Message):
    """The ground station's decision: the stage, who flies, and the desired phase spacing."""

    kind: Literal["mission"] = "mission"
    stage: Stage
    active: tuple[VehicleId, ...]
    spacing_rad: Annotated[float, Field(gt=0.0, le=2.0 * math.pi)]

    @model_validator(mode="after")
    def _unique(self) -> Self:
        if len(set(self.active)) != len(self.active):
            raise ValueError(f"active vehicles must be unique, got {self.active}")
        return self


class VehicleStatus(Message):
    """One vehicle's pose, guidance phase and health, published by its agent."""

    kind: Literal["status"] = "status"
    vehicle: VehicleId
    east_m: Finite
    north_m: Finite
    alt_m: Finite  # above the vehicle's home
    up_m: Finite | None = None  # height about the mission origin (separation, 3-D)
    climb_m_s: Finite | None = None  # its climb rate (m/s, up)
    level_up_m: Finite | None = None  # the height about the origin it is sent to (its stack)
    course_rad: Finite  # MAVLink convention: clockwise from north
    speed_m_s: NonNegative
    phase_rad: Finite  # the vehicle's phase angle about the target estimate
    stage: Stage
    link: Literal["ok", "degraded", "lost"]  # the agent's MAVLink link to its vehicle
    healthy: bool
    detail: Annotated[str, Field(max_length=200)] = ""
    # who flies the vehicle: the mission; its pilot (someone else changed its mode, named in
    # ``flight_mode``: the agent sends nothing until ``resume``); or a hold the mission asked for
    control: Literal["mission", "pilot", "hold"] = "mission"
    flight_mode: Annotated[str, Field(max_length=40)] = ""


class LinkState(Message):
    """A client's presence on the bus; registered as its MQTT last will with ``online=False``."""

    kind: Literal["link"] = "link"
    online: bool
    vehicle: VehicleId | None = None
    reason: Annotated[str, Field(max_length=200)] = ""


class MissionEpoch(Message):
    """Ground -> agents (retained): mission time 0 on the wall clock (Unix s) and the mission
    seconds per wall second, so that every process maps its vehicles' boot clocks onto one
    mission clock. ``ended``: the mission this epoch belonged to is over (wait for a new one)."""

    kind: Literal["epoch"] = "epoch"
    epoch_s: Finite
    rate: Annotated[float, Field(gt=0.0, allow_inf_nan=False)] = 1.0
    ended: bool = False


class Command(Message):
    """Ground -> agents: an instruction for some vehicles (all when ``vehicles`` is None)."""

    kind: Literal["command"] = "command"
    command: Literal["hold", "resume", "shutdown"]
    vehicles: tuple[VehicleId, ...] | None = None


AnyMessage = Annotated[
    TargetObservation
    | LocalEstimate
    | GlobalEstimate
    | MissionState
    | VehicleStatus
    | LinkState
    | MissionEpoch
    | Command,
    Field(discriminator="kind"),
]

MESSAGE_TYPES: tuple[type[Message], ...] = (
    TargetObservation,
    LocalEstimate,
    GlobalEstimate,
    MissionState,
    VehicleStatus,
    LinkState,
    MissionEpoch,
    Command,
)
