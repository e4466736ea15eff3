"""A vehicle link's transport delay, measured with MAVLink TIMESYNC: pure arithmetic, no socket.

The boot-clock map (``clockmap.BootClockMap``) stamps a frame with its boot time plus the least
``host - boot`` seen, which is the vehicle's clock offset *plus the least downlink delay*: every
frame is then stamped as if it had been sampled when it arrived. On a loopback link that is a
millisecond; through a telemetry radio or a cellular modem it is 0.1-0.5 s, and it differs per
vehicle, so the team's positions and each camera's fixes are stamped late by different amounts
(0.3 s at 14 m/s is 4 m along the orbit, 3 degrees of phase at 90 m).

The link sends TIMESYNC requests (``tc1 = 0``, ``ts1`` its own clock) and the autopilot answers
with ``ts1`` echoed; the round trip is the time from sending to the answer. Its least value over
a window (queuing and a busy host only add to it) halved is the one-way delay, assuming the two
directions take as long (a radio's usually do). The frames' stamps are then moved back by it.
"""

from __future__ import annotations

import math
from collections import OrderedDict, deque


class LinkDelay:
    """One link's TIMESYNC round trips, in the host's time (s).

    ``sent(ts1, host_t)`` records a request; ``answered(ts1, host_t)`` takes an answer and
    returns its round trip, or None when ``ts1`` is not one of the (at most ``max_pending``)
    outstanding requests: another component's, a duplicate, or one given up on.
    ``one_way_s`` is half the least round trip of the last ``window_s`` (None before the first
    answer); round trips over ``max_round_trip_s`` are not believed (a request answered after a
    link loss).
    """

    def __init__(
        self, window_s: float = 30.0, max_pending: int = 16, max_round_trip_s: float = 5.0
    ) -> None:
        for name, value in (("window_s", window_s), ("max_round_trip_s", max_round_trip_s)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if max_pending < 1:
            raise ValueError(f"max_pending must be >= 1, got {max_pending}")
        self.window_s = window_s
        self.max_pending = max_pending
        self.max_round_trip_s = max_round_trip_s
        self.answers = 0
        self.last_round_trip_s: float | None = None
        self._pending: OrderedDict[int, float] = OrderedDict()
        # (host time, round trip), round trips increasing from the left: a monotone deque
        self._trips: deque[tuple[float, float]] = deque()

    def sent(self, ts1: int, host_t_s: float) -> None:
        self._pending[ts1] = host_t_s
        while len(self._pending) > self.max_pending:
            self._pending.popitem(last=False)

    def answered(self, ts1: int, host_t_s: float) -> float | None:
        sent = self._pending.pop(ts1, None)
        if sent is None or not math.isfinite(host_t_s):
            return None
        trip = host_t_s - sent
        if not 0.0 <= trip <= self.max_round_trip_s:
            return None
        self.answers += 1
        self.last_round_trip_s = trip
        trips = self._trips
        while trips and trips[-1][1] >= trip:
            trips.pop()
        trips.append((host_t_s, trip))
        while trips[0][0] < host_t_s - self.window_s and len(trips) > 1:
            trips.popleft()
        return trip

    @property
    def one_way_s(self) -> float | None:
        return None if not self._trips else 0.5 * self._trips[0][1]


def follow(applied_s: float, wanted_s: float, max_step_s: float) -> float:
    """The correction applied to the next frame: ``wanted_s`` approached by at most
    ``max_step_s`` (a frame's stamp must never jump back past the one before it)."""
    if wanted_s > applied_s + max_step_s:
        return applied_s + max_step_s
    if wanted_s < applied_s - max_step_s:
        return applied_s - max_step_s
    return wanted_s
