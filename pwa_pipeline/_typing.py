"""Array aliases used across the numerical core."""

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

Float2D = NDArray[np.float64]
"""A float array of shape (n_samples, n_channels)."""

Signals = ArrayLike | Sequence[ArrayLike]
"""One experiment as an (N, channels) array, or a list of such arrays."""
