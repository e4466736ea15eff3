"""``standoff optimal-c``."""

import re

import pytest

from app.cli import main
from app.core.guidance.field import optimal_c


@pytest.mark.parametrize(
    ("radius", "speed", "expected"), [("300", "20", 0.191639), ("90", "14", 0.342450)]
)
def test_prints_the_optimal_c(radius, speed, expected, capsys):
    args = [
        "optimal-c",
        "--radius-m",
        radius,
        "--speed-m-s",
        speed,
        "--max-course-rate-rad-s",
        "0.2",
    ]
    assert main(args) == 0
    out = capsys.readouterr().out
    match = re.search(r"c_opt = ([0-9.]+)", out)
    assert match is not None
    assert float(match.group(1)) == pytest.approx(expected, abs=1e-6)
    assert float(match.group(1)) == pytest.approx(
        optimal_c(float(radius), float(speed), 0.2), abs=1e-6
    )
    assert "search time" in out


def test_infeasible_circle_is_reported(capsys):
    args = ["optimal-c", "--radius-m", "50", "--speed-m-s", "25", "--max-course-rate-rad-s", "0.2"]
    assert main(args) == 1
    assert "infeasible" in capsys.readouterr().out


@pytest.mark.parametrize("value", ["0", "-3", "nan", "inf"])
def test_bad_values_are_one_line_errors(value, capsys):
    args = ["optimal-c", "--radius-m", value, "--speed-m-s", "20", "--max-course-rate-rad-s", "0.2"]
    assert main(args) == 2
    assert "--radius-m must be" in capsys.readouterr().err
