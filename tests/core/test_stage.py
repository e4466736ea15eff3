import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from app.core.mission.stage import (
    Stage,
    StageParams,
    StageState,
    TeamView,
    adjacent_phase_gaps,
    next_stage,
    spacing_errors,
)

PARAMS = StageParams(dwell_s=5.0)
EVEN = (0.0, 2 * math.pi / 3, 4 * math.pi / 3)


@given(st.lists(st.floats(min_value=-20.0, max_value=20.0), min_size=1, max_size=12))
def test_gaps_cover_the_circle(angles):
    gaps = adjacent_phase_gaps(angles)
    assert len(gaps) == len(angles)
    assert all(g >= 0.0 for g in gaps)
    assert math.isclose(sum(gaps), 2 * math.pi, rel_tol=1e-9)
    assert math.isclose(sum(spacing_errors(angles)), 0.0, abs_tol=1e-9)


def test_even_spacing_has_no_error_in_any_order():
    assert spacing_errors((EVEN[2], EVEN[0], EVEN[1])) == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    # 0, 30 and 50 degrees, the paper's phase scenario start: gaps 30, 20, 310
    errs = spacing_errors(tuple(math.radians(d) for d in (0.0, 30.0, 50.0)))
    assert [math.degrees(e) for e in errs] == pytest.approx([-90.0, -100.0, 190.0])


def team(dist, angles=EVEN, speed=0.0):
    return TeamView(tuple(dist), tuple(angles), speed)


def test_stages_run_forward_through_gather_adjust_track():
    s = StageState()
    s = next_stage(s, 1.0, False, team([500.0] * 3), PARAMS)
    assert s.stage is Stage.STANDBY
    s = next_stage(s, 2.0, True, team([500.0] * 3), PARAMS)
    assert (s.stage, s.since_t_s) == (Stage.GATHER, 2.0)
    s = next_stage(s, 30.0, True, team([20.0, 5.0, 1.0]), PARAMS)
    assert s.stage is Stage.GATHER  # one vehicle still 20 m off
    s = next_stage(s, 40.0, True, team([10.0, 5.0, 1.0], (0.0, 0.5, 1.0)), PARAMS)
    assert s.stage is Stage.ADJUST
    s = next_stage(s, 60.0, True, team([1.0, 2.0, 1.0]), PARAMS)
    assert s.stage is Stage.ADJUST
    assert s.formed_since_t_s == 60.0
    s = next_stage(s, 64.0, True, team([1.0, 2.0, 1.0]), PARAMS)
    assert s.stage is Stage.ADJUST
    s = next_stage(s, 65.0, True, team([1.0, 2.0, 1.0]), PARAMS)
    assert (s.stage, s.since_t_s) == (Stage.TRACK, 65.0)
    s = next_stage(s, 70.0, True, team([50.0] * 3, (0.0, 0.1, 0.2)), PARAMS)
    assert s.stage is Stage.TRACK  # never back


def test_leaving_formation_restarts_the_dwell():
    s = StageState(Stage.ADJUST, 0.0)
    s = next_stage(s, 10.0, True, team([1.0] * 3), PARAMS)
    s = next_stage(s, 12.0, True, team([4.0, 1.0, 1.0]), PARAMS)
    assert s.formed_since_t_s is None
    s = next_stage(s, 13.0, True, team([1.0] * 3), PARAMS)
    s = next_stage(s, 17.0, True, team([1.0] * 3), PARAMS)
    assert s.stage is Stage.ADJUST
    s = next_stage(s, 18.0, True, team([1.0] * 3), PARAMS)
    assert s.stage is Stage.TRACK


def test_a_moving_target_ends_the_adjust_stage():
    s = StageState(Stage.ADJUST, 0.0)
    s = next_stage(s, 1.0, True, team([30.0] * 3, (0.0, 0.1, 0.2), speed=3.0), PARAMS)
    assert s.stage is Stage.TRACK


def test_a_target_moving_for_the_dwell_ends_the_gather_stage() -> None:
    s = StageState(Stage.GATHER, 0.0)
    far = [400.0, 20.0, 5.0]  # one vehicle still far out: not arrived
    s = next_stage(s, 100.0, True, team(far, speed=3.0), PARAMS)
    assert (s.stage, s.moving_since_t_s) == (Stage.GATHER, 100.0)
    s = next_stage(s, 102.0, True, team(far, speed=0.5), PARAMS)  # one slow estimate
    assert (s.stage, s.moving_since_t_s) == (Stage.GATHER, None)
    for t in (103.0, 105.0, 107.9):
        s = next_stage(s, t, True, team(far, speed=3.0), PARAMS)
        assert s.stage is Stage.GATHER
    s = next_stage(s, 108.0, True, team(far, speed=3.0), PARAMS)
    assert (s.stage, s.since_t_s) == (Stage.TRACK, 108.0)


def test_an_empty_team_never_counts_as_formed_or_arrived():
    s = next_stage(StageState(Stage.GATHER, 0.0), 1.0, True, TeamView((), (), 0.0), PARAMS)
    assert s.stage is Stage.GATHER


def test_bad_params_are_refused():
    with pytest.raises(ValueError, match="dwell_s"):
        StageParams(dwell_s=-1.0)
    with pytest.raises(ValueError, match="radius_tolerance_m"):
        StageParams(radius_tolerance_m=math.nan)
