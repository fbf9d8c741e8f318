"""Noise-normalised residual costs of rows under sub-models, and the noise variance they are
normalised by."""

import numpy as np
from scipy.stats import chi2

from ...._blas import single_threaded_blas
from ...._typing import Float2D


def _sq_residuals(phi: Float2D, target: Float2D, thetas: np.ndarray) -> np.ndarray:
    """Squared residuals of every row under every sub-model, shape (s, n, m)."""
    with single_threaded_blas():  # n × d by d × m products: threads only wait
        sq = np.matmul(phi, thetas)
    np.subtract(target, sq, out=sq)
    return np.square(sq, out=sq)


def _own_sq_residuals(phi: Float2D, target: Float2D, thetas: np.ndarray, labels: np.ndarray
                      ) -> np.ndarray:
    """Squared residuals of every row under its own sub-model ``labels`` (all ≥ 0), shape
    (n, m): one product per sub-model, where gathering θ per row (n × d × m) was slow."""
    return _sq_residuals(phi, target, thetas)[labels, np.arange(phi.shape[0])]


def _cost(sq: np.ndarray, sigma2: np.ndarray | None = None) -> np.ndarray:
    """Σ_p sq[..., p] (/ σ̂_p²) over the last axis: ``(sq / sigma2).sum(axis=-1)`` bit for
    bit (numpy adds fewer than 8 terms in order), without its slow strided reduction."""
    m = sq.shape[-1]
    if m >= 8:
        return (sq if sigma2 is None else sq / sigma2).sum(axis=-1)
    acc = sq[..., 0].copy() if sigma2 is None else sq[..., 0] / sigma2[0]
    for p in range(1, m):
        acc += sq[..., p] if sigma2 is None else sq[..., p] / sigma2[p]
    return acc


def _argmin_labels(sq: np.ndarray, sigma2: np.ndarray | None) -> np.ndarray:
    return np.argmin(_cost(sq, sigma2), axis=0)


def _noise_var(sq_res: np.ndarray, labels: np.ndarray, n_params: int) -> np.ndarray:
    """Pooled residual variance per output of the rows under their own sub-model."""
    rows = labels >= 0
    own = sq_res[labels[rows], np.nonzero(rows)[0]]
    dof = max(own.shape[0] - n_params, 1)
    return np.maximum(own.sum(axis=0) / dof, np.finfo(float).tiny)


def robust_noise_var(sq_res: np.ndarray) -> np.ndarray:
    """Noise variance per output from squared residuals (n, m): median / 0.455 (χ²(1) median).

    Robust to the rows a sub-model does not explain, which would inflate a plain mean.
    """
    return np.maximum(np.median(sq_res, axis=0) / chi2.ppf(0.5, 1), np.finfo(float).tiny)


def unexplained_cost(phi: Float2D, target: Float2D, thetas: np.ndarray) -> np.ndarray:
    """Noise-normalised residual Σ_p r_p² / σ̂_p² of each row under its best sub-model.

    σ̂_p² is `robust_noise_var` of those best residuals, so that rows no sub-model
    explains do not inflate the noise estimate that is to expose them.
    """
    sq = _sq_residuals(phi, target, thetas)
    best = sq[np.argmin(_cost(sq), axis=0), np.arange(phi.shape[0])]
    return _cost(best, robust_noise_var(best))


def margin_weights(margin: np.ndarray, threshold: float = 4.0) -> np.ndarray:
    """Region-SVM weight of each row: 1 where its sub-model beats the next best clearly.

    ``margin`` is the noise-normalised squared residual of the second-best sub-model minus
    the best one's; below ``threshold`` (4: predictions about two noise standard deviations
    apart) both explain the row alike, its label says nothing about the regions, and its
    weight is 0.
    """
    return (margin > threshold).astype(float)
