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
