"""Faults in the pure mission logic: the observations stop, and the fused estimate coasts.

The end-to-end version (every camera of the simulator switched off mid-track) is in
``test_mission_e2e.py``; these tests pin the ground station's part of it without I/O.
"""

import itertools
import math

import numpy as np
import pytest

from app.core.estimation.federated import MainParams
from app.core.estimation.messages import GlobalEstimate, LocalEstimate
from app.core.mission.ground import (
    GroundParams,
    GroundState,
    VehicleReport,
    coast,
    hear_local,
    hear_status,
    tick,
)

RADIUS_M = 90.0
V_NORTH_M_S = 3.0
A_NORTH_M_S2 = 0.4  # what a lagging filter may still hold just after a target stopped speeding up


def params(feedback: str) -> GroundParams:
    return GroundParams(
        vehicles=(0, 1, 2),
        radius_m=RADIUS_M,
        tracking_command_t_s=0.0,
        main=MainParams(feedback=feedback),  # type: ignore[arg-type]
    )


def local(vehicle: int, t: float) -> LocalEstimate:
    """A local estimate of a target driving north at 3 m/s (state [x, vx, y, vy, ax, ay])."""
    x = np.array([0.0, 0.0, V_NORTH_M_S * t, V_NORTH_M_S, 0.0, A_NORTH_M_S2])
    return LocalEstimate(
        str(vehicle), t, x, np.diag([4.0, 0.5, 4.0, 0.5, 0.1, 0.1]), np.array([1.0])
    )


def statuses(state: GroundState, t: float) -> GroundState:
    for v in range(3):
        a = 2.0 * math.pi * v / 3.0
        report = VehicleReport(t, RADIUS_M * math.cos(a), RADIUS_M * math.sin(a), -a, 14.0)
        state = hear_status(state, v, report)
    return state


def fly(feedback: str, seen_until_s: float, until_s: float) -> list[tuple[float, GlobalEstimate]]:
    """Ground ticks every 0.1 s; local estimates every 0.2 s until ``seen_until_s``."""
    p = params(feedback)
    state = GroundState()
    published: list[tuple[float, GlobalEstimate]] = []
    for k in range(round(until_s / 0.1) + 1):
        t = 0.1 * k
        state = statuses(state, t)
        if t <= seen_until_s + 1e-9 and k % 2 == 0:
            for v in range(3):
                state = hear_local(state, local(v, t))
        state, fused, _ = tick(state, p)
        if fused is not None:
            published.append((t, fused))
    return published


@pytest.mark.parametrize("feedback", ["none", "mixture"])
def test_without_local_estimates_the_fused_estimate_coasts_at_constant_velocity(
    feedback: str,
) -> None:
    published = fly(feedback, seen_until_s=10.0, until_s=50.0)
    after = [(t, f) for t, f in published if t > 10.0]
    # one fused estimate every fuse period to the end: never a silence that would send the
    # agents back to their standby loiter
    times = [t for t, _ in after]
    assert times[-1] >= 50.0 - 0.2
    # (a fuse period of 0.2 s, on ticks 0.1 s apart)
    assert max(b - a for a, b in zip([10.0, *times], times, strict=False)) <= 0.3 + 1e-9
    for t, f in after:
        assert f.t_s == pytest.approx(t)
    # constant velocity: the 0.4 m/s^2 last estimated is not extrapolated over 40 s (it would
    # make the target 19 m/s fast, beyond what the vehicles can follow)
    speeds = [math.hypot(*f.velocity_m_s) for _, f in after]
    assert max(speeds) <= V_NORTH_M_S + A_NORTH_M_S2 * 1.2
    assert speeds[-1] == pytest.approx(speeds[len(speeds) // 2])
    final = after[-1][1]
    north_at_cut = V_NORTH_M_S * 10.0
    assert final.position_m[1] == pytest.approx(north_at_cut + 40.0 * speeds[-1], abs=1.0)
    # a growing covariance
    variances = [float(f.p[2, 2]) for _, f in after]
    assert all(b > a for a, b in itertools.pairwise(variances))
    assert variances[-1] > 100.0 * variances[0]


def test_the_fused_estimate_is_fused_again_once_local_estimates_return() -> None:
    p = params("mixture")
    state = GroundState()
    for k in range(301):  # seen until 10 s, then 20 s blind
        t = 0.1 * k
        state = statuses(state, t)
        if t <= 10.0 and k % 2 == 0:
            for v in range(3):
                state = hear_local(state, local(v, t))
        state, _, _ = tick(state, p)
    assert state.fused is not None
    blind_north_m = state.fused.position_m[1]
    # the target is seen again, where it really is (it stopped at 40 m north)
    t = 30.2  # the next fusion
    state = statuses(state, t)
    stopped = LocalEstimate(
        "0", t, np.array([0.0, 0.0, 40.0, 0.0, 0.0, 0.0]), np.eye(6), np.array([1.0])
    )
    state = hear_local(state, stopped)
    state, fused, _ = tick(state, p)
    assert fused is not None
    # fused with the coasted copies, dominated by the fresh, far more certain estimate
    assert abs(fused.position_m[1] - 40.0) < 0.05 * abs(blind_north_m - 40.0)


def test_coast_predicts_every_model_when_the_fusion_was_model_by_model() -> None:
    fused = fly("mixture", seen_until_s=1.0, until_s=1.0)[-1][1]
    x, p = np.asarray(fused.x), np.asarray(fused.p)
    modes = GlobalEstimate(
        t_s=1.0,
        x=x,
        p=p,
        beta=(("0", 1.0),),
        mu=np.array([0.5, 0.5]),
        model_x=np.stack([x, x]),
        model_p=np.stack([p, p]),
    )
    later = coast(modes, 3.0, params("mixture").coast_model)
    assert later.t_s == 3.0
    assert later.model_x is not None
    assert later.model_p is not None
    assert np.allclose(later.model_x[0], later.x)
    assert np.allclose(later.model_p[1], later.p)
    assert coast(modes, 1.0, params("mixture").coast_model) is modes
