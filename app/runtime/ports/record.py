"""The input-recorder port: what estimation and the mission's decisions were fed, in order.

An agent tells it each observation it is about to feed its local filter and each fused estimate
it is about to apply; the ground station each vehicle status and each local estimate it is about
to take. Called just before the core's step that consumes the input, with nothing awaited in
between, so that in one process the calls come in the order the steps ran: enough to re-run the
local filters, the fusion and the stage logic offline (``standoff replay``).
"""

from typing import Protocol

from app.core.estimation.messages import Observation
from app.core.mission.ground import VehicleReport


class InputRecorder(Protocol):
    def observation(self, vehicle: int, obs: Observation, clock_t_s: float) -> None:
        """Agent ``vehicle`` feeds ``obs`` to its local filter, its own clock (newest control
        tick, which it judges message times by; -inf before the first) at ``clock_t_s``."""

    def fused(self, vehicle: int, t_s: float, clock_t_s: float) -> None:
        """Agent ``vehicle`` applies the fused estimate of mission time ``t_s``, its clock at
        ``clock_t_s``."""

    def status(self, vehicle: int, report: VehicleReport, clock_t_s: float | None) -> None:
        """The ground station takes vehicle ``vehicle``'s status ``report``, its own mission
        clock reading ``clock_t_s`` then (None: it has none)."""

    def local(self, vehicle: int, t_s: float, clock_t_s: float | None) -> None:
        """The ground station takes vehicle ``vehicle``'s local estimate of time ``t_s``, its
        clock reading ``clock_t_s`` then."""
