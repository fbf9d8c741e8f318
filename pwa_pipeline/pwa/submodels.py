"""Sub-model parameter matrices θ_i from clusters (paper step 5) and their refinement.

Two step objects: :class:`ClusterCentres`, the paper's step 5, and :class:`RefinedSubModels`,
the library default. The region estimator (step 6) is passed in by the caller, so this module
imports no other step.
"""

import hashlib
from concurrent.futures import ThreadPoolExecutor
from numbers import Integral, Real
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.stats import chi2
from sklearn.base import BaseEstimator, _fit_context, clone
from sklearn.cluster import KMeans
from sklearn.utils._param_validation import HasMethods, Interval
from sklearn.utils.validation import check_memory

from .._arrays import array_digest, relabel_by_size
from .._typing import Float2D
from ._blas import _controller, single_threaded_blas
from .neighbours import distinct_rows

if TYPE_CHECKING:
    from .local_models import LocalThetas


def _prediction_gaps(phi: Float2D, thetas: np.ndarray, labels: np.ndarray,
                     sigma2: np.ndarray) -> np.ndarray:
    """The statistic of :func:`merge_indistinguishable` for every pair of sub-models: entry
    (i, j) is the mean over the rows labelled i or j of Σ_p (ŷ_i,p − ŷ_j,p)² / σ̂_p², ŷ_i = φᵀθ_i.

    Each label's rows are predicted by every sub-model at once (in groups of sub-models that
    keep the predictions within :data:`_GAP_ENTRIES`) and summed against their own
    sub-model's: time O(s·n·d·m) with a Python step per label, where a loop over the pairs
    took a step per pair (7 s of a SISO fit that starts from a hundred clusters).
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


_GAP_ENTRIES = 1 << 22
"""Largest number of predictions :func:`_prediction_gaps` holds at once (32 MB)."""


def _rows_by_label(labels: np.ndarray, s: int) -> list[np.ndarray]:
    """The rows labelled i, in row order, for i = 0 … s−1 (rows labelled −1 in none)."""
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(s + 1))
    return [order[bounds[i]:bounds[i + 1]] for i in range(s)]


def _row_set_key(rows: np.ndarray) -> bytes:
    """A key of a set of row indices (in row order), for the memos kept over one fit."""
    return hashlib.blake2b(rows.tobytes()).digest()


def cluster_centres(local_theta: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """The paper's sub-models: the mean local θ_k of each cluster (step 5)."""
    s = int(labels.max()) + 1
    return np.stack([local_theta[labels == i].mean(axis=0) for i in range(s)])


def refit(phi: Float2D, target: Float2D, labels: np.ndarray, s: int,
          memo: dict | None = None) -> np.ndarray:
    """Least-squares θ_i on all rows labelled i, i = 0 … s−1 (NaN where a label has < d rows).

    Each θ_i is :func:`least_squares` of its rows. With ``memo`` (a dict kept over calls on
    the same ``phi`` and ``target``) each row set's θ is stored under a hash of its rows and
    taken from there when the rows come again (the sub-models a merge leaves as they were).
    """
    d, m = phi.shape[1], target.shape[1]
    thetas = np.full((s, d, m), np.nan)
    with single_threaded_blas():  # tall, thin solves: threads only wait
        for i, rows in enumerate(_rows_by_label(labels, s)):
            key = None if memo is None else _row_set_key(rows)
            if key is not None and key in memo:
                thetas[i] = memo[key]
                continue
            if len(rows) == len(labels):  # one label: every row, no copy
                thetas[i] = least_squares(phi, target)
            elif len(rows) >= d:
                thetas[i] = least_squares(phi[rows], target[rows])
            if key is not None:
                memo[key] = thetas[i].copy()
    return thetas


_NORMAL_COND = 1e6
"""Largest condition number of the column-scaled normal matrix solved as it is."""


def least_squares(phi: Float2D, target: Float2D) -> np.ndarray:
    """``np.linalg.lstsq(phi, target, rcond=None)[0]``, from the normal equations where they
    are well conditioned.

    The columns of φ are scaled to unit norm, and where that normal matrix ΦᵀΦ has a
    condition number below 1e6 its Cholesky solve agrees with ``lstsq`` to ~1e-10 relative
    (1e-12 on the robot) at a fifth of its time on tall records (one product over the rows
    instead of an SVD); otherwise (near rank deficiency) ``lstsq`` itself gives its
    minimum-norm solution.
    """
    gram = phi.T @ phi
    scale = np.sqrt(np.diagonal(gram))
    if np.all(scale > 0):
        gram /= np.outer(scale, scale)
        if np.linalg.cond(gram) < _NORMAL_COND:
            rhs = (phi.T @ target) / scale[:, None]
            return cho_solve(cho_factor(gram), rhs) / scale[:, None]
    return np.linalg.lstsq(phi, target, rcond=None)[0]


def output_lag_columns(n_outputs: int, na: int, d: int) -> np.ndarray:
    """Output of each φ column in the order of eq. (3) (per output its na lags first, as
    :func:`~pwa_pipeline.pwa.regressors.lagged_matrix` builds φ), −1 for input lags and the
    constant."""
    return np.concatenate([np.repeat(np.arange(n_outputs), na),
                           np.full(d - n_outputs * na, -1)])


def bias_compensated_refit(phi: Float2D, target: Float2D, weights: np.ndarray,
                           lag_output: np.ndarray, n_iter: int = 30, rtol: float = 1e-6
                           ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Weighted least-squares θ_i with the bias of noisy output lags compensated (BCLS).

    Measurement noise e_q (white, variance σ_q²) on the outputs enters φ through the output
    lags, and least squares is biased: E[ΦᵀWΦ]/Σw = Φ₀ᵀWΦ₀/Σw + D with D = diag(σ²_q(c)) on
    the output-lag columns c. The bias-compensated estimate (Sagara & Wada 1977; Zheng 1998)
    solves (ΦᵀWΦ − Σw·D) θ_i = ΦᵀWy. σ̂² comes from the least-squares residuals: with
    J_ip the weighted mean squared residual of output p under θ_i^LS,
    E J_ip = σ_p² + Σ_c σ²_q(c) θ_i,cp θ_i,cp^LS, pooled over the sub-models (weighted by
    Σw, one noise for all) and solved for σ² (m linear equations); θ and σ̂² are iterated
    to a fixed point.

    Guarded: when σ̂² is not finite and within (0, J̄_p] (J̄_p the pooled mean squared
    residual, which would be σ_p² if the lags were noise-free), the iteration does not
    converge in ``n_iter`` steps, or a compensated matrix is not positive definite, the
    affected θ_i (all of them, for σ̂²) keep least squares.

    Parameters
    ----------
    phi : ndarray of shape (n, d)
    target : ndarray of shape (n, m)
    weights : ndarray of shape (n, s)
        Weight of each row in each sub-model's fit (e.g. posterior probabilities).
    lag_output : ndarray of shape (d,)
        :func:`output_lag_columns`: output of each column, −1 where noise-free.

    Returns
    -------
    thetas : ndarray of shape (s, d, m)
    sigma2 : ndarray of shape (m,), or None when σ̂² was implausible
    compensated : ndarray of shape (s,), bool
        Which θ_i are bias-compensated (the others are least squares).
    """
    m = target.shape[1]
    lag = lag_output >= 0
    total = weights.sum(axis=0)
    weighted = [phi * w[:, None] for w in weights.T]
    grams = np.stack([wp.T @ phi for wp in weighted])
    rhs = np.stack([wp.T @ target for wp in weighted])
    ls = np.stack([np.linalg.lstsq(g, r, rcond=None)[0] for g, r in zip(grams, rhs)])
    mean_sq = np.stack([w @ (target - phi @ th) ** 2 for w, th in zip(weights.T, ls)]
                       ) / total[:, None]
    share = total / total.sum()
    j_bar = share @ mean_sq
    owner = np.zeros((lag_output.size, m))  # column c → one-hot of its output q(c)
    owner[np.flatnonzero(lag), lag_output[lag]] = 1.0
    thetas = ls.copy()
    for _ in range(n_iter):
        # J̄_p = σ_p² + Σ_q σ_q² M_pq, M_pq = Σ_i share_i Σ_{c of q} θ_i,cp θ_i,cp^LS
        prod = np.einsum("i,icp,icp->cp", share, thetas, ls)
        new_sigma2 = np.linalg.solve(np.eye(m) + prod.T @ owner, j_bar)
        if not (np.all(np.isfinite(new_sigma2)) and np.all(new_sigma2 > 0)
                and np.all(new_sigma2 <= j_bar)):
            return ls, None, np.zeros(len(total), bool)
        diag = owner @ new_sigma2
        new, done = ls.copy(), np.ones(len(total), bool)
        for i in range(len(total)):
            try:
                new[i] = cho_solve(cho_factor(grams[i] - total[i] * np.diag(diag)), rhs[i])
            except np.linalg.LinAlgError:
                done[i] = False
        step = np.abs(new - thetas).max() / max(np.abs(new).max(), np.finfo(float).tiny)
        thetas, sigma2 = new, new_sigma2
        if step < rtol:
            return thetas, sigma2, done
    return ls, None, np.zeros(len(total), bool)


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
    copy_tol: float | None = None, regions=None,
) -> tuple[np.ndarray, int]:
    """Greedily merge pairs of sub-models that predict alike on their own data.

    For sub-models i, j (least-squares fits on their rows) the statistic is the mean over the
    rows of both of Σ_p ((θ_i − θ_j)ᵀφ)_p² / σ̂_p², the squared difference of their
    predictions in units of the noise variance σ̂_p² (:func:`robust_noise_var`). A pair is
    mergeable when the statistic is below ``tol``, or below ``copy_tol`` while a linear
    classifier on φ (``regions``, an unfitted region estimator such as
    :class:`~pwa_pipeline.pwa.regions.SVMRegions`) cannot tell their rows apart
    (:func:`separable` is false): then they are
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
        # row sets: linear in the merges, where testing every pair at every merge was cubic.
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
    residual labels (rows weighted by :func:`margin_weights`) and re-labels every row by its
    region, so that the sub-models' rows are region-consistent. The assignment is stable
    when a sweep keeps the number of sub-models and moves at most ``tol`` × n rows (0: none),
    or, with ``settle`` > 0, changes no θ_i by more than ``settle`` of its standard errors
    (:func:`theta_shift`): with moderate noise rows near a boundary move in every sweep and
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
    the sub-models alike; :func:`refine` tests it only when a sweep keeps their count).
    """
    if before.shape != after.shape:
        return np.nan
    d, m = after.shape[1:]
    shift = [_cost((phi[labels == i] @ (after[i] - before[i])) ** 2, sigma2).sum()
             for i in range(after.shape[0])]
    return float(np.sqrt(np.max(shift) / (d * m)))


def _sweep(phi: Float2D, target: Float2D, thetas: np.ndarray, min_size: int, regions
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One sweep of :func:`refine` from the least-squares sub-models ``thetas`` of its
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
    best = sq[np.argmin(_cost(sq), axis=0), np.arange(phi.shape[0])]
    return _cost(best, robust_noise_var(best))


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


#: Sub-models tried per split search (:meth:`RefinedSubModels._best_split`).
SPLIT_CANDIDATES = 2

#: Screening of a large split search (:func:`split_gain`): above ``SCREEN_SIZE`` entries of
#: the searched φ, the search first runs with the region SVM's tolerance at ``SCREEN_TOL``,
#: and a gain below ``SCREEN`` × the caller's bar ends it. On the robot's one sub-model
#: (2,000 × 24 searched) the screen takes a quarter of the search's time and gains 0.72
#: (the search: 0.72 too). On the tuning seeds of every case (with the first two starts),
#: of 66 searches that split (gain above 1), those gaining 1–2 screened at 0.88–1.04 × their
#: gain, and none screened below 1.06. Below the size the SVM converges in a few passes at
#: any tolerance and a screen would cost as much as the search: no simulated case of
#: ``benchmarks.robustness`` is screened.
SCREEN_TOL, SCREEN, SCREEN_SIZE = 0.1, 0.8, 20_000


def split_gain(phi: Float2D, target: Float2D, local_theta: "np.ndarray | LocalThetas",
               min_size: int, n_iter: int, regions, merge_tol: float = 1.0, max_rows: int = 2000,
               seed: int = 0, at_least: float = -np.inf, tol: float = 0.0,
               settle: float = 0.0) -> tuple[float, np.ndarray | None]:
    """Whether the rows of one sub-model hold two modes that the regions separate.

    Three starts, refined by residual and by region (:func:`refine` with ``regions``) so
    that the two parts are the two sides of a hyperplane in φ: the rows' local models θ_k
    (z-scored) split in two by k-means (two modes of similar size; :func:`_kmeans_start`),
    the rows that one
    sub-model fitted to all of them leaves unexplained (:func:`robust_noise_var`-normalised
    residual above the χ²(m) 90 % quantile; a small mode inside a large one), and the best
    split at a threshold of one regressor (:func:`_axis_start`; two modes whose local models
    noise has blurred together, as two 5 % modes of the section 5 system at 20 dB). The
    start of larger gain is kept. The gain is the Gaussian log-likelihood ratio of the two
    sub-models against one, ½ n Σ_p ln(RSS_1,p / RSS_2,p), in units of
    (d·m + d + 1)·ln n: twice BIC's penalty for the second sub-model and its hyperplane
    (a split point chosen from the data earns more than a regular parameter). One mode split
    in two gains little (below 0.3 on the section 5 system at 30 dB); two modes 1–3 noise
    standard deviations apart, merged at 20 dB, gain 2–11. A split whose two sub-models
    predict alike (the statistic of :func:`merge_indistinguishable` below ``merge_tol``)
    would be merged again and gains nothing. Above ``max_rows`` rows the split is searched
    on a seeded random ``max_rows`` of them and extended to all by the regions fitted to it,
    when the gain exceeds ``at_least`` (a split the caller would reject is not extended).
    With ``at_least`` > 0 a large search is screened first (:data:`SCREEN_SIZE`; ``regions``
    with a ``tol`` parameter, as :class:`~.regions.SVMRegions`). ``tol`` and ``settle`` are
    those of :func:`refine`. ``local_theta`` holds the rows' θ_k: an array of shape
    (n, d, m), NaN where a row has no local model, or a fitted step's
    :meth:`~pwa_pipeline.pwa.local_models.LocalLeastSquares.local_thetas` of these rows.

    Returns
    -------
    gain : float
        −inf when no split keeps two sub-models that predict apart; the screened gain when
        the screen ended the search.
    labels : ndarray of shape (n,) or None
        0/1 of each row in the split; None when the gain is −inf or the screen ended the
        search, or when it is at most ``at_least`` on more than ``max_rows`` rows.
    """
    n_all, d = phi.shape
    m = target.shape[1]
    if n_all < 2 * min_size:
        return -np.inf, None
    rows = np.arange(n_all) if n_all <= max_rows else np.sort(
        np.random.default_rng(seed).choice(n_all, max_rows, replace=False))
    x, t = phi[rows], target[rows]
    n = rows.size
    one = refit(x, t, np.zeros(n, int), 1)[0]
    sq = (t - x @ one) ** 2
    starts = [(_cost(sq, robust_noise_var(sq)) > chi2.ppf(0.9, m)).astype(int)]
    kmeans = _kmeans_start(x, t, local_theta[rows], d)
    if kmeans is not None:
        starts.insert(0, kmeans)
    axis = _axis_start(x, t, min_size)
    if axis is not None:
        starts.append(axis)
    penalty = (d * m + d + 1) * np.log(n)
    search = dict(starts=starts, rss1=np.maximum(sq.sum(axis=0), np.finfo(float).tiny),
                  min_size=min_size, n_iter=n_iter, merge_tol=merge_tol, tol=tol,
                  settle=settle)
    if at_least > 0 and x.size > SCREEN_SIZE and "tol" in regions.get_params():
        loose = clone(regions).set_params(tol=max(regions.get_params()["tol"], SCREEN_TOL))
        screened = _split_search(x, t, regions=loose, **search)[0] / penalty
        if screened < SCREEN * at_least:
            return screened, None
    gain, labels = _split_search(x, t, regions=regions, **search)
    if labels is None:
        return -np.inf, None
    gain /= penalty
    if n < n_all:
        labels = clone(regions).fit(x, labels, 2).predict(phi) if gain > at_least else None
    return gain, labels


def _kmeans_start(phi: Float2D, target: Float2D, local_theta: "np.ndarray | LocalThetas",
                  min_rows: int) -> np.ndarray | None:
    """0/1 of each row: its local model θ_k's side of a k-means split of the rows' local
    models (z-scored); a row without a local model (``LocalLeastSquares.max_sets``) takes
    the side whose rows' least-squares sub-model fits it better (smaller Σ_p r_p²). None
    when fewer than 2·``min_rows`` rows have a local model, or, where some rows have none,
    when a side has fewer than ``min_rows``."""
    have, emb = _with_local_model(local_theta)
    emb = emb.reshape(len(emb), -1)
    if len(emb) < 2 * min_rows:
        return None
    scale = emb.std(axis=0)
    emb = emb / np.where(scale > 0, scale, 1.0)
    with _controller().limit(limits=1, user_api="openmp"):
        # no OpenMP worker threads: GNU OpenMP deadlocks in a child forked after they start
        side = KMeans(2, n_init=4, random_state=0).fit_predict(emb)
    if have.all():
        return side
    if np.bincount(side, minlength=2).min() < min_rows:
        return None
    two = refit(phi[have], target[have], side, 2)
    out = np.empty(len(phi), int)
    out[have] = side
    out[~have] = _argmin_labels(_sq_residuals(phi[~have], target[~have], two), None)
    return out


def _with_local_model(local_theta: "np.ndarray | LocalThetas"
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Which rows of ``local_theta`` have a local model, and their θ_k: of an array of shape
    (n, d, m) the rows without NaN, of a
    :class:`~pwa_pipeline.pwa.local_models.LocalThetas` its :meth:`estimated`."""
    if isinstance(local_theta, np.ndarray):
        have = ~np.isnan(local_theta[:, 0, 0])
        return have, local_theta[have]
    return local_theta.estimated()


def _axis_start(phi: Float2D, target: Float2D, min_size: int,
                quantiles: np.ndarray = np.linspace(0.1, 0.9, 9)) -> np.ndarray | None:
    """0/1 of each row: the split at a ``quantiles`` value of one column of φ whose two
    least-squares sub-models leave the smallest Σ_p ln RSS_p (a model-tree split), or None
    when no split leaves max(``min_size``, d + 1) rows on each side.

    Per column the rows are sorted once, the normal equations of each side are summed from
    those of the blocks between cuts, and every side's θ is solved at once (as
    :func:`least_squares` does, up to rounding; ``lstsq`` on its rows where ill-conditioned).
    """
    n, d = phi.shape
    floor = max(min_size, d + 1)
    best, out = np.inf, None
    for j in np.flatnonzero(phi.std(axis=0) > 0):
        order = np.argsort(phi[:, j], kind="stable")
        x, t = phi[order], target[order]
        ends = np.searchsorted(x[:, j], np.quantile(phi[:, j], quantiles), side="right")
        ends = ends[np.minimum(ends, n - ends) >= floor]  # rows ≤ cut: the first `end`
        if ends.size == 0:
            continue
        bounds = np.concatenate([[0], ends, [n]])
        blocks = np.stack([np.hstack([x[lo:hi], t[lo:hi]]).T @ x[lo:hi]
                           for lo, hi in zip(bounds[:-1], bounds[1:])])  # [ΦᵀΦ; YᵀΦ]
        sums = np.concatenate([np.cumsum(blocks, axis=0)[:-1],  # below each cut
                               np.cumsum(blocks[::-1], axis=0)[::-1][1:]])  # above
        rows = [slice(0, e) for e in ends] + [slice(e, n) for e in ends]
        thetas = _normal_solves(sums[:, :d], np.swapaxes(sums[:, d:], 1, 2))
        for i in np.flatnonzero(np.isnan(thetas).any(axis=(1, 2))):
            thetas[i] = np.linalg.lstsq(x[rows[i]], t[rows[i]], rcond=None)[0]
        sq = _sq_residuals(x, t, thetas)
        rss = np.stack([sq[i, r].sum(axis=0) for i, r in enumerate(rows)])
        cost = np.log(np.maximum(rss[:ends.size] + rss[ends.size:], np.finfo(float).tiny)
                      ).sum(axis=1)
        q = int(np.argmin(cost))
        if cost[q] < best:
            best, out = float(cost[q]), np.zeros(n, int)
            out[order[ends[q]:]] = 1
    return out


def _normal_solves(grams: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """The normal-equation solves of :func:`least_squares` for a stack of ΦᵀΦ (k, d, d) and
    ΦᵀY (k, d, m) at once (LU, not Cholesky: the same θ up to rounding); NaN where
    :func:`least_squares` would fall back to ``lstsq``."""
    scale = np.sqrt(np.maximum(np.diagonal(grams, axis1=1, axis2=2), 0.0))
    out = np.full(rhs.shape, np.nan)
    ok = np.flatnonzero(np.all(scale > 0, axis=1))
    if ok.size == 0:
        return out
    scaled = grams[ok] / (scale[ok, :, None] * scale[ok, None, :])
    well = np.linalg.cond(scaled) < _NORMAL_COND
    ok, scaled = ok[well], scaled[well]
    out[ok] = np.linalg.solve(scaled, rhs[ok] / scale[ok, :, None]) / scale[ok, :, None]
    return out


def _split_search(phi: Float2D, target: Float2D, starts: list, rss1: np.ndarray,
                  min_size: int, n_iter: int, regions, merge_tol: float, tol: float,
                  settle: float) -> tuple[float, np.ndarray | None]:
    """The log-likelihood ratio and labels of the best split of :func:`split_gain` from
    ``starts`` ((−inf, None) when none keeps two sub-models that predict apart); ``rss1``
    is the residual sum of squares of one sub-model, per output. The starts share one
    :func:`refine` memo: starts that reach the same labels share their further sweeps."""
    tiny = np.finfo(float).tiny
    best, memo = (-np.inf, None), {}
    for start in starts:
        thetas, labels = refine(phi, target, start, min_size, n_iter, regions, memo, tol=tol,
                                settle=settle)[:2]
        if thetas.shape[0] < 2:
            continue
        own = _own_sq_residuals(phi, target, thetas, labels)
        apart = _cost((phi @ (thetas[0] - thetas[1])) ** 2, robust_noise_var(own)).mean()
        gain = 0.5 * phi.shape[0] * float(np.log(rss1 / np.maximum(own.sum(axis=0), tiny)).sum())
        if apart >= merge_tol and gain > best[0]:
            best = (gain, labels)
    return best


class ClusterCentres(BaseEstimator):
    """The paper's step 5: each sub-model θ_i is the mean of the local θ_k of cluster i.

    Rows of local models DBSCAN labelled noise keep the label −1 (the region SVM leaves them
    out). No parameters.

    Attributes
    ----------
    thetas_ : ndarray of shape (s, d, m)
    labels_ : ndarray of shape (n,)
        DBSCAN's cluster of each row (−1: noise).
    weights_ : None
        Every clustered row weighs alike in the region SVM.
    n_submodels_ : int
    n_merged_, n_split_, n_iter_ : int
        0 (nothing is merged, split or refined).
    """

    _parameter_constraints: dict = {}

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, phi: Float2D, target: Float2D, local, clustering, regions=None
            ) -> "ClusterCentres":
        """Average the fitted ``local`` models (``theta_``) over ``clustering.labels_``.

        ``phi``, ``target`` and ``regions`` are not used; the signature is that of every
        sub-model step.
        """
        self.labels_ = clustering.labels_
        clustered = self.labels_ >= 0  # (estimated samples: read without spreading θ_k)
        self.thetas_ = cluster_centres(local.at_estimated("theta_", clustered),
                                       self.labels_[clustered])
        self.weights_ = None
        self.n_submodels_ = self.thetas_.shape[0]
        self.n_merged_ = self.n_split_ = self.n_iter_ = 0
        return self


class RefinedSubModels(BaseEstimator):
    """The library default's step 5: sub-models refitted on their rows, merged when they
    predict alike, rows re-assigned by residual and by region until stable, and a search for
    modes too small to form a cluster.

    1. DBSCAN clusters that predict alike are merged (:func:`merge_indistinguishable`:
       predictions closer than ``merge_tol`` noise variances, or closer than ``copy_tol``
       while no linear classifier on φ tells their rows apart, i.e. copies of one mode);
       then rows are re-assigned by residual alone until stable (:func:`refine`), merging
       again, until nothing merges.
    2. Rows are re-assigned by residual and by the regions, and sub-models refitted, until
       stable (:func:`refine` with the region estimator); sub-models that now predict alike
       are merged and step 2 repeats.
    3. A sub-model whose rows hold two modes that a hyperplane separates is split
       (:func:`split_gain` above ``split_tol``; the largest gain first), and step 2 repeats;
       at most ``n_split`` splits, and rows whose split step 2 undid are not split again.
       Moderate noise (20–25 dB) blurs local models so that DBSCAN can put two modes a few
       noise standard deviations apart into one cluster.
    4. A mode whose local sets were too few to form a cluster shows as rows no sub-model
       explains (:func:`unexplained_cost` above the χ²(m) 99.9 % quantile): local models are
       estimated again among those rows alone (where local sets are purer) with the same
       local-model step, clustered with ε from the data, the new clusters join as
       sub-models, and step 2 repeats; at most ``n_search`` searches, and only while each
       leaves fewer rows unexplained.

    Sub-models need at least max(d + 1, MinPts) rows.

    Parameters
    ----------
    merge_tol : float, default 1
        Merge two sub-models whose predictions differ by less than this many noise
        variances (mean over their rows of Σ_p Δŷ_p² / σ̂_p²).
    copy_tol : float, optional, default 25
        Merge them below this statistic too when their rows are not separable on φ. None:
        never.
    n_refine : int, default 20
        Largest number of re-assignment sweeps per :func:`refine` call.
    n_search : int, default 3
        Largest number of searches for missed modes.
    split_tol : float, optional, default 1
        Split a sub-model when :func:`split_gain` exceeds this. None: never.
    n_split : int, default 4
        Largest number of splits.
    split_sweep_tol : float, default 0
        A split search's re-assignment (:func:`split_gain`, up to 5 sweeps per start) is
        stable when a sweep moves at most this share of the rows (``tol`` of
        :func:`refine`; 0: when none moves). At 20 dB 1–3 % of the rows near a boundary move
        in every sweep, so most starts run to their last sweep. 0.01 cut the CPU time of
        the sub-model step of two 20 dB fits by 8 % and 42 %; on the evaluation seeds of
        ``benchmarks.robustness`` every case's mode counts stayed, but the 20 dB median and
        worst largest errors went 0.0647 → 0.0651 and 0.1622 → 0.1629 (8 of 20 seeds moved,
        3 for the worse), so the default keeps 0.
    settle_tol : float, default 2
        The re-assignments with the regions (steps 2–3 and the split search) also end at a
        sweep that keeps the number of sub-models and changes no θ_i by more than this many
        of its standard errors (``settle`` of :func:`refine`, :func:`theta_shift`): at
        20 dB tens of rows near the boundaries move in every sweep and the sub-models
        wander within their own uncertainty, so the sweeps ran to ``n_refine``. On the
        tuning seeds of ``benchmarks.robustness`` at 20 dB, 1 kept the mode count (16/20)
        and the medians at 0.65× the fit's CPU time, and 2 found 17/20 with the medians
        unchanged; on 10 tuning seeds of every case 2 changed no other mode count or
        median. 0: only when no row moves (or ``split_sweep_tol``).
    memory : str or object with the joblib.Memory interface, optional
        Cache of steps 2–4, as scikit-learn's ``Pipeline(memory=...)``: a folder (a
        ``joblib.Memory`` there) or an object whose ``cache(func)`` returns ``func`` cached.
        Steps 2–4 are a function of step 1's consolidated labels (with the data, the local
        models, MinPts and these parameters), and hyper-parameter sets that differ only in ε
        or MinPts often consolidate alike (on the robot every set of ``benchmarks.sweep``
        ends step 1 with all rows in one sub-model), so a sweep fits steps 2–4 once per
        consolidated state. None (default): no caching. The results are the same bit for
        bit; joblib's cache is not emptied when this library changes (the pipeline's cache
        is kept per version of the numerical core).

    Attributes
    ----------
    thetas_ : ndarray of shape (s, d, m)
    labels_ : ndarray of shape (n,)
        Sub-model of every row.
    weights_ : ndarray of shape (n,)
        Region-SVM weight of each row (:func:`margin_weights`).
    n_submodels_ : int
    n_merged_ : int
        Merges done.
    n_split_ : int
        Splits done.
    n_iter_ : int
        Re-assignment sweeps run.
    """

    _parameter_constraints: dict = {
        "merge_tol": [Interval(Real, 0, None, closed="left")],
        "copy_tol": [Interval(Real, 0, None, closed="left"), None],
        "n_refine": [Interval(Integral, 0, None, closed="left")],
        "n_search": [Interval(Integral, 0, None, closed="left")],
        "split_tol": [Interval(Real, 0, None, closed="left"), None],
        "n_split": [Interval(Integral, 0, None, closed="left")],
        "split_sweep_tol": [Interval(Real, 0, 1, closed="both")],
        "settle_tol": [Interval(Real, 0, None, closed="left")],
        "memory": [None, str, HasMethods(["cache"])],
    }

    def __init__(self, merge_tol: float = 1.0, copy_tol: float | None = 25.0,
                 n_refine: int = 20, n_search: int = 3, split_tol: float | None = 1.0,
                 n_split: int = 4, split_sweep_tol: float = 0.0, settle_tol: float = 2.0,
                 memory=None):
        self.merge_tol = merge_tol
        self.copy_tol = copy_tol
        self.n_refine = n_refine
        self.n_search = n_search
        self.split_tol = split_tol
        self.n_split = n_split
        self.split_sweep_tol = split_sweep_tol
        self.settle_tol = settle_tol
        self.memory = memory

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, phi: Float2D, target: Float2D, local, clustering, regions
            ) -> "RefinedSubModels":
        """Steps 1–4 of the class description.

        Parameters
        ----------
        phi : ndarray of shape (n, d)
        target : ndarray of shape (n, m)
        local : fitted :class:`~pwa_pipeline.pwa.local_models.LocalLeastSquares`
            Cloned (with its parameters) for the missed-mode search.
        clustering : fitted :class:`~pwa_pipeline.pwa.clustering.DBSCANClustering`
            Its labels start the refinement; cloned for the missed-mode search.
        regions : unfitted :class:`~pwa_pipeline.pwa.regions.SVMRegions`
            The region estimator of step 6, used to keep rows region-consistent.
        """
        min_pts = clustering.min_pts_
        min_size = max(phi.shape[1] + 1, min_pts)
        merge = dict(tol=self.merge_tol, copy_tol=self.copy_tol, regions=regions)
        labels = clustering.labels_.copy()
        rows = labels >= 0
        labels[rows], n_merged = merge_indistinguishable(phi[rows], target[rows], labels[rows],
                                                         **merge)
        # Consolidate by residual alone first, merging copies: an SVM over many small,
        # overlapping clusters can give all rows to the largest one.
        more, memo = 1, {}
        while more:
            labels = refine(phi, target, labels, min_size, self.n_refine, memo=memo)[1]
            labels, more = merge_indistinguishable(phi, target, labels, **merge)
            n_merged += more
        # the cache's key holds the local models as the digest of the estimated samples and
        # their θ_k (which give theta_, NaN elsewhere), read without spreading a loaded
        # step's arrays (5,000 of the robot's 40k rows)
        local_key = None if self.memory is None else array_digest(local.estimated_,
                                                                  local.estimated_theta())
        consolidated = check_memory(self.memory).cache(_from_consolidated, ignore=["local"])
        (self.thetas_, self.labels_, margin, merged, self.n_iter_,
         self.n_split_) = consolidated(clone(self).set_params(memory=None), phi, target, labels,
                                       local, local_key, min_pts,
                                       *_search_steps(local, clustering), regions)
        self.weights_ = margin_weights(margin)
        self.n_submodels_ = self.thetas_.shape[0]
        self.n_merged_ = n_merged + merged
        return self

    def _from_consolidated(self, phi, target, labels, local_theta, min_pts, search_local,
                           search_clustering, regions):
        """Steps 2–4 from the consolidated ``labels``: the sub-models, every row's label and
        margin (:func:`refine`), the merges, sweeps and splits done."""
        min_size = max(phi.shape[1] + 1, min_pts)
        limit = chi2.ppf(0.999, target.shape[1])
        merge = dict(tol=self.merge_tol, copy_tol=self.copy_tol, regions=regions)
        n_iter, searches, n_split, n_merged, memo = 0, 0, 0, 0, {}
        best, searched, split_once = None, {}, set()
        # The missed-mode search (4. above: local models and clusters, no SVM) runs in a
        # second thread beside the split search (3., whose SVMs stay in this thread:
        # liblinear draws from one global random generator) and is dropped when a split
        # holds. BLAS single-threaded for both, one limit over the loop (a limit set and
        # restored in one thread would undo the other's).
        with single_threaded_blas(), ThreadPoolExecutor(1) as beside:
            while True:
                thetas, labels, margin, sweeps = refine(phi, target, labels, min_size,
                                                        self.n_refine, regions, memo,
                                                        settle=self.settle_tol)
                n_iter += sweeps
                merged, more = merge_indistinguishable(phi, target, labels, **merge)
                if more:
                    labels, n_merged = merged, n_merged + more
                    continue
                polished = refine(phi, target, labels, min_size, self.n_refine, memo=memo)
                poor = unexplained_cost(phi, target, polished[0]) > limit
                # the search did not explain more rows: the previous state is kept
                better = best is None or poor.sum() < best[0]
                search = better and searches < self.n_search and poor.sum() >= min_pts
                found = beside.submit(_missed_mode_clusters, phi[poor], target[poor],
                                      search_local, search_clustering) if search else None
                if self.split_tol is not None and n_split < self.n_split:
                    split = self._best_split(phi, target, labels, local_theta, min_size,
                                             regions, searched, split_once)
                    if split is not None:
                        if found is not None:
                            found.cancel()  # (if not started)
                        labels, n_split = split, n_split + 1
                        continue
                if not better:
                    break
                best = (int(poor.sum()), polished)
                if not search:
                    break
                searches += 1
                extra = found.result()
                if extra is None:
                    break
                labels = labels.copy()
                joins = extra >= 0
                labels[np.nonzero(poor)[0][joins]] = thetas.shape[0] + extra[joins]
        thetas, labels, margin, sweeps = best[1]  # the state kept, polished
        return thetas, labels, margin, n_merged, n_iter + sweeps, n_split

    def _best_split(self, phi, target, labels, local_theta, min_size, regions, searched,
                    split_once):
        """``labels`` with the sub-model of largest :func:`split_gain` above ``split_tol``
        split in two, or None.

        The :data:`SPLIT_CANDIDATES` sub-models whose rows fit worst are tried (largest mean
        Σ_p r_p² / σ̂_p² over their rows, σ̂_p² the :func:`robust_noise_var` of every row
        under its own sub-model: two modes in one sub-model, or a small mode inside a large
        one, inflate it), so that the search costs little on records with many sub-models;
        each split is refined with at most 5 sweeps. ``searched`` (a dict kept over one fit)
        holds each row set's gain and split: the split of a sub-model whose rows come back
        unchanged (after a missed-mode search whose clusters merged away) is not searched
        twice. A row set that was split and came back unchanged (the refinement gave one half's
        rows back to the other sub-models) is in ``split_once`` (a set kept over one fit) and
        is not a candidate again, so that the next worst-fitting sub-model is tried instead of
        spending every split on one that does not hold.
        """
        s = int(labels.max()) + 1
        thetas = refit(phi, target, labels, s)
        own = _own_sq_residuals(phi, target, thetas, labels)
        cost = _cost(own, robust_noise_var(own))
        excess = np.bincount(labels, cost, s) / np.maximum(np.bincount(labels, minlength=s), 1)
        best, tried = (self.split_tol, None, None), 0
        for i in np.argsort(-excess):
            if tried == SPLIT_CANDIDATES:
                break
            rows = np.flatnonzero(labels == i)
            key = _row_set_key(rows)
            if key in split_once:
                continue
            tried += 1
            if key not in searched:  # split_gain depends only on the rows
                searched[key] = split_gain(phi[rows], target[rows], local_theta[rows],
                                           min_size, min(self.n_refine, 5), regions,
                                           self.merge_tol, at_least=self.split_tol,
                                           tol=self.split_sweep_tol, settle=self.settle_tol)
            gain, halves = searched[key]
            if gain > best[0]:
                new = labels.copy()
                new[rows[halves == 1]] = s
                best = (gain, new, key)
        if best[2] is not None:
            split_once.add(best[2])
        return best[1]


def _search_steps(local, clustering) -> tuple[BaseEstimator, BaseEstimator]:
    """The unfitted steps 2–4 of the missed-mode search (:func:`_missed_mode_clusters`): the
    fitted ``local`` step's with its n_ρ, and the fitted ``clustering``'s with its MinPts and
    ε from the data."""
    return (clone(local).set_params(n_rho=local.n_rho_),
            clone(clustering).set_params(eps=None, min_pts=clustering.min_pts_))


def _missed_mode_clusters(phi: Float2D, target: Float2D, local, clustering
                          ) -> np.ndarray | None:
    """Steps 2–4 again on the rows no sub-model explains, with the unfitted steps ``local``
    and ``clustering`` (:func:`_search_steps`): the cluster label of each row, or None when
    there are too few rows or no cluster."""
    n_distinct = len(distinct_rows(np.hstack([phi, target]))[0])  # as step 2 counts them
    n_rho = min(local.n_rho, n_distinct - 1)
    if n_rho <= phi.shape[1]:
        return None
    try:
        sub_local = clone(local).set_params(n_rho=n_rho).fit(phi, target)
        return clone(clustering).fit(sub_local, target).labels_
    except ValueError:
        return None


def _from_consolidated(step: RefinedSubModels, phi: Float2D, target: Float2D,
                       labels: np.ndarray, local, local_key: str | None,
                       min_pts: int, search_local, search_clustering, regions) -> tuple:
    """:meth:`RefinedSubModels._from_consolidated` of ``step`` (no ``memory``) with the
    fitted local-model step's θ_k (:meth:`~pwa_pipeline.pwa.local_models.LocalLeastSquares.local_thetas`,
    read without spreading ``theta_``): a function of its arguments alone, for
    ``RefinedSubModels.memory`` to cache, ``local_key`` (the
    :func:`~pwa_pipeline._arrays.array_digest` of its estimated samples and their θ_k)
    standing for ``local`` in its key."""
    return step._from_consolidated(phi, target, labels, local.local_thetas(), min_pts,
                                   search_local, search_clustering, regions)
