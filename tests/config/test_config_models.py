import pytest
from pydantic import BaseModel

from app.config import validate_config
from app.config.schema import LimitsConfig, TargetConfig
from app.errors import ConfigError


class Holder(BaseModel):
    target: TargetConfig
    limits: LimitsConfig


LIMITS = {"cruise_speed_m_s": 14.0, "min_speed_m_s": 10.0, "max_speed_m_s": 18.0}
GOOD = {
    "limits": LIMITS,
    "target": {
        "kind": "waypoints",
        "wait_s": 5.0,
        "legs": [{"to_east_m": 0.0, "to_north_m": 100.0, "speed_m_s": 7.0, "label": "A-B"}],
    },
}


def test_a_valid_config_builds_core_values():
    cfg = validate_config(GOOD, Holder)
    path = cfg.target.build()
    assert path.labels == ("wait", "A-B")
    assert cfg.limits.build().max_course_rate_rad_s == 0.2


@pytest.mark.parametrize(
    ("patch", "needle"),
    [
        (
            {"limits": {"cruise_speed_m_s": 20.0, "min_speed_m_s": 10.0, "max_speed_m_s": 18.0}},
            "cruise_speed_m_s",
        ),
        ({"limits": {**LIMITS, "max_accel_m_s2": -1.0}}, "limits.max_accel_m_s2"),
        ({"limits": {**LIMITS, "typo_m_s": 1.0}}, "typo_m_s"),
        ({"target": {"kind": "teleport"}}, "target"),
        ({"target": {"kind": "waypoints", "legs": []}}, "target.waypoints.legs"),
    ],
)
def test_bad_configs_name_the_field(patch, needle):
    with pytest.raises(ConfigError, match=needle.replace(".", r"\.")):
        validate_config({**GOOD, **patch}, Holder, source="test.toml")
