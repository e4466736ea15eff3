"""Conversions between the bus's messages and the core's values (one place, both directions)."""

import numpy as np

from app.adapters.bus import messages as bus
from app.core.estimation import messages as est


def observation_to_core(message: bus.TargetObservation, vehicle: int) -> est.Observation:
    return est.Observation(
        t_s=message.t_s,
        sensor=str(vehicle),
        east_m=message.east_m,
        north_m=message.north_m,
        sigma_m=message.sigma_m,
    )


def local_to_bus(estimate: est.LocalEstimate, vehicle: int, sender: str) -> bus.LocalEstimate:
    return bus.LocalEstimate.from_arrays(
        sender=sender,
        t_s=estimate.t_s,
        vehicle=vehicle,
        x=estimate.x,
        P=estimate.p,
        q_scale=estimate.q_scale,
    )


def local_to_core(message: bus.LocalEstimate) -> est.LocalEstimate:
    return est.LocalEstimate(
        sensor=str(message.vehicle),
        t_s=message.t_s,
        x=np.array(message.x),
        p=np.array(message.P),
        mu=np.zeros(0),
        q_scale=message.q_scale,
    )


def global_to_bus(estimate: est.GlobalEstimate, sender: str) -> bus.GlobalEstimate:
    return bus.GlobalEstimate.from_arrays(
        sender=sender,
        t_s=estimate.t_s,
        x=estimate.x,
        P=estimate.p,
        beta={int(sensor): share for sensor, share in estimate.beta if share > 0.0},
    )


def global_to_core(message: bus.GlobalEstimate) -> est.GlobalEstimate:
    return est.GlobalEstimate(
        t_s=message.t_s,
        x=np.array(message.x),
        p=np.array(message.P),
        beta=tuple((str(v), share) for v, share in sorted(message.beta.items())),
    )
