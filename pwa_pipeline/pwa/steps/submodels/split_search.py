"""The search for two modes inside one sub-model that a hyperplane separates (step 5)."""

import numpy as np
from scipy.stats import chi2
from sklearn.base import clone
from sklearn.cluster import KMeans

from ...._blas import _controller
from ...._typing import Float2D
from .least_squares import _normal_solves, refit
from .reassign import refine
from .residuals import _argmin_labels, _cost, _own_sq_residuals, _sq_residuals, robust_noise_var

#: Screening of a large split search (`split_gain`): above ``SCREEN_SIZE`` entries of
#: the searched φ, the search first runs with the region SVM's tolerance at ``SCREEN_TOL``,
#: and a gain below ``SCREEN`` × the caller's bar ends it. A loose SVM tolerance costs a
#: fraction of a tight one on a large search and gives nearly the same gain (splits that
#: hold screen at about 0.9–1.0 × their gain), so a search that cannot reach the bar ends
#: early. Below the size the SVM converges in a few passes at any tolerance and a screen
#: would cost as much as the search.
SCREEN_TOL, SCREEN, SCREEN_SIZE = 0.1, 0.8, 20_000


def split_gain(phi: Float2D, target: Float2D, local_theta: np.ndarray,
               min_size: int, n_iter: int, regions, merge_tol: float = 1.0, max_rows: int = 2000,
               seed: int = 0, at_least: float = -np.inf, tol: float = 0.0,
               settle: float = 0.0) -> tuple[float, np.ndarray | None]:
    """Whether the rows of one sub-model hold two modes that the regions separate.

    Three starts, refined by residual and by region (`refine` with ``regions``) so
    that the two parts are the two sides of a hyperplane in φ: the rows' local models θ_k
    (z-scored) split in two by k-means (two modes of similar size; `_kmeans_start`),
    the rows that one
    sub-model fitted to all of them leaves unexplained (`robust_noise_var`-normalised
    residual above the χ²(m) 90 % quantile; a small mode inside a large one), and the best
    split at a threshold of one regressor (`_axis_start`; two modes whose local models
    noise has blurred together, as two 5 % modes of the section 5 system at 20 dB). The
    start of larger gain is kept. The gain is the Gaussian log-likelihood ratio of the two
    sub-models against one, ½ n Σ_p ln(RSS_1,p / RSS_2,p), in units of
    (d·m + d + 1)·ln n: twice BIC's penalty for the second sub-model and its hyperplane
    (a split point chosen from the data earns more than a regular parameter). One mode split
    in two gains little (below 0.3 on the section 5 system at 30 dB); two modes 1–3 noise
    standard deviations apart, merged at 20 dB, gain 2–11. A split whose two sub-models
    predict alike (the statistic of `merge_indistinguishable` below ``merge_tol``)
    would be merged again and gains nothing. Above ``max_rows`` rows the split is searched
    on a seeded random ``max_rows`` of them and extended to all by the regions fitted to it,
    when the gain exceeds ``at_least`` (a split the caller would reject is not extended).
    With ``at_least`` > 0 a large search is screened first (`SCREEN_SIZE`; ``regions``
    with a ``tol`` parameter, as [`SVMRegions`][pwa_pipeline.pwa.SVMRegions]). ``tol`` and ``settle`` are
    those of `refine`. ``local_theta`` holds the rows' θ_k (eq. 6), shape (n, d, m),
    NaN where a row has no local model.

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


def _kmeans_start(phi: Float2D, target: Float2D, local_theta: np.ndarray,
                  min_rows: int) -> np.ndarray | None:
    """0/1 of each row: its local model θ_k's side of a k-means split of the rows' local
    models (z-scored); a row without a local model (``LocalLeastSquares.max_sets``) takes
    the side whose rows' least-squares sub-model fits it better (smaller Σ_p r_p²). None
    when fewer than 2·``min_rows`` rows have a local model, or, where some rows have none,
    when a side has fewer than ``min_rows``."""
    have = ~np.isnan(local_theta[:, 0, 0])
    emb = local_theta[have]
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


def _axis_start(phi: Float2D, target: Float2D, min_size: int,
                quantiles: np.ndarray = np.linspace(0.1, 0.9, 9)) -> np.ndarray | None:
    """0/1 of each row: the split at a ``quantiles`` value of one column of φ whose two
    least-squares sub-models leave the smallest Σ_p ln RSS_p (a model-tree split), or None
    when no split leaves max(``min_size``, d + 1) rows on each side.

    Per column the rows are sorted once, the normal equations of each side are summed from
    those of the blocks between cuts, and every side's θ is solved at once (as
    `least_squares` does, up to rounding; ``lstsq`` on its rows where ill-conditioned).
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


def _split_search(phi: Float2D, target: Float2D, starts: list, rss1: np.ndarray,
                  min_size: int, n_iter: int, regions, merge_tol: float, tol: float,
                  settle: float) -> tuple[float, np.ndarray | None]:
    """The log-likelihood ratio and labels of the best split of `split_gain` from
    ``starts`` ((−inf, None) when none keeps two sub-models that predict apart); ``rss1``
    is the residual sum of squares of one sub-model, per output. The starts share one
    `refine` memo: starts that reach the same labels share their further sweeps."""
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
