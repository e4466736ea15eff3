"""Plain values that travel between estimators: observations, local and global estimates.

Local filters (one per vehicle) and the main filter may run in different processes, so what they
exchange is frozen data with a ``to_dict`` / ``from_dict`` pair of JSON-ready plain types
(str, float, lists). ``from_dict`` checks shapes and types and raises ``InputError`` naming the
field; it does not judge values (a non-finite observation is the filter's to reject and count).
"""

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.core.estimation.models import STATE_DIM
from app.errors import InputError

FloatArray = NDArray[np.float64]


def _number(raw: Mapping[str, Any], key: str, kind: str) -> float:
    if key not in raw:
        raise InputError(f"{kind}: missing field {key!r}")
    value = raw[key]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{kind}: field {key!r} must be a number, got {value!r}")
    return float(value)


def _text(raw: Mapping[str, Any], key: str, kind: str) -> str:
    value = raw.get(key)
    if not isinstance(value, str) or not value:
        raise InputError(f"{kind}: field {key!r} must be a non-empty string, got {value!r}")
    return value


def _array(raw: Mapping[str, Any], key: str, kind: str, shape: tuple[int, ...]) -> FloatArray:
    if key not in raw:
        raise InputError(f"{kind}: missing field {key!r}")
    try:
        value = np.array(raw[key], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{kind}: field {key!r} is not numeric: {exc}") from exc
    if value.shape != shape:
        raise InputError(f"{kind}: field {key!r} must have shape {shape}, got {value.shape}")
    if not np.isfinite(value).all():
        raise InputError(f"{kind}: field {key!r} has non-finite entries")
    value.setflags(write=False)
    return value


def _frozen(a: FloatArray) -> FloatArray:
    """A read-only float64 array with the values of ``a`` (``a`` itself if it already is one)."""
    if isinstance(a, np.ndarray) and a.dtype == np.float64 and not a.flags.writeable:
        return a
    out = np.array(a, dtype=np.float64)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, slots=True)
class Observation:
    """A position fix of the target from one sensor (a vehicle's camera), at its own time.

    Attributes
    ----------
    t_s
        When the target was seen, s (mission time).
    sensor
        Who saw it (the vehicle id); the federated estimator routes by it.
    east_m, north_m
        The target's position, m about the mission origin.
    sigma_m
        Standard deviation of each coordinate, m; ``None``: the estimator's default.
    """

    t_s: float
    sensor: str
    east_m: float
    north_m: float
    sigma_m: float | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "t_s": self.t_s,
            "sensor": self.sensor,
            "east_m": self.east_m,
            "north_m": self.north_m,
        }
        if self.sigma_m is not None:
            out["sigma_m"] = self.sigma_m
        return out

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any]) -> "Observation":
        kind = "observation"
        sigma = _number(raw, "sigma_m", kind) if raw.get("sigma_m") is not None else None
        return cls(
            t_s=_number(raw, "t_s", kind),
            sensor=_text(raw, "sensor", kind),
            east_m=_number(raw, "east_m", kind),
            north_m=_number(raw, "north_m", kind),
            sigma_m=sigma,
        )


@dataclass(frozen=True, slots=True)
class LocalEstimate:
    """A local filter's output, sent to the main filter (Appendix A's X_i, P_i).

    Attributes
    ----------
    sensor
        The local filter (vehicle) it comes from.
    t_s
        Time of the estimate, s.
    x
        Combined IMM state X_i = [x, vx, y, vy, ax, ay], shape (6,).
    p
        Its covariance P_i, shape (6, 6).
    mu
        The local IMM's mode probabilities, shape (r,) (for display; not fused).
    q_scale
        The multiple of its own covariance the local filter holds (Appendix A's beta_i^-1
        under feedback, else 1); its Q is scaled by it, and so is the main filter's time update.
    model_x, model_p
        The model-conditioned means (r, 6) and covariances (r, 6, 6) behind ``x`` and ``p``
        (the main filter fuses them model by model in the ``"modewise"`` design).
    alloc_t_s
        The basis: the time of the fused estimate whose information allocation the local filter
        last took (``None`` before any). The main filter fuses an estimate only with copies of
        the allocation it is built on.
    """

    sensor: str
    t_s: float
    x: FloatArray
    p: FloatArray
    mu: FloatArray
    q_scale: float = 1.0
    model_x: FloatArray | None = None
    model_p: FloatArray | None = None
    alloc_t_s: float | None = None

    def __post_init__(self) -> None:
        _freeze_fields(self, ("x", "p", "mu", "model_x", "model_p"))
        if self.x.shape != (STATE_DIM,) or self.p.shape != (STATE_DIM, STATE_DIM):
            raise ValueError("local estimate needs x of shape (6,) and p of shape (6, 6)")
        _check_models(self.mu, self.model_x, self.model_p)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "sensor": self.sensor,
            "t_s": self.t_s,
            "x": self.x.tolist(),
            "p": self.p.tolist(),
            "mu": self.mu.tolist(),
            "q_scale": self.q_scale,
        }
        if self.model_x is not None and self.model_p is not None:
            out["model_x"] = self.model_x.tolist()
            out["model_p"] = self.model_p.tolist()
        if self.alloc_t_s is not None:
            out["alloc_t_s"] = self.alloc_t_s
        return out

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any]) -> "LocalEstimate":
        kind = "local estimate"
        mu_raw = raw.get("mu")
        n_mu = len(mu_raw) if isinstance(mu_raw, list) else -1
        return cls(
            sensor=_text(raw, "sensor", kind),
            t_s=_finite(_number(raw, "t_s", kind), "t_s", kind),
            x=_array(raw, "x", kind, (STATE_DIM,)),
            p=_array(raw, "p", kind, (STATE_DIM, STATE_DIM)),
            mu=_array(raw, "mu", kind, (max(n_mu, 0),)),
            q_scale=_finite(_number(raw, "q_scale", kind), "q_scale", kind)
            if "q_scale" in raw
            else 1.0,
            **_models_from(raw, kind, max(n_mu, 0)),
            alloc_t_s=_finite(_number(raw, "alloc_t_s", kind), "alloc_t_s", kind)
            if raw.get("alloc_t_s") is not None
            else None,
        )


@dataclass(frozen=True, slots=True)
class GlobalEstimate:
    """The main filter's fused estimate and the information shares sent back (Appendix A).

    Attributes
    ----------
    t_s
        Time of the fused estimate, s.
    x
        X_g = P_g sum_i P_i^-1 X_i, shape (6,).
    p
        P_g = (sum_i P_i^-1)^-1, shape (6, 6).
    beta
        Information share beta_i of every fused local filter (sum 1; the main filter keeps 0).
    mu, model_x, model_p
        Fused mode probabilities (r,) and model-conditioned means (r, 6) and covariances
        (r, 6, 6), when the fusion was model by model (else ``None``).
    included_t_s
        For each fused local filter, the time of its newest own estimate in the fusion: its
        observations after that time are not in, and it replays them on top of its allocation.
        A filter not listed replays those after ``t_s``.
    """

    t_s: float
    x: FloatArray
    p: FloatArray
    beta: tuple[tuple[str, float], ...]
    mu: FloatArray | None = None
    model_x: FloatArray | None = None
    model_p: FloatArray | None = None
    included_t_s: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        _freeze_fields(self, ("x", "p", "mu", "model_x", "model_p"))
        object.__setattr__(self, "beta", tuple((str(k), float(v)) for k, v in self.beta))
        object.__setattr__(
            self, "included_t_s", tuple((str(k), float(v)) for k, v in self.included_t_s)
        )
        if self.mu is not None:
            _check_models(self.mu, self.model_x, self.model_p)

    @property
    def position_m(self) -> tuple[float, float]:
        """(east, north) of the fused estimate, m."""
        return float(self.x[0]), float(self.x[2])

    @property
    def velocity_m_s(self) -> tuple[float, float]:
        """(east, north) velocity of the fused estimate, m/s."""
        return float(self.x[1]), float(self.x[3])

    def beta_for(self, sensor: str) -> float | None:
        """This sensor's share, or None if it was not part of the fusion."""
        return dict(self.beta).get(sensor)

    def included_for(self, sensor: str) -> float:
        """The time after which this sensor's observations are not in the fusion."""
        return dict(self.included_t_s).get(sensor, self.t_s)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "t_s": self.t_s,
            "x": self.x.tolist(),
            "p": self.p.tolist(),
            "beta": dict(self.beta),
        }
        if self.mu is not None and self.model_x is not None and self.model_p is not None:
            out["mu"] = self.mu.tolist()
            out["model_x"] = self.model_x.tolist()
            out["model_p"] = self.model_p.tolist()
        if self.included_t_s:
            out["included_t_s"] = dict(self.included_t_s)
        return out

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any]) -> "GlobalEstimate":
        kind = "global estimate"
        beta_raw = raw.get("beta")
        if not isinstance(beta_raw, Mapping):
            raise InputError(f"{kind}: field 'beta' must be a mapping of sensor to share")
        beta = tuple(
            (str(k), _finite(_number(beta_raw, k, kind), f"beta.{k}", kind)) for k in beta_raw
        )
        extra: dict[str, Any] = {}
        if raw.get("mu") is not None:
            mu_raw = raw["mu"]
            n_mu = len(mu_raw) if isinstance(mu_raw, list) else -1
            extra = {"mu": _array(raw, "mu", kind, (max(n_mu, 0),))}
            extra.update(_models_from(raw, kind, max(n_mu, 0)))
        included_raw = raw.get("included_t_s", {})
        if not isinstance(included_raw, Mapping):
            raise InputError(f"{kind}: field 'included_t_s' must be a mapping of sensor to time")
        extra["included_t_s"] = tuple(
            (str(k), _finite(_number(included_raw, k, kind), f"included_t_s.{k}", kind))
            for k in included_raw
        )
        return cls(
            t_s=_finite(_number(raw, "t_s", kind), "t_s", kind),
            x=_array(raw, "x", kind, (STATE_DIM,)),
            p=_array(raw, "p", kind, (STATE_DIM, STATE_DIM)),
            beta=beta,
            **extra,
        )


def _finite(value: float, key: str, kind: str) -> float:
    if not math.isfinite(value):
        raise InputError(f"{kind}: field {key!r} must be finite, got {value!r}")
    return value


def _freeze_fields(obj: object, names: tuple[str, ...]) -> None:
    for name in names:
        value = getattr(obj, name)
        if value is not None:
            object.__setattr__(obj, name, _frozen(value))


def _check_models(mu: FloatArray, xs: FloatArray | None, ps: FloatArray | None) -> None:
    r = mu.shape[0]
    if (xs is None) != (ps is None):
        raise ValueError("model_x and model_p come together")
    if (
        xs is not None
        and ps is not None
        and (xs.shape != (r, STATE_DIM) or ps.shape != (r, STATE_DIM, STATE_DIM))
    ):
        raise ValueError(f"model_x must be ({r}, 6) and model_p ({r}, 6, 6)")


def _models_from(raw: Mapping[str, Any], kind: str, r: int) -> dict[str, FloatArray]:
    if raw.get("model_x") is None and raw.get("model_p") is None:
        return {}
    return {
        "model_x": _array(raw, "model_x", kind, (r, STATE_DIM)),
        "model_p": _array(raw, "model_p", kind, (r, STATE_DIM, STATE_DIM)),
    }
