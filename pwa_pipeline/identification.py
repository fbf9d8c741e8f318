"""The PWARX estimator: MIMO piecewise-affine ARX identification by extended DBSCAN."""

import time
from dataclasses import dataclass
from numbers import Integral, Real

import numpy as np
from scipy.stats import chi2
from sklearn.base import _fit_context
from sklearn.utils._param_validation import Interval, StrOptions

from ._typing import Float2D, Signals
from ._validation import as_experiments
from .arx import ARXModelBase
from .clustering import Clustering, cluster_local_models, confident_models
from .local_models import LocalModels, column_rms, estimate_local_models
from .regions import Regions, fit_regions
from .regressors import Regressors, build_regressors
from .submodels import (
    SubModels,
    cluster_centres,
    margin_weights,
    merge_indistinguishable,
    refine,
    unexplained_cost,
)


@dataclass(frozen=True)
class Settings:
    """Resolved choices of one identification run (see :class:`PWARX`)."""

    n_rho: int
    min_pts: int
    eps: float | None
    embedding: str
    standardize: bool
    scale_theta: bool
    confidence: float | None
    submodel: str
    merge_tol: float | None
    copy_tol: float | None
    n_refine: int
    n_search: int
    ridge: float
    svm_c: float
    max_cluster: int | None
    seed: int


_PRESETS = {
    "paper": dict(standardize=False, scale_theta=False, confidence=None, submodel="centre",
                  merge_tol=None, copy_tol=None, n_refine=0, n_search=0,
                  max_cluster=None),
    "default": dict(standardize=True, scale_theta=True, confidence=3.0, submodel="refit",
                    merge_tol=1.0, copy_tol=25.0, n_refine=20, n_search=3,
                    max_cluster=3000),
}


class PWARX(ARXModelBase):
    """MIMO piecewise-affine ARX model identified by clustering local models (Lassoued &
    Abderrahim 2023).

    y(k) = θ_iᵀ φ(k) when φ(k) ∈ H_i (eq. 1), φ(k) from eq. (2)–(3). The fit follows the
    paper's steps: regressors, local sets of n_ρ neighbours, local least squares (eq. 6–7),
    DBSCAN on the Vθ distance (eq. 8–10), one sub-model per cluster, and regions by a
    multi-class linear SVM.

    Parameters
    ----------
    na, nb : int
        Output and input orders (eq. 3).
    n_rho : int, optional
        Local set size n_ρ (> d). Default: 3·d with ``settings="default"``; required with
        ``"paper"``.
    eps : float, optional
        DBSCAN radius ε. Default: chosen from the k-distance curve
        (:func:`pwa_pipeline.clustering.k_distance_eps`); the value used is ``eps_``.
    min_pts : int, optional
        DBSCAN MinPts. Default: 2·d.
    affine : bool, default False
        Append the constant 1 to φ (eq. 2).
    settings : {"default", "paper"}
        ``"paper"`` reproduces the paper: raw regressors in the neighbour search, DBSCAN on
        θ_k as it is, sub-models as cluster centres (step 5), SVM trained on the clustered
        rows, noise rows left out. ``"default"`` is the robust variant: z-scored neighbour
        search, θ_k made unit-free (scaled by the regressors' and outputs' RMS) before the
        Vθ distance, local models with a residual variance over 3× the median left out (and
        at most 3,000 of them clustered), then sub-models refitted by least squares, rows
        re-assigned by residual and by SVM regions until stable, sub-models merged when their
        predictions differ by less than the noise (or are copies of one mode that no linear
        classifier on φ tells apart), and rows no sub-model explains clustered again for
        modes too small for the first pass (see ``_refined_submodels``).
    embedding : {"exact", "literal"}
        DBSCAN on the literal Vθ of eq. (9), or on the d·m-dimensional map with the same
        distances (faster, same labels).
    ridge : float, default 0
        Tikhonov term for degenerate local sets (0: a singular local set raises).
    svm_c : float, default 1
        Regularisation of the region SVM.
    random_state : int, default 0
        Seed of the subset of local models the default setting clusters on long records
        (at most 3,000 confident local models go to DBSCAN; all rows are used afterwards).

    Attributes
    ----------
    thetas_ : ndarray of shape (s, d, m)
        Sub-model parameter matrices θ_i (eq. 4).
    n_submodels_ : int
    labels_ : ndarray of shape (n,)
        Sub-model of each training regressor row (−1: noise, paper setting only).
    regions_ : Regions
        The hyperplanes of H_i; ``regions_.predict(phi)``.
    cluster_labels_ : ndarray of shape (n,)
        DBSCAN's label of each local model (−1: noise).
    eps_, n_rho_, min_pts_ : the values used.
    noise_share_ : float
        Share of local models DBSCAN labelled noise.
    n_inputs_, n_outputs_ : int
    timings_ : dict
        Seconds spent in each step.

    Examples
    --------
    >>> import numpy as np
    >>> from pwa_pipeline.datasets import make_hure_vasak
    >>> from pwa_pipeline.identification import PWARX
    >>> data = make_hure_vasak(n_samples=2000, snr_db=None, seed=0)
    >>> model = PWARX(na=1, nb=1).fit(data.u, data.y)
    >>> model.n_submodels_
    4
    >>> bool(np.allclose(np.sort(model.thetas_, axis=0), np.sort(data.thetas, axis=0)))
    True
    """

    _parameter_constraints: dict = {
        "na": [Interval(Integral, 0, None, closed="left")],
        "nb": [Interval(Integral, 0, None, closed="left")],
        "n_rho": [Interval(Integral, 2, None, closed="left"), None],
        "eps": [Interval(Real, 0, None, closed="neither"), None],
        "min_pts": [Interval(Integral, 1, None, closed="left"), None],
        "affine": ["boolean"],
        "settings": [StrOptions(set(_PRESETS))],
        "embedding": [StrOptions({"exact", "literal"})],
        "ridge": [Interval(Real, 0, None, closed="left")],
        "svm_c": [Interval(Real, 0, None, closed="neither")],
        "random_state": [Interval(Integral, 0, None, closed="left")],
    }

    def __init__(
        self,
        na: int = 1,
        nb: int = 1,
        n_rho: int | None = None,
        eps: float | None = None,
        min_pts: int | None = None,
        affine: bool = False,
        settings: str = "default",
        embedding: str = "exact",
        ridge: float = 0.0,
        svm_c: float = 1.0,
        random_state: int = 0,
    ):
        self.na = na
        self.nb = nb
        self.n_rho = n_rho
        self.eps = eps
        self.min_pts = min_pts
        self.affine = affine
        self.settings = settings
        self.embedding = embedding
        self.ridge = ridge
        self.svm_c = svm_c
        self.random_state = random_state

    def resolve_settings(self, d: int) -> Settings:
        """The settings a fit uses for regressor dimension d (automatic values filled in)."""
        if self.settings == "paper":
            missing = [k for k in ("n_rho", "eps", "min_pts") if getattr(self, k) is None]
            if missing:
                raise ValueError(
                    f"settings='paper' needs explicit {', '.join(missing)}: the paper gives "
                    f"values per data set, no rule (e.g. n_rho=18, eps=0.1, min_pts=20 for "
                    f"its simulation example)"
                )
        return Settings(
            n_rho=self.n_rho if self.n_rho is not None else 3 * d,
            min_pts=self.min_pts if self.min_pts is not None else 2 * d,
            eps=self.eps,
            embedding=self.embedding,
            ridge=self.ridge,
            svm_c=self.svm_c,
            seed=self.random_state,
            **_PRESETS[self.settings],
        )

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, u: Signals, y: Signals) -> "PWARX":
        """Identify the PWARX model from one or several experiments.

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays (separate experiments)
        y : array-like of shape (N, m), or a list of such arrays

        Returns
        -------
        self

        Raises
        ------
        ValueError
            On NaN/inf, mismatched lengths or dimensions, too few samples for n_ρ, n_ρ ≤ d,
            a singular local problem, or when DBSCAN finds no cluster.
        """
        pairs = as_experiments(u, y)
        timings: dict[str, float] = {}
        t0 = time.perf_counter()
        reg = build_regressors(pairs, self.na, self.nb, self.affine)
        cfg = self.resolve_settings(reg.phi.shape[1])
        timings["regressors"] = time.perf_counter() - t0
        local = self.fit_local_models(reg, cfg, timings)
        clusters = self.fit_clusters(reg, local, cfg, timings)
        subs = self.fit_submodels(reg, local, clusters, cfg, timings)
        regions = self.fit_regions(reg, subs, cfg, timings)
        return self.assemble(pairs, reg, local, clusters, subs, regions, cfg, timings)

    # The steps below are public so that a pipeline can run, cache and inspect them apart.

    @staticmethod
    def fit_local_models(
        reg: Regressors, cfg: Settings, timings: dict | None = None
    ) -> LocalModels:
        """Steps 2–3: local sets and local least squares."""
        t0 = time.perf_counter()
        local = estimate_local_models(reg.phi, reg.target, cfg.n_rho, cfg.standardize, cfg.ridge)
        if timings is not None:
            timings["local_models"] = time.perf_counter() - t0
        return local

    @staticmethod
    def fit_clusters(
        reg: Regressors, local: LocalModels, cfg: Settings, timings: dict | None = None
    ) -> Clustering:
        """Step 4: DBSCAN on the (optionally unit-free) local parameter matrices."""
        t0 = time.perf_counter()
        keep = _clustering_subset(local, cfg)
        clusters = cluster_local_models(_clustering_theta(reg, local, cfg), cfg.eps,
                                        cfg.min_pts, cfg.embedding, keep)
        if timings is not None:
            timings["clusters"] = time.perf_counter() - t0
        return clusters

    @staticmethod
    def fit_submodels(
        reg: Regressors,
        local: LocalModels,
        clusters: Clustering,
        cfg: Settings,
        timings: dict | None = None,
    ) -> SubModels:
        """Step 5: one sub-model per cluster (centre or refit), then merge and refine."""
        t0 = time.perf_counter()
        labels = clusters.labels
        if cfg.submodel == "centre":
            subs = SubModels(thetas=cluster_centres(local.theta, labels), labels=labels)
        else:
            subs = _refined_submodels(reg, local, clusters, cfg)
        if timings is not None:
            timings["sub_models"] = time.perf_counter() - t0
        return subs

    @staticmethod
    def fit_regions(
        reg: Regressors, subs: SubModels, cfg: Settings, timings: dict | None = None
    ) -> Regions:
        """Step 6: the regions H_i by a multi-class linear SVM on the labelled φ(k)."""
        t0 = time.perf_counter()
        regions = fit_regions(reg.phi, subs.labels, subs.thetas.shape[0], C=cfg.svm_c,
                              sample_weight=subs.weights)
        if timings is not None:
            timings["svm_regions"] = time.perf_counter() - t0
        return regions

    def assemble(
        self,
        pairs: list[tuple[Float2D, Float2D]],
        reg: Regressors,
        local: LocalModels,
        clusters: Clustering,
        subs: SubModels,
        regions: Regions,
        cfg: Settings,
        timings: dict | None = None,
    ) -> "PWARX":
        """Set the fitted attributes from the steps' results; returns self."""
        self.n_inputs_ = pairs[0][0].shape[1]
        self.n_outputs_ = pairs[0][1].shape[1]
        self.n_features_in_ = self.n_inputs_
        self.settings_ = cfg
        self.n_rho_, self.min_pts_, self.eps_ = cfg.n_rho, cfg.min_pts, clusters.eps
        self.cluster_labels_ = clusters.labels
        self.noise_share_ = clusters.noise_share
        self.thetas_ = subs.thetas
        self.n_submodels_ = subs.thetas.shape[0]
        self.labels_ = subs.labels
        self.regions_ = regions
        self.timings_ = dict(timings or {})
        return self

    def _predict_phi(self, phi: Float2D) -> Float2D:
        region = self.regions_.predict(phi)
        return np.einsum("nd,ndm->nm", phi, self.thetas_[region])


def _clustering_subset(local: LocalModels, cfg: Settings) -> np.ndarray | None:
    """Local models passed to DBSCAN: the confident ones, at most ``max_cluster`` of them
    (a seeded random subset) so that DBSCAN's cost stays bounded on long records."""
    n = local.theta.shape[0]
    keep = np.ones(n, bool) if cfg.confidence is None else confident_models(
        local.residual_var, cfg.confidence)
    if cfg.max_cluster is not None and keep.sum() > cfg.max_cluster:
        rows = np.random.default_rng(cfg.seed).choice(np.nonzero(keep)[0], cfg.max_cluster,
                                                      replace=False)
        keep = np.zeros(n, bool)
        keep[rows] = True
    return keep


def _clustering_theta(reg: Regressors, local: LocalModels, cfg: Settings) -> np.ndarray:
    """θ_k as DBSCAN sees it: unit-free (θ·rms(φ)/rms(y)) with ``scale_theta``, else raw."""
    if not cfg.scale_theta:
        return local.theta
    return local.theta * local.phi_scale[None, :, None] / column_rms(reg.target)


def _refined_submodels(
    reg: Regressors, local: LocalModels, clusters: Clustering, cfg: Settings
) -> SubModels:
    """The default step 5: merge, refine, look for missed modes.

    1. DBSCAN clusters that predict alike are merged
       (:func:`pwa_pipeline.submodels.merge_indistinguishable`: predictions closer than the
       noise, or closer than 5 noise standard deviations while no linear classifier on φ
       tells their rows apart, i.e. copies of one mode), then rows are re-assigned by
       residual alone until stable, merging again, until nothing merges.
    2. Rows are re-assigned by residual and sub-models refitted until stable
       (:func:`pwa_pipeline.submodels.refine`); sub-models that now predict alike are merged
       and step 2 repeats.
    3. A mode whose local sets were too few to form a cluster shows as rows no sub-model
       explains (normalised residual above the χ²(m) 99.9 % quantile): local models are
       estimated again among those rows alone, where local sets are purer, clustered, and the
       new clusters join as sub-models, and step 2 repeats (at most three searches, and only
       while each leaves fewer rows unexplained).
    """
    min_size = max(reg.phi.shape[1] + 1, cfg.min_pts)
    limit = chi2.ppf(0.999, reg.target.shape[1])
    labels = clusters.labels
    n_merged, n_iter, searches = 0, 0, 0
    if cfg.merge_tol is not None:
        labels, n_merged = _merge_clustered(reg, labels, cfg.merge_tol, cfg.copy_tol)
    # Consolidate by residual alone first, merging copies: an SVM over many small,
    # overlapping clusters can give all rows to the largest one.
    more = 1
    while more:
        labels = refine(reg.phi, reg.target, labels, min_size, cfg.n_refine)[1]
        more = 0
        if cfg.merge_tol is not None:
            labels, more = merge_indistinguishable(reg.phi, reg.target, labels, cfg.merge_tol,
                                                   cfg.copy_tol)
            n_merged += more
    best = None
    while True:
        thetas, labels, margin, sweeps = refine(reg.phi, reg.target, labels, min_size,
                                                cfg.n_refine, cfg.svm_c)
        n_iter += sweeps
        if cfg.merge_tol is not None:
            merged, more = merge_indistinguishable(reg.phi, reg.target, labels, cfg.merge_tol,
                                                   cfg.copy_tol)
            if more:
                labels, n_merged = merged, n_merged + more
                continue
        polished = refine(reg.phi, reg.target, labels, min_size, cfg.n_refine)
        poor = unexplained_cost(reg.phi, reg.target, polished[0]) > limit
        if best is not None and poor.sum() >= best[0]:
            break  # the search did not explain more rows: keep the previous state
        best = (int(poor.sum()), polished)
        if searches >= cfg.n_search or poor.sum() < cfg.min_pts:
            break
        searches += 1
        extra = _cluster_subset(reg, poor, cfg)
        if extra is None:
            break
        labels = labels.copy()
        found = extra.labels >= 0
        labels[np.nonzero(poor)[0][found]] = thetas.shape[0] + extra.labels[found]
    thetas, labels, margin, sweeps = best[1]  # the state kept, polished by residual
    n_iter += sweeps
    return SubModels(thetas=thetas, labels=labels, weights=margin_weights(margin),
                     n_merged=n_merged, n_iter=n_iter)


def _cluster_subset(reg: Regressors, rows: np.ndarray, cfg: Settings) -> Clustering | None:
    """Steps 2–4 again on a subset of rows; None when it is too small or has no cluster."""
    n_rho = min(cfg.n_rho, int(rows.sum()) - 1)
    if n_rho <= reg.phi.shape[1]:
        return None
    sub = Regressors(phi=reg.phi[rows], target=reg.target[rows],
                     experiment=reg.experiment[rows], time=reg.time[rows])
    try:
        local = estimate_local_models(sub.phi, sub.target, n_rho, cfg.standardize, cfg.ridge)
        return cluster_local_models(_clustering_theta(sub, local, cfg), None, cfg.min_pts,
                                    cfg.embedding, _clustering_subset(local, cfg))
    except ValueError:
        return None


def _merge_clustered(reg: Regressors, labels: np.ndarray, tol: float, copy_tol: float | None):
    """:func:`merge_indistinguishable` on the rows DBSCAN clustered (noise stays −1)."""
    rows = labels >= 0
    merged, n = merge_indistinguishable(reg.phi[rows], reg.target[rows], labels[rows], tol,
                                        copy_tol)
    out = labels.copy()
    out[rows] = merged
    return out, n
