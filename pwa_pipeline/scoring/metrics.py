"""Scores of identified models: NRMSE and R² per output (paper eq. 21–24)."""

import numpy as np
from scipy.optimize import linear_sum_assignment

from .._typing import Float2D


def _pair(y_true, y_pred) -> tuple[Float2D, Float2D]:
    yt = np.asarray(y_true, dtype=float)
    yp = np.asarray(y_pred, dtype=float)
    yt = yt[:, None] if yt.ndim == 1 else yt
    yp = yp[:, None] if yp.ndim == 1 else yp
    if yt.shape != yp.shape:
        raise ValueError(f"y_true and y_pred differ in shape: {yt.shape} and {yp.shape}")
    if yt.shape[0] < 2:
        raise ValueError(f"need at least 2 samples to score, got {yt.shape[0]}")
    if not np.all(np.isfinite(yt)):
        raise ValueError("y_true contains NaN or inf")
    return yt, yp


def rmse(y_true, y_pred) -> np.ndarray:
    """Root-mean-square error per output, in the data's units."""
    yt, yp = _pair(y_true, y_pred)
    with np.errstate(over="ignore", invalid="ignore"):
        return np.sqrt(np.mean((yt - yp) ** 2, axis=0))


def nrmse(y_true, y_pred) -> np.ndarray:
    """Normalised RMSE per output, eq. (21): RMSE / σ(measured output).

    σ is the population standard deviation (1/N) of the measured output. 0 is perfect;
    1 is as good as predicting the mean. A non-finite prediction gives ``inf``.
    """
    yt, yp = _pair(y_true, y_pred)
    err = rmse(yt, yp)
    return np.where(np.isfinite(err), err, np.inf) / yt.std(axis=0)


def r2_score(y_true, y_pred) -> np.ndarray:
    """Coefficient of determination per output (eq. 22 in its standard form), as a fraction.

    R² = 1 − Σ(q − y)² / Σ(q − q̄)² with q̄ the mean of the *measured* output q. Eq. (22) of the
    paper prints the mean of the estimated output instead, a typo: with the measured mean,
    R² = 1 − NRMSE² holds exactly. Multiply by 100 for the paper's percentages.
    """
    return 1.0 - nrmse(y_true, y_pred) ** 2


def mean_nrmse(y_true, y_pred) -> float:
    """Average NRMSE over outputs, eq. (23)."""
    return float(np.mean(nrmse(y_true, y_pred)))


def mean_r2(y_true, y_pred) -> float:
    """Average R² over outputs, eq. (24), as a fraction."""
    return float(np.mean(r2_score(y_true, y_pred)))


def match_submodels(estimated: np.ndarray, true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pair estimated sub-models with true ones by parameters (Hungarian assignment).

    Parameters
    ----------
    estimated, true : ndarrays of shape (s_est, d, m) and (s_true, d, m)

    Returns
    -------
    mode_of : ndarray of shape (s_est,)
        The true sub-model matched to each estimated one, −1 where none is (more estimated
        than true).
    error : ndarray of shape (s_est,)
        Largest absolute parameter difference to the matched true sub-model (NaN: none).
    """
    cost = np.array([[np.abs(a - b).max() for b in true] for a in estimated])
    rows, cols = linear_sum_assignment(cost)
    mode_of = np.full(len(estimated), -1)
    mode_of[rows] = cols
    error = np.full(len(estimated), np.nan)
    error[rows] = cost[rows, cols]
    return mode_of, error
