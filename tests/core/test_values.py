"""``app.core.values.replace`` gives what ``dataclasses.replace`` gives, faster."""

import dataclasses
import itertools
from collections.abc import Sequence

import numpy as np
import pytest

from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.core import values
from app.core.estimation.imm import default_imm_params, imm_init
from app.core.estimation.local import LocalState
from app.core.mission.agent import JoinPath, MissionAgentState, initial_agent_state
from app.core.mission.schedule import Every
from app.core.values import replace


@pytest.fixture(scope="module")
def state() -> MissionAgentState:
    plan = build_plan(load_config("hil", MissionConfig))
    return initial_agent_state(plan.agents[0])


def test_a_copy_with_changes_equals_what_dataclasses_replace_makes(
    state: MissionAgentState,
) -> None:
    before = state.now_t_s
    ours = replace(state, now_t_s=before + 12.5, stage=state.stage)
    theirs = dataclasses.replace(state, now_t_s=before + 12.5, stage=state.stage)
    assert ours == theirs
    assert ours is not state
    assert ours.now_t_s == before + 12.5
    assert state.now_t_s == before  # the input is left alone
    # and the agent's state is one the slots are copied for, not dataclasses.replace's walk
    assert values._REPLACERS[MissionAgentState] is not values._by_dataclasses
    for f in dataclasses.fields(state):
        if f.name != "now_t_s":
            assert getattr(ours, f.name) is getattr(state, f.name), f.name


def test_a_copy_without_changes_is_an_equal_new_value() -> None:
    path = JoinPath(((0.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)), 1.0, 15.0)
    copy = replace(path)
    assert copy == path
    assert copy is not path
    assert replace(path, progress=1).progress == 1
    assert path.progress == 0


def test_the_copy_stays_frozen() -> None:
    path = replace(JoinPath(((0.0, 0.0, 0.0, 0.0),), 0.0, 15.0), length_m=2.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        path.length_m = 3.0  # type: ignore[misc]


def test_a_name_that_is_not_a_field_is_a_type_error(state: MissionAgentState) -> None:
    with pytest.raises(TypeError, match="no_such_field"):
        replace(state, no_such_field=1)  # type: ignore[call-arg]
    with pytest.raises(TypeError):
        dataclasses.replace(state, no_such_field=1)  # type: ignore[call-arg]


def test_a_class_that_checks_itself_is_still_checked() -> None:
    every = Every(period_s=1.0)
    assert replace(every, period_s=2.0).period_s == 2.0
    with pytest.raises(ValueError):
        replace(every, period_s=-1.0)


def test_a_cached_estimate_is_not_carried_into_a_copy_with_another_filter_state() -> None:
    params = default_imm_params()
    first = LocalState("1", imm_init(1.0, np.zeros(6), np.eye(6), params))
    moved = imm_init(2.0, np.array([5.0, 1.0, -3.0, 0.0, 0.0, 0.0]), np.eye(6), params)
    before = first.estimate()
    assert before is not None
    assert first.estimate() is before  # worked out once per state
    second = replace(first, imm=moved)
    after = second.estimate()
    assert after is not None
    assert after.t_s == 2.0
    np.testing.assert_allclose(after.x, moved.x[0])
    assert first.estimate() is before
    # a field left out of __init__ starts as __init__ leaves it, on both ways of copying
    assert dataclasses.replace(first, imm=moved) == second
    assert second.consecutive_gated == first.consecutive_gated


def _sent_at(every: Every, times: Sequence[float]) -> list[float]:
    """The times of ``times`` at which ``every`` was due (and so sent)."""
    out = []
    for t in times:
        if every.due(t):
            every = every.sent(t)
            out.append(t)
    return out


def test_a_schedule_paced_by_times_a_period_apart_skips_none_of_them() -> None:
    # statuses of three vehicles a few ms apart, each vehicle's 0.1 s apart as sums of floats
    # give them: the station's tick must come every 0.1 s, not every 0.2 s now and then
    times = sorted(
        sum([0.1] * k, start=11.6) + offset for k in range(400) for offset in (0.0, 0.0024, 0.0036)
    )
    ticks = _sent_at(Every(0.1), times)
    gaps = [b - a for a, b in itertools.pairwise(ticks)]
    assert len(ticks) == 400
    assert max(gaps) < 0.1 + 0.004
    # one vehicle alone, its frames 0.1 s apart give or take a ms of clock jitter
    jitter = [0.1 * k + (0.001 if k % 3 == 1 else -0.001 if k % 3 == 2 else 0.0) for k in range(50)]
    assert len(_sent_at(Every(0.1), jitter)) == 50


def test_a_schedule_keeps_its_rate_and_starts_again_after_a_gap() -> None:
    fast_frames = [0.02 * k for k in range(500)]  # 50 Hz telemetry paces a 0.2 s schedule
    sent = _sent_at(Every(0.2), fast_frames)
    gaps = [b - a for a, b in itertools.pairwise(sent[1:])]
    # five a second: each a frame of the slot's time at most, none a slot late
    assert len(gaps) == 49
    assert all(abs(g - 0.2) < 0.02 + 1e-9 for g in gaps)
    assert abs(sent[-1] - sent[1] - 49 * 0.2) < 0.02 + 1e-9
    # a silence of 3 s: the first time after it is due at once, the grid restarts there
    after_gap = _sent_at(Every(0.5), [0.0, 0.5, 1.0, 4.2, 4.3, 4.7, 5.2])
    assert after_gap == [0.0, 0.5, 1.0, 4.2, 4.7, 5.2]
    # period 0: every time
    assert _sent_at(Every(0.0), [1.0, 1.0, 1.1]) == [1.0, 1.0, 1.1]


def test_a_schedule_taken_late_starts_again_and_never_sends_twice_within_half_a_period() -> None:
    # the statuses of the slot at 0.4 s came late (the first at 0.46 s): the next slot is a
    # period after that one, and the status at 0.49 s, just inside the 0.5 s slot's early
    # allowance, does not catch up
    times = [0.0, 0.1, 0.2, 0.3, 0.46, 0.49, 0.5, 0.6, 0.7]
    sent = _sent_at(Every(0.1), times)
    assert sent == [0.0, 0.1, 0.2, 0.3, 0.46, 0.6, 0.7]
    gaps = [b - a for a, b in itertools.pairwise(sent)]
    assert min(gaps) > 0.05
