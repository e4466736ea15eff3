"""Estimates cross the bus (and a JSON round trip) with every number intact."""

import numpy as np

from app.adapters.bus import codec
from app.core.estimation import messages as est
from app.runtime.wire import global_to_bus, global_to_core, local_to_bus, local_to_core


def spd(rng, n=6):
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


def through_json(message):
    return codec.decode(codec.encode(message))


def test_local_estimate_with_models_round_trips():
    rng = np.random.default_rng(3)
    local = est.LocalEstimate(
        "2",
        12.5,
        rng.normal(size=6),
        spd(rng),
        np.array([0.7, 0.2, 0.1]),
        q_scale=2.5,
        model_x=rng.normal(size=(3, 6)),
        model_p=np.stack([spd(rng) for _ in range(3)]),
        alloc_t_s=12.25,
    )
    back = local_to_core(through_json(local_to_bus(local, 2, "agent-3")))
    assert back.sensor == "2"
    assert back.t_s == 12.5
    assert back.q_scale == 2.5
    assert back.alloc_t_s == 12.25
    for name in ("x", "p", "mu", "model_x", "model_p"):
        assert np.allclose(getattr(back, name), getattr(local, name), rtol=0, atol=1e-12), name


def test_global_estimate_round_trips_and_plain_ones_stay_plain():
    rng = np.random.default_rng(4)
    fused = est.GlobalEstimate(
        3.0, rng.normal(size=6), spd(rng), (("0", 0.5), ("1", 0.25), ("2", 0.25))
    )
    message = through_json(global_to_bus(fused, "ground"))
    assert message.beta == {0: 0.5, 1: 0.25, 2: 0.25}
    assert message.model_x is None
    assert message.included_t_s is None
    back = global_to_core(message)
    assert back.beta == fused.beta
    assert back.model_x is None
    assert back.included_t_s == ()
    assert np.allclose(back.p, fused.p, atol=1e-12)


def test_the_allocation_basis_round_trips():
    """A local estimate says which allocation it is built on (None before any); an allocation
    says up to when each filter's own estimates are in it."""
    rng = np.random.default_rng(5)
    before = est.LocalEstimate("1", 2.0, rng.normal(size=6), spd(rng), np.array([1.0]))
    message = through_json(local_to_bus(before, 1, "agent-2"))
    assert message.alloc_t_s is None
    assert local_to_core(message).alloc_t_s is None
    fused = est.GlobalEstimate(
        3.0,
        rng.normal(size=6),
        spd(rng),
        (("0", 0.5), ("1", 0.5)),
        included_t_s=(("0", 2.75), ("1", 2.5)),
    )
    message = through_json(global_to_bus(fused, "ground"))
    assert message.included_t_s == {0: 2.75, 1: 2.5}
    back = global_to_core(message)
    assert back.included_t_s == fused.included_t_s
    assert back.included_for("1") == 2.5
    assert back.included_for("7") == 3.0
