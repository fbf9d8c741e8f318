"""Re-assignment of rows to sub-models by residual, and by region, until stable (step 5)."""

import numpy as np
from sklearn.base import clone

from ...._arrays import relabel_by_size
from ...._typing import Float2D
from .least_squares import refit
from .residuals import _argmin_labels, _cost, _noise_var, _sq_residuals, margin_weights


def refine(
    phi: Float2D,
    target: Float2D,
    labels: np.ndarray,
    min_size: int,
    n_iter: int,
    regions=None,
    memo: dict | None = None,
    tol: float = 0.0,
    settle: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Re-assign rows to sub-models by residual and refit until the assignment is stable.

    Each sweep: every row goes to the sub-model with the smallest noise-normalised residual
    Σ_p (y_p − θ_(p),iᵀφ)² / σ̂_p², sub-models left with fewer than ``min_size`` rows are
    dropped (their rows re-assigned), and every sub-model is refitted by least squares on its
    rows. Rows labelled −1 (DBSCAN noise) are assigned from the first sweep on. With
    ``regions`` (an unfitted region estimator) each sweep then fits the regions on the
    residual labels (rows weighted by `margin_weights`) and re-labels every row by its
    region, so that the sub-models' rows are region-consistent. The assignment is stable
    when a sweep keeps the number of sub-models and moves at most ``tol`` × n rows (0: none),
    or, with ``settle`` > 0, changes no θ_i by more than ``settle`` of its standard errors
    (`theta_shift`): with moderate noise rows near a boundary move in every sweep and
    the sub-models wander within their own uncertainty without settling.

    A sweep is a function of the labels it starts from (its sub-models are their
    least-squares fits), so with ``memo`` (a dict kept over calls on the same ``phi``,
    ``target`` and ``min_size``, e.g. over one fit) each sweep's result is stored under the
    region estimator's parameters and its starting labels, and taken from there when a
    sweep repeats: within a call that cycles through the same labels, and across calls that
    start where an earlier one passed (after a split or a missed-mode search that did not
    hold). The results are those without it, bit for bit.

    Returns
    -------
    thetas : ndarray of shape (s, d, m)
    labels : ndarray of shape (n,)
        Every row labelled.
    margin : ndarray of shape (n,)
        Normalised residual cost of the second-best sub-model minus the best one's.
    n_iter : int
        Sweeps run.

    Raises
    ------
    ValueError
        If ``memo`` was filled by calls on other data.
    """
    labels = relabel_by_size(labels)
    thetas = refit(phi, target, labels, int(labels.max()) + 1)
    if memo is not None and memo.setdefault("data", (id(phi), id(target), min_size)) != (
            id(phi), id(target), min_size):
        raise ValueError("refine's memo holds sweeps of other data (phi, target, min_size)")
    setting = None if regions is None else repr(sorted(regions.get_params().items()))
    it = 0
    for it in range(1, n_iter + 1):
        key, before = (setting, labels.tobytes()), thetas
        if memo is not None and key in memo:
            new, thetas, sigma2 = memo[key]
        else:
            new, thetas, sigma2 = _sweep(phi, target, thetas, min_size, regions)
            if memo is not None:
                memo[key] = (new, thetas, sigma2)
        if new.max() == labels.max() and (
                np.count_nonzero(new != labels) <= tol * new.size
                or settle > 0 and theta_shift(phi, before, thetas, new, sigma2) <= settle):
            break
        labels = new
    cost = np.sort(_cost(_sq_residuals(phi, target, thetas), sigma2), axis=0)
    margin = cost[1] - cost[0] if len(thetas) > 1 else np.full(phi.shape[0], np.inf)
    return thetas.copy(), new.copy(), margin, it


def theta_shift(phi: Float2D, before: np.ndarray, after: np.ndarray, labels: np.ndarray,
                sigma2: np.ndarray) -> float:
    """The largest change of a sub-model between two sweeps, in its standard errors.

    For each i, √(Σ_p ‖Φ_i (θ_i,p^after − θ_i,p^before)‖² / σ̂_p² / (d·m)), Φ_i the rows
    ``labels`` gives sub-model i: the root mean square of the change over the d·m entries
    of θ_i, each in the standard error of its least-squares estimate
    (Cov θ̂_i,p = σ_p² (Φ_iᵀΦ_i)⁻¹), so that 1 is a change as large as the noise makes the
    estimate uncertain. NaN when the two stacks differ in shape or hold NaN (they must number
    the sub-models alike; `refine` tests it only when a sweep keeps their count).
    """
    if before.shape != after.shape:
        return np.nan
    d, m = after.shape[1:]
    shift = [_cost((phi[labels == i] @ (after[i] - before[i])) ** 2, sigma2).sum()
             for i in range(after.shape[0])]
    return float(np.sqrt(np.max(shift) / (d * m)))


def _sweep(phi: Float2D, target: Float2D, thetas: np.ndarray, min_size: int, regions
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One sweep of `refine` from the least-squares sub-models ``thetas`` of its
    starting labels: the new labels, their sub-models and the noise variance σ̂² used."""
    thetas = thetas[~np.isnan(thetas).any(axis=(1, 2))]
    sq = _sq_residuals(phi, target, thetas)
    sigma2 = _noise_var(sq, _argmin_labels(sq, None), len(thetas) * phi.shape[1])
    new = _argmin_labels(sq, sigma2)
    sizes = np.bincount(new, minlength=len(thetas))
    if (sizes < min_size).any() and (sizes >= min_size).any():
        new = _argmin_labels(sq[sizes >= min_size], sigma2)
    new = relabel_by_size(new)
    thetas = refit(phi, target, new, int(new.max()) + 1)
    if regions is not None and thetas.shape[0] > 1:
        cost = np.sort(_cost(_sq_residuals(phi, target, thetas), sigma2), axis=0)
        fitted = clone(regions).fit(phi, new, thetas.shape[0],
                                    sample_weight=margin_weights(cost[1] - cost[0]))
        new = fitted.predict(phi)
        sizes = np.bincount(new, minlength=thetas.shape[0])
        if (sizes < min_size).any():
            sq = _sq_residuals(phi, target, thetas[sizes >= min_size])
            new = _argmin_labels(sq, sigma2)
        new = relabel_by_size(new)
        thetas = refit(phi, target, new, int(new.max()) + 1)
    return new, thetas, sigma2
