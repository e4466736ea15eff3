"""What reaches the operator's terminal: events that need a person are warnings."""

import logging

import pytest

from app.runtime.events import LoggingSink


@pytest.mark.parametrize("kind", ["pilot_took_over", "handover_timeout", "clock_rebased"])
def test_events_that_need_the_operator_are_warnings(
    kind: str, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.INFO, logger="standoff.events"):
        LoggingSink().emit(kind, 12.0, vehicle=1)
        LoggingSink().emit("stage", 12.0, detail="track")
    levels = {r.getMessage().split()[1]: r.levelno for r in caplog.records}
    assert levels == {kind: logging.WARNING, "stage": logging.INFO}
