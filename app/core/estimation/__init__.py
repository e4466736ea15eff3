"""Target state estimation: motion models (eqs 16-21), IMM-UKF (Appendix B), federated filter
(Appendix A). Pure functions of frozen values; no clock, no I/O.

The pieces a mission uses:

- ``local_step(LocalState, Observation, LocalParams) -> (LocalState, StepReport)`` on each vehicle,
  ``LocalState.estimate() -> LocalEstimate`` to publish;
- ``main_receive`` / ``main_fuse`` / ``main_allocate`` at the ground station,
  ``apply_feedback(LocalState, GlobalEstimate, ...)`` back on the vehicle;
- ``federated_step`` / ``run_federated`` / ``run_centralised`` to run it all in one process.

Messages (``Observation``, ``LocalEstimate``, ``GlobalEstimate``) convert to and from plain dicts.
"""

from app.core.estimation.federated import (
    FEEDBACK_MODES,
    FeedbackMode,
    MainParams,
    MainState,
    apply_feedback,
    fuse,
    information_shares,
    main_allocate,
    main_fuse,
    main_receive,
)
from app.core.estimation.imm import IMMParams, IMMState, combine, imm_init, imm_predict, imm_update
from app.core.estimation.local import (
    FilterCounters,
    LocalParams,
    LocalState,
    StepReport,
    check_observation,
    local_predict,
    local_step,
)
from app.core.estimation.messages import GlobalEstimate, LocalEstimate, Observation
from app.core.estimation.models import MotionModel
from app.core.estimation.pipeline import (
    EstimateTrack,
    FederatedParams,
    FederatedState,
    RunResult,
    federated_step,
    run_centralised,
    run_federated,
)
from app.core.estimation.ukf import SigmaPoints

__all__ = [
    "FEEDBACK_MODES",
    "EstimateTrack",
    "FederatedParams",
    "FederatedState",
    "FeedbackMode",
    "FilterCounters",
    "GlobalEstimate",
    "IMMParams",
    "IMMState",
    "LocalEstimate",
    "LocalParams",
    "LocalState",
    "MainParams",
    "MainState",
    "MotionModel",
    "Observation",
    "RunResult",
    "SigmaPoints",
    "StepReport",
    "apply_feedback",
    "check_observation",
    "combine",
    "federated_step",
    "fuse",
    "imm_init",
    "imm_predict",
    "imm_update",
    "information_shares",
    "local_predict",
    "local_step",
    "main_allocate",
    "main_fuse",
    "main_receive",
    "run_centralised",
    "run_federated",
]
