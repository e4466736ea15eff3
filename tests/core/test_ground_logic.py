import math
from dataclasses import replace

import numpy as np
import pytest

from app.core.estimation.federated import MainParams
from app.core.estimation.messages import LocalEstimate
from app.core.mission.ground import (
    GroundParams,
    GroundState,
    HeardStatuses,
    VehicleReport,
    hear_local,
    hear_status,
    step,
    tick,
)
from app.core.mission.stage import Stage

PARAMS = GroundParams(
    vehicles=(0, 1, 2), radius_m=90.0, tracking_command_t_s=10.0, main=MainParams(feedback="none")
)


def on_circle(t, vehicle, angle_deg):
    a = math.radians(angle_deg)
    return VehicleReport(t, 90.0 * math.cos(a), 90.0 * math.sin(a), -a, 14.0)


def local(vehicle, t, east=0.0, north=0.0, var=4.0):
    x = np.array([east, 0.0, north, 0.0, 0.0, 0.0])
    return LocalEstimate(str(vehicle), t, x, np.eye(6) * var, np.array([1.0]))


def run(state, t, angles=(0.0, 120.0, 240.0), vehicles=(0, 1, 2)):
    for v in vehicles:
        state = hear_status(state, v, on_circle(t, v, angles[v]))
        state = hear_local(state, local(v, t))
    return tick(state, PARAMS)


def test_fusion_of_three_equal_estimates_thirds_the_covariance():
    state, fused, _ = run(GroundState(), 1.0)
    assert fused is not None
    assert np.allclose(fused.p, np.eye(6) * 4.0 / 3.0)
    assert dict(fused.beta) == pytest.approx({"0": 1 / 3, "1": 1 / 3, "2": 1 / 3})
    assert state.active == (0, 1, 2)


def test_stages_follow_the_tracking_command_and_the_formation():
    state = GroundState()
    kinds = []
    for k in range(200):
        state, _, events = run(state, 0.1 * k)
        kinds += [(round(e.t_s, 1), e.kind, e.detail) for e in events if e.kind == "stage"]
    # standby until t = 10 s; the team is already on the circle, so gather ends at once and
    # adjust after the 5 s dwell in formation
    assert kinds == [(10.0, "stage", "gather"), (10.1, "stage", "adjust"), (15.1, "stage", "track")]
    assert state.stage.stage is Stage.TRACK


def test_a_silent_vehicle_leaves_and_rejoins():
    state = GroundState()
    state, _, events = run(state, 0.0)
    left = []
    for k in range(1, 40):
        state, _, events = run(state, 0.1 * k, vehicles=(0, 2))
        left += [e for e in events if e.kind == "vehicle_left"]
    assert [e.detail for e in left] == ["vehicle 2 left the formation"]  # index 1, number 2
    assert left[0].t_s == pytest.approx(2.1)  # more than lost_after_s = 2 s behind
    assert state.active == (0, 2)
    state, _, events = run(state, 4.0)
    assert [e.kind for e in events] == ["vehicle_joined"]
    assert state.active == (0, 1, 2)


def test_a_vehicle_reporting_a_lost_link_is_left_out():
    state, _, _ = run(GroundState(), 0.0)
    report = VehicleReport(0.1, 90.0, 0.0, 0.0, 14.0, link_ok=False)
    state = hear_status(state, 0, report)
    state, _, events = tick(state, PARAMS)
    assert state.active == (1, 2)
    assert events[0].kind == "vehicle_left"


def test_older_reports_never_replace_newer_ones():
    state = hear_status(GroundState(), 0, on_circle(5.0, 0, 0.0))
    assert hear_status(state, 0, on_circle(4.0, 0, 90.0)) is state


def test_bad_params_are_refused():
    with pytest.raises(ValueError, match="unique"):
        GroundParams(vehicles=(0, 0), radius_m=90.0, tracking_command_t_s=0.0)
    with pytest.raises(ValueError, match="radius_m"):
        GroundParams(vehicles=(0,), radius_m=-1.0, tracking_command_t_s=0.0)


def test_allocations_go_out_once_per_feedback_period_and_fusions_between_without_shares():
    """The ground fuses every 0.2 s but allocates every 1 s: the fused estimates between go
    out with no shares (nothing for the agents to take), and the main filter keeps fusing
    its copies of the last allocation with estimates built on it."""
    params = GroundParams(
        vehicles=(0, 1, 2),
        radius_m=90.0,
        tracking_command_t_s=10.0,
        main=MainParams(feedback="mixture"),
        feedback_period_s=1.0,
    )
    state = GroundState()
    shared = []
    for k in range(11):
        t = 0.1 * k
        for v in (0, 1, 2):
            state = hear_status(state, v, on_circle(t, v, 120.0 * v))
            basis = None if state.main.shared is None else state.main.shared.t_s
            state = hear_local(state, replace(local(v, t), alloc_t_s=basis))
        state, fused, _ = tick(state, params)
        if fused is not None:
            shared.append((round(t, 1), bool(fused.beta)))
    assert shared == [
        (0.0, True),
        (0.2, False),
        (0.4, False),
        (0.6, False),
        (0.8, False),
        (1.0, True),
    ]
    assert state.main.stale_basis_dropped == 0
    # an estimate built before the last allocation is refused
    state = hear_local(state, replace(local(0, 1.05), alloc_t_s=0.0))
    assert state.main.stale_basis_dropped == 1


@pytest.mark.parametrize("t0", [11.6, 100.0, 237.2053])
def test_the_ground_fuses_every_fuse_period_when_statuses_come_a_rounding_error_early(t0):
    """Three vehicles' statuses and local estimates, each vehicle's 0.1 s apart as the sums
    of floats a clock gives (a few ms between vehicles): the station ticks every 0.1 s and
    fuses every 0.2 s, none a tick late (a tick a hair short of the next fusion's time once
    put it off to the tick after: from 100 s on, every 0.3 s), and at the first tick after
    each round of estimates (a grid of its own once fused them a tick later)."""
    state = GroundState()
    fusions = []
    for k in range(200):
        for v, offset in enumerate((0.0, 0.001, 0.0037)):
            t = sum([0.1] * k, start=t0) + offset
            heard = HeardStatuses(((v, on_circle(t, v, 120.0 * v)),))
            state, out = step(state, heard, PARAMS)
            if out.fused is not None:
                fusions.append(out.fused.t_s)
            if k % 2 == 0:
                state = hear_local(state, local(v, t))
    # the estimates of every other tick came after its statuses (as a camera fix comes after
    # the telemetry of its instant): each round is fused at the next tick, every 0.2 s
    assert len(fusions) == 100
    assert np.diff(fusions).max() < 0.2 + 0.005
    assert fusions[:3] == pytest.approx([t0 + 0.1, t0 + 0.3, t0 + 0.5])


def test_the_ground_fuses_a_round_of_estimates_at_the_tick_it_is_in_and_predicts_without():
    """Estimates heard before the statuses of their instant (the fast simulation's order) are
    fused at that very tick; with no estimate new, the fused estimate is still brought forward
    every fuse period and a half (0.3 s) for the agents to steer by."""
    state = GroundState()
    fusions = []
    for k in range(40):
        t = 0.1 * k
        for v in (0, 1, 2):
            if k % 2 == 1 and k < 20:
                state = hear_local(state, local(v, t))
        for v in (0, 1, 2):
            heard = HeardStatuses(((v, on_circle(t, v, 120.0 * v)),))
            state, out = step(state, heard, PARAMS)
            if out.fused is not None:
                fusions.append(round(out.fused.t_s, 6))
    assert fusions[:10] == pytest.approx([0.1, 0.3, 0.5, 0.7, 0.9, 1.1, 1.3, 1.5, 1.7, 1.9])
    assert fusions[10:] == pytest.approx([2.2, 2.5, 2.8, 3.1, 3.4, 3.7])
