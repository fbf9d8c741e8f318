"""Polyhedral regions H_i from a multi-class linear SVM on φ (paper step 6)."""

import warnings
from dataclasses import dataclass

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.svm import LinearSVC

from ._typing import Float2D


@dataclass(frozen=True)
class Regions:
    """A linear partition of the regressor space: φ ∈ H_i ⇔ i = argmax_j (W φ + b)_j.

    Attributes
    ----------
    coef : ndarray of shape (s, d)
        One row w_i per region, in the regressors' own units; the hyperplane between H_i and
        H_j is (w_i − w_j)·φ + (b_i − b_j) = 0.
    intercept : ndarray of shape (s,)
    """

    coef: Float2D
    intercept: np.ndarray

    @property
    def n_regions(self) -> int:
        """Number of regions s."""
        return self.coef.shape[0]

    def predict(self, phi: Float2D) -> np.ndarray:
        """Region index of each row of φ."""
        if self.n_regions == 1:
            return np.zeros(phi.shape[0], dtype=int)
        return np.argmax(phi @ self.coef.T + self.intercept, axis=1)


def fit_regions(
    phi: Float2D,
    labels: np.ndarray,
    n_regions: int,
    C: float = 1.0,
    sample_weight: np.ndarray | None = None,
) -> Regions:
    """Fit the regions H_i by a multi-class linear SVM (one-vs-rest) on labelled φ(k).

    The SVM is trained on z-scored regressors (constant columns such as the affine 1 are
    dropped; the SVM has its own intercept) and its hyperplanes are mapped back to φ's units.
    Rows labelled −1 (noise) or weighted 0 are left out; a label left with no row gets a
    region that is never chosen.

    Parameters
    ----------
    phi : ndarray of shape (n, d)
    labels : ndarray of shape (n,)
        Sub-model index 0 … s−1 of each row, or −1.
    n_regions : int
        s; a label that has no row gets a region that is never chosen.
    C : float
        SVM regularisation (larger: fewer misclassified training points).
    sample_weight : ndarray of shape (n,), optional
        Weight of each row in the SVM loss.
    """
    d = phi.shape[1]
    keep = labels >= 0
    if sample_weight is not None:
        keep &= np.asarray(sample_weight, float) > 0
    x, lab = phi[keep], labels[keep]
    present = np.unique(lab)
    coef = np.zeros((n_regions, d))
    intercept = np.full(n_regions, -np.inf)
    if present.size <= 1:
        if present.size == 1:
            intercept[present[0]] = 0.0
        return Regions(coef=coef, intercept=intercept)
    mean, std = x.mean(axis=0), x.std(axis=0)
    cols = std > 0
    z = (x[:, cols] - mean[cols]) / std[cols]
    weight = None if sample_weight is None else np.asarray(sample_weight, float)[keep]
    svm = LinearSVC(C=C, multi_class="crammer_singer", max_iter=50000, random_state=0)
    with warnings.catch_warnings():
        # Where classes overlap (noisy boundaries) the Crammer–Singer dual keeps making tiny
        # updates after the hyperplanes have settled; the regions are scored, not trusted.
        warnings.simplefilter("ignore", ConvergenceWarning)
        svm.fit(z, lab, sample_weight=weight)
    w, b = np.atleast_2d(svm.coef_), np.atleast_1d(svm.intercept_)
    if present.size == 2:
        w, b = np.vstack([-w / 2, w / 2]), np.array([-b[0] / 2, b[0] / 2])
    w_phi = w / std[cols]
    coef[np.ix_(present, np.nonzero(cols)[0])] = w_phi
    intercept[present] = b - w_phi @ mean[cols]
    return Regions(coef=coef, intercept=intercept)
