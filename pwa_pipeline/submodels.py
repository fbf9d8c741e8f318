"""Sub-model parameter matrices θ_i from clusters (paper step 5) and their refinement."""

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from ._typing import Float2D
from .clustering import relabel_by_size
from .regions import fit_regions


@dataclass(frozen=True)
class SubModels:
    """Sub-models and the data each one explains.

    Attributes
    ----------
    thetas : ndarray of shape (s, d, m)
    labels : ndarray of shape (n,)
        Sub-model of each regressor row; −1 for rows no sub-model was fitted on (noise).
    weights : ndarray of shape (n,), optional
        How clearly each row belongs to its sub-model (0: as well explained by another), used
        to weight the region SVM; None weighs all rows alike.
    n_merged : int
        Sub-models merged by :func:`merge_indistinguishable`.
    n_iter : int
        Refinement sweeps run.
    """

    thetas: np.ndarray
    labels: np.ndarray
    weights: np.ndarray | None = None
    n_merged: int = 0
    n_iter: int = 0


def cluster_centres(local_theta: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """The paper's sub-models: the mean local θ_k of each cluster (step 5)."""
    s = int(labels.max()) + 1
    return np.stack([local_theta[labels == i].mean(axis=0) for i in range(s)])


def refit(phi: Float2D, target: Float2D, labels: np.ndarray, s: int) -> np.ndarray:
    """Least-squares θ_i on all rows labelled i, i = 0 … s−1 (NaN where a label has < d rows)."""
    d, m = phi.shape[1], target.shape[1]
    thetas = np.full((s, d, m), np.nan)
    for i in range(s):
        rows = labels == i
        if rows.sum() >= d:
            thetas[i] = np.linalg.lstsq(phi[rows], target[rows], rcond=None)[0]
    return thetas


def _sq_residuals(phi: Float2D, target: Float2D, thetas: np.ndarray) -> np.ndarray:
    """Squared residuals of every row under every sub-model, shape (s, n, m)."""
    return (target[None] - np.einsum("nd,sdm->snm", phi, thetas)) ** 2


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


def merge_indistinguishable(
    phi: Float2D, target: Float2D, labels: np.ndarray, tol: float,
    copy_tol: float | None = None,
) -> tuple[np.ndarray, int]:
    """Greedily merge pairs of sub-models that predict alike on their own data.

    For sub-models i, j (least-squares fits on their rows) the statistic is the mean over the
    rows of both of Σ_p ((θ_i − θ_j)ᵀφ)_p² / σ̂_p², the squared difference of their
    predictions in units of the noise variance σ̂_p² (:func:`robust_noise_var`). A pair is
    mergeable when the statistic is below ``tol``, or below ``copy_tol`` while a linear
    classifier on φ cannot tell their rows apart (:func:`separable` is false): then they are
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
    """
    labels = relabel_by_size(labels)
    n_merged = 0
    while (s := int(labels.max()) + 1) > 1:
        thetas = refit(phi, target, labels, s)
        if np.isnan(thetas).any():
            break
        rows = labels >= 0
        sq = _sq_residuals(phi[rows], target[rows], thetas)
        sigma2 = robust_noise_var(sq[labels[rows], np.arange(rows.sum())])
        best, pair = np.inf, None
        for i in range(s):
            for j in range(i + 1, s):
                both = (labels == i) | (labels == j)
                diff = phi[both] @ (thetas[i] - thetas[j])
                stat = float(np.mean((diff**2 / sigma2).sum(axis=1)))
                copies = (copy_tol is not None and tol <= stat < copy_tol
                          and not separable(phi[both], labels[both] == i))
                if (stat < tol or copies) and (pair is None or stat < best):
                    best, pair = stat, (i, j)
        if pair is None:
            break
        labels[labels == pair[1]] = pair[0]
        labels = relabel_by_size(labels)
        n_merged += 1
    return labels, n_merged


def separable(phi: Float2D, is_first: np.ndarray, accuracy: float = 0.9) -> bool:
    """Whether a linear SVM on φ tells two groups of rows apart (training accuracy ≥
    ``accuracy``)."""
    labels = is_first.astype(int)
    if labels.min() == labels.max():
        return True
    predicted = fit_regions(phi, labels, 2).predict(phi)
    return bool(np.mean(predicted == labels) >= accuracy)


def refine(
    phi: Float2D,
    target: Float2D,
    labels: np.ndarray,
    min_size: int,
    n_iter: int,
    svm_c: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Re-assign rows to sub-models by residual and refit until the assignment is stable.

    Each sweep: every row goes to the sub-model with the smallest noise-normalised residual
    Σ_p (y_p − θ_(p),iᵀφ)² / σ̂_p², sub-models left with fewer than ``min_size`` rows are
    dropped (their rows re-assigned), and every sub-model is refitted by least squares on its
    rows. Rows labelled −1 (DBSCAN noise) are assigned from the first sweep on.

    Returns
    -------
    thetas : ndarray of shape (s, d, m)
    labels : ndarray of shape (n,)
        Every row labelled.
    margin : ndarray of shape (n,)
        Normalised residual cost of the second-best sub-model minus the best one's.
    n_iter : int
        Sweeps run.
    """
    d = phi.shape[1]
    labels = relabel_by_size(labels)
    thetas = refit(phi, target, labels, int(labels.max()) + 1)
    it = 0
    for it in range(1, n_iter + 1):
        thetas = thetas[~np.isnan(thetas).any(axis=(1, 2))]
        sq = _sq_residuals(phi, target, thetas)
        sigma2 = _noise_var(sq, _argmin_labels(sq, None), len(thetas) * d)
        new = _argmin_labels(sq, sigma2)
        sizes = np.bincount(new, minlength=len(thetas))
        if (sizes < min_size).any() and (sizes >= min_size).any():
            new = _argmin_labels(sq[sizes >= min_size], sigma2)
        new = relabel_by_size(new)
        thetas = refit(phi, target, new, int(new.max()) + 1)
        if svm_c is not None and thetas.shape[0] > 1:
            cost = np.sort((_sq_residuals(phi, target, thetas) / sigma2).sum(axis=2), axis=0)
            regions = fit_regions(phi, new, thetas.shape[0], C=svm_c,
                                  sample_weight=margin_weights(cost[1] - cost[0]))
            new = regions.predict(phi)
            sizes = np.bincount(new, minlength=thetas.shape[0])
            if (sizes < min_size).any():
                sq = _sq_residuals(phi, target, thetas[sizes >= min_size])
                new = _argmin_labels(sq, sigma2)
            new = relabel_by_size(new)
            thetas = refit(phi, target, new, int(new.max()) + 1)
        if np.array_equal(new, labels):
            break
        labels = new
    cost = np.sort((_sq_residuals(phi, target, thetas) / sigma2).sum(axis=2), axis=0)
    margin = cost[1] - cost[0] if len(thetas) > 1 else np.full(phi.shape[0], np.inf)
    return thetas, new, margin, it


def margin_weights(margin: np.ndarray, threshold: float = 4.0) -> np.ndarray:
    """Region-SVM weight of each row: 1 where its sub-model beats the next best clearly.

    ``margin`` is the noise-normalised squared residual of the second-best sub-model minus
    the best one's; below ``threshold`` (4: predictions about two noise standard deviations
    apart) both explain the row alike, its label says nothing about the regions, and its
    weight is 0.
    """
    return (margin > threshold).astype(float)


def unexplained_cost(phi: Float2D, target: Float2D, thetas: np.ndarray) -> np.ndarray:
    """Noise-normalised residual Σ_p r_p² / σ̂_p² of each row under its best sub-model.

    σ̂_p² is :func:`robust_noise_var` of those best residuals, so that rows no sub-model
    explains do not inflate the noise estimate that is to expose them.
    """
    sq = _sq_residuals(phi, target, thetas)
    best = sq[np.argmin(sq.sum(axis=2), axis=0), np.arange(phi.shape[0])]
    return (best / robust_noise_var(best)).sum(axis=1)


def _argmin_labels(sq: np.ndarray, sigma2: np.ndarray | None) -> np.ndarray:
    cost = sq.sum(axis=2) if sigma2 is None else (sq / sigma2).sum(axis=2)
    return np.argmin(cost, axis=0)
