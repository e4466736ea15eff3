"""Fixtures shared across the test folders; the helpers they use live in ``tests/support/``.

The folders follow the layers: ``core/`` (pure functions: closed forms, properties,
cross-checks), ``config/``, ``runtime/`` (the loops over fakes, the fast simulation, the
fast-sim vs async cross-check), ``adapters/`` (buses on a real broker, the MAVSDK link and the
autopilot adapters against the built-in simulator over UDP), ``sitl/`` (the simulator over
MAVLink), ``report/``, ``cli/``, and ``system/`` (whole missions, one process and many).
Tests marked ``slow`` (a few seconds or more each) are left out by ``pytest -m "not slow"``.
"""

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.mosquitto import Mosquitto


@pytest.fixture(name="mosquitto")
def mosquitto_fixture(tmp_path: Path) -> Iterator[Mosquitto]:
    """A real mosquitto broker on a free loopback port, stopped after the test."""
    broker = Mosquitto(tmp_path)
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()


# The test command (scripts/test) runs three lanes at once on a multi-core machine: the whole
# missions (one process flying a team in wall-clock time, or a ground and its agents), one after
# another; beside them the other wall-clock tests (one vehicle over UDP, brokers), lighter; and the
# pure computations at a lower priority, so that they use only the idle cores.
_COMPUTE_LANE = (
    "tests/core/",
    "tests/config/",
    "tests/report/",
    "tests/runtime/test_fastsim.py",
    "tests/runtime/test_mission_fastsim.py",
    "tests/runtime/test_wire.py",
    "tests/adapters/test_bus_codec.py",
    "tests/sitl/test_sitl_geodesy.py",
    "tests/sitl/test_target.py",
)
_MISSION_LANE = (
    "tests/system/",
    "tests/runtime/test_silent_mission.py",
    "tests/cli/test_replay.py",
    "tests/cli/test_install.py",
)
_ROOT = Path(__file__).resolve().parents[1]


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        where = item.path.resolve().relative_to(_ROOT).as_posix()
        if where.startswith(_COMPUTE_LANE):
            item.add_marker(pytest.mark.compute)
        elif where.startswith(_MISSION_LANE):
            item.add_marker(pytest.mark.mission)
