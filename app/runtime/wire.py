"""Conversions between the bus's messages and the core's values (one place, both directions).

Estimates travel with their per-model moments when the filter has them, so that the main
filter's model-by-model ("modewise") fusion and feedback work across processes.
"""

from typing import Any

import numpy as np

from app.core.estimation import messages as est
from app.runtime.ports import messages as bus


def _nested(a: Any) -> Any:
    """An array's values as nested tuples of Python floats (what the messages' fields hold)."""
    array = np.asarray(a, dtype=np.float64)
    return _tuples(array.tolist(), array.ndim)


def _tuples(values: Any, ndim: int) -> Any:
    if ndim <= 1:
        return tuple(values) if ndim == 1 else values
    if ndim == 2:
        return tuple(map(tuple, values))
    return tuple(_tuples(v, ndim - 1) for v in values)


def _models(mu: Any, model_x: Any, model_p: Any) -> dict[str, Any]:
    if mu is None or model_x is None or model_p is None:
        return {}
    return {
        "mu": _nested(mu),
        "model_x": _nested(model_x),
        "model_P": _nested(model_p),
    }


def _arrays(message: bus.LocalEstimate | bus.GlobalEstimate) -> dict[str, Any]:
    if message.mu is None or message.model_x is None or message.model_P is None:
        return {}
    return {
        "mu": np.array(message.mu),
        "model_x": np.array(message.model_x),
        "model_p": np.array(message.model_P),
    }


def observation_to_core(message: bus.TargetObservation, vehicle: int) -> est.Observation:
    return est.Observation(
        t_s=message.t_s,
        sensor=str(vehicle),
        east_m=message.east_m,
        north_m=message.north_m,
        sigma_m=message.sigma_m,
    )


def local_to_bus(estimate: est.LocalEstimate, vehicle: int, sender: str) -> bus.LocalEstimate:
    return bus.LocalEstimate(
        sender=sender,
        t_s=estimate.t_s,
        vehicle=vehicle,
        x=_nested(estimate.x),
        P=_nested(estimate.p),
        q_scale=estimate.q_scale,
        alloc_t_s=estimate.alloc_t_s,
        **_models(estimate.mu, estimate.model_x, estimate.model_p),
    )


def local_to_core(message: bus.LocalEstimate) -> est.LocalEstimate:
    models = _arrays(message)
    return est.LocalEstimate(
        sensor=str(message.vehicle),
        t_s=message.t_s,
        x=np.array(message.x),
        p=np.array(message.P),
        mu=models.pop("mu", np.zeros(0)),
        q_scale=message.q_scale,
        alloc_t_s=message.alloc_t_s,
        **models,
    )


def global_to_bus(estimate: est.GlobalEstimate, sender: str) -> bus.GlobalEstimate:
    return bus.GlobalEstimate(
        sender=sender,
        t_s=estimate.t_s,
        x=_nested(estimate.x),
        P=_nested(estimate.p),
        beta={int(sensor): share for sensor, share in estimate.beta if share > 0.0},
        included_t_s={int(sensor): t for sensor, t in estimate.included_t_s} or None,
        **_models(estimate.mu, estimate.model_x, estimate.model_p),
    )


def global_to_core(message: bus.GlobalEstimate) -> est.GlobalEstimate:
    return est.GlobalEstimate(
        t_s=message.t_s,
        x=np.array(message.x),
        p=np.array(message.P),
        beta=tuple((str(v), share) for v, share in sorted(message.beta.items())),
        included_t_s=tuple((str(v), t) for v, t in sorted((message.included_t_s or {}).items())),
        **_arrays(message),
    )
