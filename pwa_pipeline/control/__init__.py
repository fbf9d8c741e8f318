"""Control-ready models: a fitted PWARX (or LinearARX) model as a PWA state-space model.

``model.to_state_space()`` ([`to_state_space`][pwa_pipeline.control.to_state_space]) gives a
[`PWAStateSpace`][pwa_pipeline.control.PWAStateSpace], x⁺ = A_i x + B_i u + f_i, y = C_i x + g_i on polyhedral
regions P_i = {z : H_i z ≤ h_i} of z = [x; u] inside the data envelope, the form of MPT3's ``PWASystem``: its
state is the non-minimal one of the regressor of eq. (2)–(3) (past outputs and inputs), so it simulates as
the model of eq. (1) does. It is written as versioned JSON
([`PWAStateSpace.to_json`][pwa_pipeline.control.PWAStateSpace.to_json]) or as an MPT3 script
([`PWAStateSpace.to_mpt3`][pwa_pipeline.control.PWAStateSpace.to_mpt3]), and its stability is reported by
[`PWAStateSpace.stability`][pwa_pipeline.control.PWAStateSpace.stability].
[`HybridMPC`][pwa_pipeline.control.HybridMPC] controls it by model predictive control solved as a
mixed-integer linear program (HiGHS, through ``scipy.optimize.milp``). Only numpy and scipy (and cvxpy for the
Lyapunov search) are used here.
"""

from .conversion import PADDING, to_state_space
from .json_format import SCHEMA, SCHEMA_VERSION
from .mpc import ClosedLoop, HybridMPC, MPCSolution
from .stability import StabilityReport, stability_report
from .state_space import PWAStateSpace

__all__ = ["PADDING", "SCHEMA", "SCHEMA_VERSION", "ClosedLoop", "HybridMPC", "MPCSolution",
           "PWAStateSpace", "StabilityReport", "stability_report", "to_state_space"]
