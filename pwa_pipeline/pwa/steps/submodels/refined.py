"""The library default's step 5: sub-models refitted, merged, re-assigned and split."""

from concurrent.futures import ThreadPoolExecutor
from numbers import Integral, Real

import numpy as np
from scipy.stats import chi2
from sklearn.base import BaseEstimator, _fit_context, clone
from sklearn.utils._param_validation import HasMethods, Interval
from sklearn.utils.validation import check_memory

from ...._arrays import array_digest
from ...._blas import single_threaded_blas
from ...._typing import Float2D
from ..base import BaseSubModels
from ..local_models import _spread
from ..neighbours import distinct_rows
from .least_squares import _row_set_key, refit
from .merge import merge_indistinguishable
from .reassign import refine
from .residuals import _cost, _own_sq_residuals, margin_weights, robust_noise_var, unexplained_cost
from .split_search import split_gain

#: Sub-models tried per split search (`RefinedSubModels._best_split`).
SPLIT_CANDIDATES = 2


class RefinedSubModels(BaseSubModels):
    """The library default's step 5: sub-models refitted on their rows, merged when they
    predict alike, rows re-assigned by residual and by region until stable, and a search for
    modes too small to form a cluster.

    1. DBSCAN clusters that predict alike are merged (`merge_indistinguishable`:
       predictions closer than ``merge_tol`` noise variances, or closer than ``copy_tol``
       while no linear classifier on φ tells their rows apart, i.e. copies of one mode);
       then rows are re-assigned by residual alone until stable (`refine`), merging
       again, until nothing merges.
    2. Rows are re-assigned by residual and by the regions, and sub-models refitted, until
       stable (`refine` with the region estimator); sub-models that now predict alike
       are merged and step 2 repeats.
    3. A sub-model whose rows hold two modes that a hyperplane separates is split
       (`split_gain` above ``split_tol``; the largest gain first), and step 2 repeats;
       at most ``n_split`` splits, and rows whose split step 2 undid are not split again.
       Moderate noise (20–25 dB) blurs local models so that DBSCAN can put two modes a few
       noise standard deviations apart into one cluster.
    4. A mode whose local sets were too few to form a cluster shows as rows no sub-model
       explains (`unexplained_cost` above the χ²(m) 99.9 % quantile): local models are
       estimated again among those rows alone (where local sets are purer) with the same
       local-model step, clustered with ε from the data, the new clusters join as
       sub-models, and step 2 repeats; at most ``n_search`` searches, and only while each
       leaves fewer rows unexplained.

    Sub-models need at least max(d + 1, MinPts) rows. On a record of more than
    `max_rows` regressor rows, steps 1–4 run on `max_rows` of them (the rows DBSCAN
    clustered, then a seeded random choice of the others), so that their cost stays
    bounded; the other rows get no label (−1, weight 0: the region step leaves them out).

    Parameters
    ----------
    merge_tol : float, default 1
        Merge two sub-models whose predictions differ by less than this many noise
        variances (mean over their rows of Σ_p Δŷ_p² / σ̂_p²).
    copy_tol : float, optional, default 25
        Merge them below this statistic too when their rows are not separable on φ. None:
        never.
    n_refine : int, default 20
        Largest number of re-assignment sweeps per `refine` call.
    n_search : int, default 3
        Largest number of searches for missed modes.
    split_tol : float, optional, default 1
        Split a sub-model when `split_gain` exceeds this. None: never.
    n_split : int, default 4
        Largest number of splits.
    split_sweep_tol : float, default 0
        A split search's re-assignment (`split_gain`, up to 5 sweeps per start) is
        stable when a sweep moves at most this share of the rows (``tol`` of
        `refine`; 0: when none moves). With moderate noise a few per cent of the rows
        near a boundary move in every sweep, so most starts run to their last sweep; a
        positive value saves those sweeps but can change which split is found, so the
        default keeps 0.
    settle_tol : float, default 2
        The re-assignments with the regions (steps 2–3 and the split search) also end at a
        sweep that keeps the number of sub-models and changes no θ_i by more than this many
        of its standard errors (``settle`` of `refine`, `theta_shift`): with
        moderate noise tens of rows near the boundaries move in every sweep and the
        sub-models wander within their own uncertainty, so the sweeps would run to
        ``n_refine``. 0: only when no row moves (or ``split_sweep_tol``).
    memory : str or object with the joblib.Memory interface, optional
        Cache of steps 2–4, as scikit-learn's ``Pipeline(memory=...)``: a folder (a
        ``joblib.Memory`` there) or an object whose ``cache(func)`` returns ``func`` cached.
        Steps 2–4 are a function of step 1's consolidated labels (with the data, the local
        models, MinPts and these parameters), and hyper-parameter sets that differ only in ε
        or MinPts often consolidate alike, so a sweep fits steps 2–4 once per consolidated
        state. None (default): no caching. The results are the same bit for bit; joblib's
        cache is not emptied when this library changes.
    max_rows : int, optional, default 500000
        Run on at most this many rows (see above). Steps 1–4 take time and memory in
        proportion to the rows (15.5 s and about 0.8 GB for 400,000 rows of the simulated
        section 5 system in `benchmarks.scale`, more with more sub-models): with every row
        of a 5-million-row record they ran for minutes and took 15 GB. None: every row.
    random_state : int, default 0
        Seed of that choice.

    Attributes
    ----------
    thetas_ : ndarray of shape (s, d, m)
    labels_ : ndarray of shape (n,)
        Sub-model of every row (−1 for the rows left out by `max_rows`).
    weights_ : ndarray of shape (n,)
        Region-SVM weight of each row (`margin_weights`; 0 for the rows left out).
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
        "max_rows": [Interval(Integral, 2, None, closed="left"), None],
        "random_state": [Interval(Integral, 0, None, closed="left")],
    }

    def __init__(self, merge_tol: float = 1.0, copy_tol: float | None = 25.0,
                 n_refine: int = 20, n_search: int = 3, split_tol: float | None = 1.0,
                 n_split: int = 4, split_sweep_tol: float = 0.0, settle_tol: float = 2.0,
                 memory=None, max_rows: int | None = 500_000, random_state: int = 0):
        self.merge_tol = merge_tol
        self.copy_tol = copy_tol
        self.n_refine = n_refine
        self.n_search = n_search
        self.split_tol = split_tol
        self.n_split = n_split
        self.split_sweep_tol = split_sweep_tol
        self.settle_tol = settle_tol
        self.memory = memory
        self.max_rows = max_rows
        self.random_state = random_state

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, phi: Float2D, target: Float2D, local, clustering, regions
            ) -> "RefinedSubModels":
        """Steps 1–4 of the class description.

        Parameters
        ----------
        phi : ndarray of shape (n, d)
        target : ndarray of shape (n, m)
        local : fitted LocalLeastSquares
            Cloned (with its parameters) for the missed-mode search.
        clustering : fitted DBSCANClustering
            Its labels start the refinement; cloned for the missed-mode search.
        regions : unfitted SVMRegions
            The region estimator of step 6, used to keep rows region-consistent.
        """
        n = phi.shape[0]
        subset = self.rows(clustering.labels_)
        local_theta = local.theta_ if subset is None else local.theta_[subset]
        if subset is not None:
            phi, target = phi[subset], target[subset]
        min_pts = clustering.min_pts_
        min_size = max(phi.shape[1] + 1, min_pts)
        merge = dict(tol=self.merge_tol, copy_tol=self.copy_tol, regions=regions)
        labels = clustering.labels_.copy() if subset is None else clustering.labels_[subset]
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
        # the cache keys on a digest of the local models in place of the array itself
        local_key = None if self.memory is None else array_digest(local.theta_)
        consolidated = check_memory(self.memory).cache(_from_consolidated,
                                                       ignore=["local_theta"])
        (self.thetas_, self.labels_, margin, merged, self.n_iter_,
         self.n_split_) = consolidated(clone(self).set_params(memory=None), phi, target, labels,
                                       local_theta, local_key, min_pts,
                                       *_search_steps(local, clustering), regions)
        self.weights_ = margin_weights(margin)
        if subset is not None:  # the rows left out: no label, no weight
            self.labels_ = _spread(self.labels_, subset, n, -1)
            self.weights_ = _spread(self.weights_, subset, n, 0.0)
        self.n_submodels_ = self.thetas_.shape[0]
        self.n_merged_ = n_merged + merged
        return self

    def rows(self, clustered: np.ndarray) -> np.ndarray | None:
        """The rows steps 1–4 run on, given the clustering's labels (−1: not clustered):
        None (every row) up to `max_rows` rows, else `max_rows` of them in row order,
        the clustered ones first, then a seeded random choice of the others."""
        n = clustered.size
        if self.max_rows is None or n <= self.max_rows:
            return None
        rng = np.random.default_rng(self.random_state)
        first = np.flatnonzero(clustered >= 0)
        if first.size >= self.max_rows:
            return np.sort(rng.choice(first, self.max_rows, replace=False))
        others = rng.choice(np.flatnonzero(clustered < 0), self.max_rows - first.size,
                            replace=False)
        return np.sort(np.concatenate([first, others]))

    def _best_split(self, phi, target, labels, local_theta, min_size, regions, searched,
                    split_once):
        """``labels`` with the sub-model of largest `split_gain` above ``split_tol``
        split in two, or None.

        The `SPLIT_CANDIDATES` sub-models whose rows fit worst are tried (largest mean
        Σ_p r_p² / σ̂_p² over their rows, σ̂_p² the `robust_noise_var` of every row
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
    """The unfitted steps 2–4 of the missed-mode search (`_missed_mode_clusters`): the
    fitted ``local`` step's with its n_ρ, and the fitted ``clustering``'s with its MinPts and
    ε from the data."""
    return (clone(local).set_params(n_rho=local.n_rho_),
            clone(clustering).set_params(eps=None, min_pts=clustering.min_pts_))


def _missed_mode_clusters(phi: Float2D, target: Float2D, local, clustering
                          ) -> np.ndarray | None:
    """Steps 2–4 again on the rows no sub-model explains, with the unfitted steps ``local``
    and ``clustering`` (`_search_steps`): the cluster label of each row, or None when
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
                       labels: np.ndarray, local_theta: np.ndarray, local_key: str | None,
                       min_pts: int, search_local, search_clustering, regions) -> tuple:
    """Steps 2–4 of [`RefinedSubModels`][pwa_pipeline.pwa.RefinedSubModels] ``step`` (its ``memory`` None)
    from the consolidated ``labels``: the sub-models, every row's label and margin (`refine`),
    the merges, sweeps and splits done.

    A function of its arguments alone, so that ``RefinedSubModels.memory`` can cache it;
    ``local_key`` (`array_digest` of ``local_theta``, the local
    models' θ_k of eq. 6) stands for ``local_theta`` in the cache's key.
    """
    min_size = max(phi.shape[1] + 1, min_pts)
    limit = chi2.ppf(0.999, target.shape[1])
    merge = dict(tol=step.merge_tol, copy_tol=step.copy_tol, regions=regions)
    n_iter, searches, n_split, n_merged, memo = 0, 0, 0, 0, {}
    best, searched, split_once = None, {}, set()
    # The missed-mode search (step 4 of the class description: local models and clusters, no SVM) runs in a
    # second thread beside the split search (step 3, whose SVMs stay in this thread:
    # liblinear draws from one global random generator) and is dropped when a split
    # holds. BLAS single-threaded for both, one limit over the loop (a limit set and
    # restored in one thread would undo the other's).
    with single_threaded_blas(), ThreadPoolExecutor(1) as beside:
        while True:
            thetas, labels, margin, sweeps = refine(phi, target, labels, min_size,
                                                    step.n_refine, regions, memo,
                                                    settle=step.settle_tol)
            n_iter += sweeps
            merged, more = merge_indistinguishable(phi, target, labels, **merge)
            if more:
                labels, n_merged = merged, n_merged + more
                continue
            polished = refine(phi, target, labels, min_size, step.n_refine, memo=memo)
            poor = unexplained_cost(phi, target, polished[0]) > limit
            # the search did not explain more rows: the previous state is kept
            better = best is None or poor.sum() < best[0]
            search = better and searches < step.n_search and poor.sum() >= min_pts
            found = beside.submit(_missed_mode_clusters, phi[poor], target[poor],
                                  search_local, search_clustering) if search else None
            if step.split_tol is not None and n_split < step.n_split:
                split = step._best_split(phi, target, labels, local_theta, min_size,
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
