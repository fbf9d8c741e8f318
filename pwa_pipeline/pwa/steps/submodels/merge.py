"""Merging sub-models that predict alike, or that are copies of one mode (step 5)."""

import numpy as np
from sklearn.base import clone

from ...._arrays import relabel_by_size
from ...._blas import single_threaded_blas
from ...._typing import Float2D
from .least_squares import _row_set_key, _rows_by_label, refit
from .residuals import _cost, _sq_residuals, robust_noise_var

_GAP_ENTRIES = 1 << 22
"""Largest number of predictions `_prediction_gaps` holds at once (32 MB)."""


def _prediction_gaps(phi: Float2D, thetas: np.ndarray, labels: np.ndarray,
                     sigma2: np.ndarray) -> np.ndarray:
    """The statistic of `merge_indistinguishable` for every pair of sub-models: entry
    (i, j) is the mean over the rows labelled i or j of Σ_p (ŷ_i,p − ŷ_j,p)² / σ̂_p², ŷ_i = φᵀθ_i.

    Each label's rows are predicted by every sub-model at once (in groups of sub-models that
    keep the predictions within `_GAP_ENTRIES`) and summed against their own
    sub-model's: time O(s·n·d·m) with a Python step per label rather than per pair (a fit
    may start from a hundred clusters, thousands of pairs).
    """
    s, m = thetas.shape[0], thetas.shape[2]
    groups = _rows_by_label(labels, s)
    within = np.empty((s, s))  # (i, j): the sum over the rows labelled i
    with single_threaded_blas():  # n × d by d × m products: threads only wait
        for i, rows in enumerate(groups):
            x = phi[rows]
            own = x @ thetas[i]
            step = max(1, _GAP_ENTRIES // max(x.shape[0] * m, 1))
            for j in range(0, s, step):
                gap = np.matmul(x, thetas[j:j + step])
                gap -= own
                within[i, j:j + step] = _cost(np.square(gap, out=gap), sigma2).sum(axis=1)
    sizes = np.array([len(rows) for rows in groups])
    return (within + within.T) / np.maximum(sizes[:, None] + sizes[None, :], 1)


def merge_indistinguishable(
    phi: Float2D, target: Float2D, labels: np.ndarray, tol: float,
    copy_tol: float | None = None, regions=None,
) -> tuple[np.ndarray, int]:
    """Greedily merge pairs of sub-models that predict alike on their own data.

    For sub-models i, j (least-squares fits on their rows) the statistic is the mean over the
    rows of both of Σ_p ((θ_i − θ_j)ᵀφ)_p² / σ̂_p², the squared difference of their
    predictions in units of the noise variance σ̂_p² (`robust_noise_var`). A pair is
    mergeable when the statistic is below ``tol``, or below ``copy_tol`` while a linear
    classifier on φ (``regions``, an unfitted region estimator such as
    [`SVMRegions`][pwa_pipeline.pwa.SVMRegions]) cannot tell their rows apart
    (`separable` is false): then they are
    copies of one mode that a residual-based assignment split along the noise, not modes of
    distinct regions. The mergeable pair with the smallest statistic is merged, until none is.
    An effect size and not a significance test: with thousands of rows, the slightly
    different biases of errors-in-variables estimates in different parts of one mode are
    significant, but they move predictions by far less than the noise.

    Returns
    -------
    labels : ndarray
        Relabelled by size.
    n_merged : int

    Raises
    ------
    ValueError
        If ``copy_tol`` is given without ``regions``.
    """
    if copy_tol is not None and regions is None:
        raise ValueError("merging copies (copy_tol) needs a region estimator (regions)")
    labels = relabel_by_size(labels)
    n_merged = 0
    verdicts: dict[tuple[bytes, bytes], bool] = {}  # separable(), by the rows of each pair
    fits: dict[bytes, np.ndarray] = {}  # refit()'s θ, by rows: a merge changes one
    while (s := int(labels.max()) + 1) > 1:
        thetas = refit(phi, target, labels, s, fits)
        if np.isnan(thetas).any():
            break
        rows = labels >= 0
        sq = _sq_residuals(phi[rows], target[rows], thetas)
        sigma2 = robust_noise_var(sq[labels[rows], np.arange(rows.sum())])
        stat = _prediction_gaps(phi, thetas, labels, sigma2)
        stats = [(float(stat[i, j]), i, j) for i in range(s) for j in range(i + 1, s)]
        # The mergeable pair with the smallest statistic is the first mergeable one in this
        # order, so the SVM runs only on pairs closer than that one, and once per pair of
        # row sets: linear in the merges, not cubic as testing every pair at every merge.
        pair = None
        for stat, i, j in sorted(stats):
            if stat < tol:
                pair = (i, j)
                break
            if copy_tol is None or stat >= copy_tol:
                break
            key = tuple(_row_set_key(np.flatnonzero(labels == g)) for g in (i, j))
            if key not in verdicts:
                both = (labels == i) | (labels == j)
                verdicts[key] = separable(phi[both], labels[both] == i, regions)
            if not verdicts[key]:
                pair = (i, j)
                break
        if pair is None:
            break
        labels[labels == pair[1]] = pair[0]
        labels = relabel_by_size(labels)
        n_merged += 1
    return labels, n_merged


def separable(phi: Float2D, is_first: np.ndarray, regions, accuracy: float = 0.9) -> bool:
    """Whether the region estimator ``regions`` (unfitted) tells two groups of rows apart on
    φ (training accuracy ≥ ``accuracy``)."""
    labels = is_first.astype(int)
    if labels.min() == labels.max():
        return True
    predicted = clone(regions).fit(phi, labels, 2).predict(phi)
    return bool(np.mean(predicted == labels) >= accuracy)
