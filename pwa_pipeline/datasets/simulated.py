"""The simulated 2-input, 2-output, 4-mode PWA system of the paper's section 5 (eq. 11–14)."""

import numpy as np

from .._typing import Float2D
from .dataset import Dataset, GroundTruth

#: Sub-model matrices of eq. (11), as θ_i of shape (d, m) = (4, 2), for modes λ = 1 … 4.
HURE_VASAK_THETAS = np.array(
    [
        [[0.9, 0.0, 0.1, 0.0], [0.0, 0.6, 0.0, 0.4]],
        [[0.7, 0.0, 0.3, 0.0], [0.15, 0.6, 0.0, 0.4]],
        [[0.7, -0.2, 0.3, 0.0], [0.15, 0.8, 0.0, 0.2]],
        [[0.9, -0.2, 0.1, 0.0], [0.0, 0.8, 0.0, 0.2]],
    ]
).transpose(0, 2, 1)


def hure_vasak_mode(y_prev: Float2D) -> np.ndarray:
    """Mode λ − 1 of eq. (12) from y(k−1): quadrants of (y1, y2) around (0.5, 0.5)."""
    hi1, hi2 = y_prev[..., 0] > 0.5, y_prev[..., 1] > 0.5
    return np.select([hi1 & hi2, ~hi1 & hi2, ~hi1 & ~hi2], [0, 1, 2], default=3)


def add_output_noise(y_clean: Float2D, snr_db: float, rng: np.random.Generator) -> Float2D:
    """Gaussian noise scaled so that eq. (14) holds exactly for every output."""
    e = rng.standard_normal(y_clean.shape)
    gain = np.sqrt((y_clean**2).sum(axis=0) / (10 ** (snr_db / 10) * (e**2).sum(axis=0)))
    return e * gain


def _record(n_samples: int, snr_db: float | None, seed: int, burn_in: int
            ) -> tuple[Float2D, Float2D, Float2D, np.ndarray]:
    """One simulated record: u, the measured y, the noise-free y and the modes."""
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
    return u, y + noise, y, modes


#: Offset of the held-out record's seed from the training record's.
TEST_SEED_OFFSET = 1000


def make_hure_vasak(n_samples: int = 4000, snr_db: float | None = 30.0, seed: int = 0,
                    n_test: int = 0, burn_in: int = 100) -> Dataset:
    """The 2-input, 2-output, 4-mode PWA system of the paper's section 5 (eq. 11–14).

    u(k) is white and uniform in the box [−4, 6] × [−2, 4]; y(k) = θ_λᵀ [y(k−1); u(k−1)] with
    λ from eq. (12); the measured output is y + e with e Gaussian at ``snr_db`` per output as
    eq. (14) defines it (``None``: noise-free). The first ``burn_in`` simulated samples are
    dropped so that the record starts in steady operation.

    Parameters
    ----------
    n_samples : int, default 4000
        Samples of the training record.
    snr_db : float or None, default 30
    seed : int, default 0
        Seed of the training record; the held-out record's is ``seed`` + 1000
        (`TEST_SEED_OFFSET`), so that the two never share an input or a noise draw.
    n_test : int, default 0
        Samples of the held-out record (0: none).
    burn_in : int, default 100

    Returns
    -------
    Dataset
        One training record (and one held-out record with ``n_test``), with the
        [`GroundTruth`][pwa_pipeline.datasets.GroundTruth]: θ_i, each sample's mode, the noise-free outputs.

    Examples
    --------
    >>> data = make_hure_vasak(n_samples=500, n_test=200, seed=0)
    >>> [u.shape for u in data.u_train], [y.shape for y in data.y_test]
    ([(500, 2)], [(200, 2)])
    >>> data.truth.thetas.shape  # four modes, d = 4, m = 2
    (4, 4, 2)
    """
    if n_samples < 2:
        raise ValueError(f"n_samples must be at least 2, got {n_samples}")
    if n_test < 0 or n_test == 1:
        raise ValueError(f"n_test must be 0 (no held-out record) or at least 2, got {n_test}")
    parts = [_record(n_samples, snr_db, seed, burn_in)]
    if n_test:
        parts.append(_record(n_test, snr_db, seed + TEST_SEED_OFFSET, burn_in))
    train, test = parts[0], parts[1:]
    truth = GroundTruth(
        y_clean_train=[train[2]], y_clean_test=[p[2] for p in test],
        thetas=HURE_VASAK_THETAS.copy(), modes_train=[train[3]],
        modes_test=[p[3] for p in test], na=1, nb=1, affine=False)
    return Dataset("hure_vasak", [train[0]], [train[1]], [p[0] for p in test],
                   [p[1] for p in test], ["u1", "u2"], ["y1", "y2"], truth)
