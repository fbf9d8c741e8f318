"""Polyhedral regions H_i from a multi-class linear SVM on φ (paper step 6)."""

import warnings
from numbers import Integral, Real

import numpy as np
from sklearn.base import _fit_context
from sklearn.exceptions import ConvergenceWarning
from sklearn.svm import LinearSVC
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted

from ..._typing import Float2D
from ..partitions import CompiledForm, Halfspaces, argmax_halfspaces
from .base import BaseRegions


class SVMRegions(BaseRegions):
    """Step 6 of the method: the regions H_i of a linear partition of the regressor space,
    φ ∈ H_i ⇔ i = argmax_j (w_j·φ + b_j), from a multi-class linear SVM on labelled φ(k).

    The SVM is Crammer and Singer's joint multi-class formulation (scikit-learn's
    ``LinearSVC(multi_class="crammer_singer")``), trained on z-scored regressors (constant
    columns such as the affine 1 are dropped; the SVM has its own intercept); its hyperplanes
    are mapped back to φ's units. Two classes are solved as the binary hinge-loss SVM with
    2C, the same problem (tested), in about half the time (``LinearSVC(loss="hinge")``).
    Rows labelled −1 (DBSCAN noise) or weighted 0 are left out.

    Parameters
    ----------
    C : float, default 1
        SVM regularisation (larger: fewer misclassified training rows).
    max_rows : int, optional, default 5000
        Fit on at most this many rows: above it each class keeps at most an equal share
        (``max_rows`` // classes, a seeded random choice), so a rare class keeps all its rows
        up to that share, and kept rows are weighted so that the classes keep the proportions
        they have among all rows (``C`` then weighs the loss as on a fit of the kept rows).
        The dual solver's cost grows faster than the rows where classes overlap, and a
        linear boundary is fixed by far fewer. None: every row.
    random_state : int, default 0
        Seed of that choice.
    tol : float, default 1e-4
        Stopping tolerance of the SVM's dual solver (scikit-learn's ``LinearSVC(tol=...)``;
        liblinear's own default for this formulation is 0.1). The paper's preset uses 1e-2:
        on the robot's tens of thousands of clustered rows in 27 classes, 1e-4 does not
        converge (it stops at ``max_iter`` with a ConvergenceWarning), while 1e-2 converges
        and gives the regions of a much tighter solve; on heavily overlapping classes rows
        near the boundaries move between solves at any tolerance. On the simulated system
        1e-2 moves a few rows in thousands against 1e-4, so the default keeps 1e-4.

    Attributes
    ----------
    coef_ : ndarray of shape (s, d)
        One row w_i per region, in φ's units; the hyperplane between H_i and H_j is
        (w_i − w_j)·φ + (b_i − b_j) = 0.
    intercept_ : ndarray of shape (s,)
        b_i; −inf for a label that had no row (a region that is never chosen).
    n_regions_ : int
        s.

    Examples
    --------
    >>> import numpy as np
    >>> phi = np.random.default_rng(0).normal(size=(300, 2))
    >>> labels = (phi[:, 0] > 0.5).astype(int)
    >>> regions = SVMRegions(C=10.0).fit(phi, labels)
    >>> bool(np.mean(regions.predict(phi) == labels) > 0.98)
    True
    """

    _parameter_constraints: dict = {
        "C": [Interval(Real, 0, None, closed="neither")],
        "max_rows": [Interval(Integral, 2, None, closed="left"), None],
        "random_state": [Interval(Integral, 0, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="neither")],
    }

    def __init__(self, C: float = 1.0, max_rows: int | None = 5000, random_state: int = 0,
                 tol: float = 1e-4):
        self.C = C
        self.max_rows = max_rows
        self.random_state = random_state
        self.tol = tol

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(
        self,
        phi: Float2D,
        labels: np.ndarray,
        n_regions: int | None = None,
        sample_weight: np.ndarray | None = None,
        *,
        target: Float2D | None = None,
        thetas: np.ndarray | None = None,
        output_lags: np.ndarray | None = None,
        experiment: np.ndarray | None = None,
    ) -> "SVMRegions":
        """Fit the hyperplanes on the labelled rows.

        Parameters
        ----------
        phi : ndarray of shape (n, d)
        labels : ndarray of shape (n,)
            Sub-model index 0 … s−1 of each row, or −1 (left out).
        n_regions : int, optional
            s (default: the largest label + 1); a label that has no row gets a region that
            is never chosen.
        sample_weight : ndarray of shape (n,), optional
            Weight of each row in the SVM loss; rows weighted 0 are left out.
        target, thetas, output_lags, experiment : optional
            Not used: the SVM separates the labels alone. Accepted so that every region
            step is fitted alike ([`BaseRegions`][pwa_pipeline.pwa.steps.base.BaseRegions]).
        """
        labels = np.asarray(labels)
        d = phi.shape[1]
        s = int(labels.max()) + 1 if n_regions is None else n_regions
        keep = labels >= 0
        if sample_weight is not None:
            keep &= np.asarray(sample_weight, float) > 0
        keep = np.flatnonzero(keep)
        present = np.unique(labels[keep])
        weight = None if sample_weight is None else np.asarray(sample_weight, float)
        if self.max_rows is not None and keep.size > self.max_rows:
            keep, represents = _capped_per_class(keep, labels[keep],
                                                 self.max_rows // present.size,
                                                 np.random.default_rng(self.random_state))
            weight = represents if weight is None else weight[keep] * represents
        elif weight is not None:
            weight = weight[keep]
        x, lab = phi[keep], labels[keep]
        self.n_regions_ = s
        self.coef_ = np.zeros((s, d))
        self.intercept_ = np.full(s, -np.inf)
        if present.size <= 1:
            if present.size == 1:
                self.intercept_[present[0]] = 0.0
            return self
        mean, std = x.mean(axis=0), x.std(axis=0)
        cols = std > 0
        z = (x[:, cols] - mean[cols]) / std[cols]
        # Two classes: Crammer and Singer's problem is the binary hinge-loss SVM with 2C
        # (w_1 = −w_0 = v/2 leaves ¼‖v‖² + C Σ ξ), whose dual solver takes half the time.
        problem = (dict(C=2 * self.C, loss="hinge") if present.size == 2 else
                   dict(C=self.C, multi_class="crammer_singer"))
        svm = LinearSVC(max_iter=50000, random_state=0, tol=self.tol, **problem)
        with warnings.catch_warnings():
            # Where classes overlap (noisy boundaries) the Crammer–Singer dual keeps making tiny
            # updates after the hyperplanes have settled; the regions are scored, not trusted.
            warnings.simplefilter("ignore", ConvergenceWarning)
            svm.fit(z, lab, sample_weight=weight)
        w, b = np.atleast_2d(svm.coef_), np.atleast_1d(svm.intercept_)
        if present.size == 2:
            w, b = np.vstack([-w / 2, w / 2]), np.array([-b[0] / 2, b[0] / 2])
        w_phi = w / std[cols]
        self.coef_[np.ix_(present, np.nonzero(cols)[0])] = w_phi
        self.intercept_[present] = b - w_phi @ mean[cols]
        return self

    def predict(self, phi: Float2D) -> np.ndarray:
        """Region index of each row of φ."""
        check_is_fitted(self)
        if self.n_regions_ == 1:
            return np.zeros(phi.shape[0], dtype=int)
        return np.argmax(phi @ self.coef_.T + self.intercept_, axis=1)

    def compiled(self) -> CompiledForm:
        """argmax_i w_i·φ + b_i (the scores of `predict`); with one region, no
        scores."""
        check_is_fitted(self)
        if self.n_regions_ == 1:
            return "sign", np.zeros((0, self.coef_.shape[1])), np.zeros(0)
        return "argmax", self.coef_, self.intercept_

    def halfspaces(self) -> list[Halfspaces]:
        """H_i = {φ : (w_j − w_i)·φ ≤ b_i − b_j for every j ≠ i} (` argmax_halfspaces`); with one region, all
        of φ-space."""
        check_is_fitted(self)
        if self.n_regions_ == 1:
            return [(np.zeros((0, self.coef_.shape[1])), np.zeros(0))]
        return argmax_halfspaces(self.coef_, self.intercept_)


def _capped_per_class(rows: np.ndarray, labels: np.ndarray, share: int,
                      rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``rows`` with at most ``share`` of each label (a random choice), in row order, and a
    weight per kept row ∝ n_c / kept_c (how many rows of its class it stands for), scaled to
    mean 1: the classes keep their proportions among all rows (an unweighted equal share
    moved the boundary of a 2-mode record far enough to merge its modes).
    """
    kept, represents = [], []
    for c in np.unique(labels):
        r = rows[labels == c]
        take = r if r.size <= share else rng.choice(r, share, replace=False)
        kept.append(take)
        represents.append(np.full(take.size, r.size / take.size))
    kept, represents = np.concatenate(kept), np.concatenate(represents)
    order = np.argsort(kept)
    return kept[order], represents[order] / represents.mean()
