"""Hybrid model predictive control of a PWA state-space model: the mixed-integer linear
program (:mod:`.formulation`) and the controller that solves it at each sample
(:mod:`.controller`)."""

from .controller import ClosedLoop, HybridMPC, MPCSolution
from .formulation import MLDProgram

__all__ = ["ClosedLoop", "HybridMPC", "MLDProgram", "MPCSolution"]
