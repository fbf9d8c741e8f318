"""A system shared by the output-error tests (tests/pwa/output_error/test_output_error_*.py)."""

import numpy as np


def _output_noise_system(seed: int, n: int = 3000, sigma: float = 0.5):
    """y(k) = 0.9 y(k−1) + 0.5 u(k−1), measured with white noise: an output-error system."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 1))
    y = np.zeros((n, 1))
    for k in range(1, n):
        y[k] = 0.9 * y[k - 1] + 0.5 * u[k - 1]
    return u, y + sigma * rng.normal(size=y.shape)
