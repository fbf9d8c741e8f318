"""Hybrid model predictive control of a PWA state-space model: the mixed-integer linear
program (`formulation`) and the controller that solves it at each sample
(`controller`)."""

from .controller import ClosedLoop, HybridMPC, MPCSolution
from .formulation import MLDProgram

__all__ = ["ClosedLoop", "HybridMPC", "MLDProgram", "MPCSolution"]
