"""Linear baselines scored beside the PWA model: ARX by least squares, and a subspace
(N4SID-type) state-space model."""

from .linear import LinearARX
from .subspace import SubspaceSS

__all__ = ["LinearARX", "SubspaceSS"]
