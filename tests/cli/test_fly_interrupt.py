"""``fly_until_interrupted``: a Ctrl-C stops a mission even when a cancellation is lost on the
way (a stand-in mission that swallows cancellations, as a library race can, and flies on)."""

import asyncio
import os
import signal

import pytest

from app.compose import mission as mission_module
from app.compose.mission import fly_until_interrupted


class StandIn:
    """Advances its mission time every 10 ms; swallows the first ``swallow`` cancellations
    (flying on), or with ``end_after_swallow`` returns after swallowing one."""

    def __init__(
        self, swallow: int = 0, end_after_swallow: bool = False, steps: int = 1000
    ) -> None:
        self.t = 0.0
        self.cancels = 0
        self.swallow = swallow
        self.end_after_swallow = end_after_swallow
        self.steps = steps

    def mission_t(self) -> float:
        return self.t

    async def run(self) -> str:
        while True:
            try:
                for _ in range(self.steps):
                    await asyncio.sleep(0.01)
                    self.t += 0.01
                return "flown to its end"
            except asyncio.CancelledError:
                self.cancels += 1
                if self.cancels > self.swallow:
                    raise
                if self.end_after_swallow:
                    return "ended after a swallowed cancellation"


def ctrl_c_in(delay_s: float) -> None:
    asyncio.get_running_loop().call_later(delay_s, os.kill, os.getpid(), signal.SIGINT)


@pytest.fixture(autouse=True)
def quick_checks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(mission_module, "FLYING_ON_CHECK_S", 0.05)


async def test_a_ctrl_c_stops_the_mission_as_a_keyboard_interrupt() -> None:
    stand_in = StandIn()
    ctrl_c_in(0.1)
    with pytest.raises(KeyboardInterrupt):
        await fly_until_interrupted(stand_in.run(), stand_in.mission_t)
    assert stand_in.cancels == 1
    assert stand_in.t < 1.0
    # the terminal's Ctrl-C is Python's own again
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


async def test_a_mission_that_swallowed_the_cancellation_and_flies_on_is_cancelled_again() -> None:
    stand_in = StandIn(swallow=2)
    ctrl_c_in(0.1)
    with pytest.raises(KeyboardInterrupt):
        await fly_until_interrupted(stand_in.run(), stand_in.mission_t)
    assert stand_in.cancels == 3
    assert stand_in.t < 2.0  # well before its end at 10 s


async def test_a_mission_that_ended_after_a_ctrl_c_still_ends_as_interrupted() -> None:
    stand_in = StandIn(swallow=1, end_after_swallow=True)
    ctrl_c_in(0.1)
    with pytest.raises(KeyboardInterrupt):
        await fly_until_interrupted(stand_in.run(), stand_in.mission_t)
    assert stand_in.cancels == 1


async def test_without_a_ctrl_c_the_mission_flies_to_its_end() -> None:
    stand_in = StandIn(steps=20)
    assert await fly_until_interrupted(stand_in.run(), stand_in.mission_t) == "flown to its end"
    assert stand_in.cancels == 0
