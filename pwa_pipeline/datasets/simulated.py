"""The simulated 2-input, 2-output, 4-mode PWA system of the paper's section 5 (eq. 11–14)."""

from dataclasses import dataclass, field

import numpy as np

from .._typing import Float2D

#: Sub-model matrices of eq. (11), as θ_i of shape (d, m) = (4, 2), for modes λ = 1 … 4.
HURE_VASAK_THETAS = np.array(
    [
        [[0.9, 0.0, 0.1, 0.0], [0.0, 0.6, 0.0, 0.4]],
        [[0.7, 0.0, 0.3, 0.0], [0.15, 0.6, 0.0, 0.4]],
        [[0.7, -0.2, 0.3, 0.0], [0.15, 0.8, 0.0, 0.2]],
        [[0.9, -0.2, 0.1, 0.0], [0.0, 0.8, 0.0, 0.2]],
    ]
).transpose(0, 2, 1)

@dataclass(frozen=True)
class SimulatedPWA:
    """A simulated PWARX data set with its ground truth.

    Attributes
    ----------
    u : ndarray of shape (N, r)
    y : ndarray of shape (N, m)
        Measured (noisy) outputs.
    y_clean : ndarray of shape (N, m)
    modes : ndarray of shape (N,)
        True sub-model (0-based) that produced y(k).
    thetas : ndarray of shape (s, d, m)
        True parameter matrices.
    snr_db : float or None
    """

    u: Float2D
    y: Float2D
    y_clean: Float2D
    modes: np.ndarray
    thetas: np.ndarray
    snr_db: float | None
    u_names: list[str] = field(default_factory=lambda: ["u1", "u2"])
    y_names: list[str] = field(default_factory=lambda: ["y1", "y2"])


def hure_vasak_mode(y_prev: Float2D) -> np.ndarray:
    """Mode λ − 1 of eq. (12) from y(k−1): quadrants of (y1, y2) around (0.5, 0.5)."""
    hi1, hi2 = y_prev[..., 0] > 0.5, y_prev[..., 1] > 0.5
    return np.select([hi1 & hi2, ~hi1 & hi2, ~hi1 & ~hi2], [0, 1, 2], default=3)


def add_output_noise(y_clean: Float2D, snr_db: float, rng: np.random.Generator) -> Float2D:
    """Gaussian noise scaled so that eq. (14) holds exactly for every output."""
    e = rng.standard_normal(y_clean.shape)
    gain = np.sqrt((y_clean**2).sum(axis=0) / (10 ** (snr_db / 10) * (e**2).sum(axis=0)))
    return e * gain


def make_hure_vasak(
    n_samples: int = 4000, snr_db: float | None = 30.0, seed: int = 0, burn_in: int = 100
) -> SimulatedPWA:
    """The 2-input, 2-output, 4-mode PWA system of the paper's section 5 (eq. 11–14).

    u(k) is white and uniform in the box [−4, 6] × [−2, 4]; y(k) = θ_λᵀ [y(k−1); u(k−1)] with
    λ from eq. (12); the measured output is y + e with e Gaussian at ``snr_db`` per output as
    eq. (14) defines it (``None``: noise-free). The first ``burn_in`` simulated samples are
    dropped so that the record starts in steady operation.

    Parameters
    ----------
    n_samples : int, default 4000
    snr_db : float or None, default 30
    seed : int, default 0
    burn_in : int, default 100
    """
    if n_samples < 2:
        raise ValueError(f"n_samples must be at least 2, got {n_samples}")
    rng = np.random.default_rng(seed)
    total = n_samples + burn_in
    u = np.column_stack([rng.uniform(-4, 6, total), rng.uniform(-2, 4, total)])
    y = np.zeros((total, 2))
    modes = np.zeros(total, dtype=int)
    for k in range(1, total):
        modes[k] = hure_vasak_mode(y[k - 1])
        y[k] = np.concatenate([y[k - 1], u[k - 1]]) @ HURE_VASAK_THETAS[modes[k]]
    u, y, modes = u[burn_in:], y[burn_in:], modes[burn_in:]
    noise = np.zeros_like(y) if snr_db is None else add_output_noise(y, snr_db, rng)
    return SimulatedPWA(u=u, y=y + noise, y_clean=y, modes=modes,
                        thetas=HURE_VASAK_THETAS.copy(), snr_db=snr_db)
