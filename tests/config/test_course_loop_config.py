"""The mission file's course_loop_identification key reaches every agent."""

import pytest

from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan


@pytest.mark.parametrize(
    ("value", "identifies", "flies"),
    [("fly", True, True), ("report", True, False), ("off", False, False)],
)
def test_course_loop_identification_selects_the_agents_identifier(
    value: str, identifies: bool, flies: bool
) -> None:
    base = load_config("test-short", MissionConfig)
    config = base.model_copy(
        update={"guidance": base.guidance.model_copy(update={"course_loop_identification": value})}
    )
    plan = build_plan(config)
    for agent in plan.agents:
        assert (agent.course_id is not None) is identifies
        assert agent.fly_identified is flies
        if agent.course_id is not None:
            # W is the envelope's: saturation is judged against the vehicle's own limit
            envelope = agent.agent.envelope
            assert agent.course_id.max_rate_rad_s == envelope.max_course_rate_rad_s


def test_an_unknown_course_loop_identification_is_refused() -> None:
    with pytest.raises(ValueError, match="course_loop_identification"):
        MissionConfig.model_validate(
            {
                **load_config("test-short", MissionConfig).model_dump(),
                "guidance": {"course_loop_identification": "sometimes"},
            }
        )
