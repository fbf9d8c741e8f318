"""Extended DBSCAN on the local parameter matrices (paper step 4, section 4)."""

from numbers import Integral, Real

import numpy as np
from sklearn.base import _fit_context
from sklearn.neighbors import NearestNeighbors
from sklearn.utils._param_validation import Interval, StrOptions

from ..._arrays import column_rms, relabel_by_size
from ..kernels.cluster import (
    core_distances,
    spanning_tree_edges,
    squared_distances,
    to_distances,
)
from .base import BaseClustering
from .dbscan import dbscan
from .embedding import EMBEDDINGS

_EPS_SAMPLE = 5000
_DENSE = 1 << 24
"""Largest n² for which `dbscan_cluster_counts` keeps every distance (128 MB)."""


def confident_models(residual_var: np.ndarray, factor: float) -> np.ndarray:
    """Local models whose residual variance is at most ``factor`` × the median, per output.

    A local set that mixes modes fits badly, so its residual variance is large
    (Ferrari-Trecate et al. 2003 weight local models by this confidence); pure local sets
    have a residual variance near the noise variance, i.e. near the median.
    """
    ratio = residual_var / np.maximum(np.median(residual_var, axis=0), np.finfo(float).tiny)
    return np.all(ratio <= factor, axis=1)


def k_distances(emb: np.ndarray, min_pts: int, seed: int = 0,
                max_query: int = _EPS_SAMPLE) -> np.ndarray:
    """Sorted distance of each point to its MinPts-th neighbour, the point itself included.

    That distance decides whether a point is a DBSCAN core point: the curve is flat inside
    dense clusters and rises for points between them. At most ``max_query`` points (a
    seeded random subset) are queried, against all points, to bound the cost.
    """
    n = emb.shape[0]
    rng = np.random.default_rng(seed)
    query = emb if n <= max_query else emb[rng.choice(n, max_query, replace=False)]
    nn = NearestNeighbors(n_neighbors=min(min_pts, n)).fit(emb)
    return np.sort(nn.kneighbors(query)[0][:, -1])


def k_distance_eps(emb: np.ndarray, min_pts: int, n_grid: int = 20) -> float:
    """ε from the k-distance curve: the candidate that separates the most clusters.

    Candidates are the 2 % … 60 % quantiles of `k_distances`. The number of DBSCAN
    clusters at every candidate comes from one minimum spanning tree of the mutual
    reachability distances (`dbscan_cluster_counts`), and the largest ε giving the
    most clusters wins. Over-splitting a mode is harmless where sub-models that predict
    alike are merged afterwards (as
    [`pwa_pipeline.pwa.steps.submodels.RefinedSubModels`][pwa_pipeline.pwa.RefinedSubModels] does); merging
    two modes is not repairable, and the classic knee of the curve does that when one mode is much larger than
    another.
    """
    dist = k_distances(emb, min_pts)
    # Distances below 1e-6 of the parameters' size are rounding error (noise-free data).
    floor = 1e-6 * max(float(np.median(np.linalg.norm(emb, axis=1))), np.finfo(float).tiny)
    grid = np.unique(np.maximum(np.quantile(dist, np.linspace(0.02, 0.6, n_grid)), floor))
    counts = dbscan_cluster_counts(emb, grid, min_pts)
    best = max(range(len(grid)), key=lambda i: (counts[i], i))
    return float(grid[best])


def dbscan_cluster_counts(x: np.ndarray, grid: np.ndarray, min_pts: int) -> np.ndarray:
    """Number of DBSCAN clusters of ``x`` at every ε of ``grid``, no neighbourhood stored.

    At ε the core points are those whose (MinPts − 1)-th nearest other point lies within ε
    (their core distance c_p), and the clusters are the connected components of the core
    points under "within ε": the components of the graph of mutual reachability distances
    max(c_p, c_q, ‖p − q‖) ≤ ε. One minimum spanning tree of that graph (Prim's algorithm,
    compiled: `_cluster_kernels`) gives them all: clusters(ε) = #{c_p ≤ ε} − #{tree
    edges ≤ ε}. Distances are rounded as scikit-learn's radius search at the largest ε
    rounds them (its k-d tree up to 15 dimensions: Σ_j (x_pj − x_qj)² in feature order; its
    brute force above: (‖p‖² − 2 p·q) + ‖q‖² clipped at 0) and compared with ε as its
    DBSCAN on that precomputed radius graph compares them, so up to 15 dimensions the
    counts are exactly those (tested); above, pairs within ~1e-13 relative of an ε may
    differ. Time O(n² d); memory n² floats up to n = 4096 (all distances, above 15
    dimensions from one symmetric BLAS product), O(n) above (each point's distances
    computed when needed, twice).
    """
    n = len(x)
    grid = np.asarray(grid, dtype=float)
    r2 = float(grid[-1]) ** 2
    x = np.ascontiguousarray(x, dtype=float)
    # scikit-learn's NearestNeighbors(radius=...) picks its brute force above 15 dimensions
    # and for tiny sets (5 default neighbours >= n // 2), its k-d tree otherwise
    sq = np.einsum("ij,ij->i", x, x) if x.shape[1] > 15 or 5 >= n // 2 else np.empty(0)
    dense = np.empty((0, 0))
    if n * n <= _DENSE:
        dense = x @ x.T if len(sq) else squared_distances(np.ascontiguousarray(x.T))
        to_distances(dense, sq, r2)
    core = core_distances(x, sq, dense, r2, min_pts)
    edges = spanning_tree_edges(x, sq, dense, r2, core)
    core.sort()
    edges.sort()
    return np.searchsorted(core, grid, "right") - np.searchsorted(edges, grid, "right")


def cluster_local_models(
    theta: np.ndarray,
    eps: float | None,
    min_pts: int,
    embedding: str = "exact",
    clustered: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Cluster local parameter matrices with DBSCAN on the Vθ distance (eq. 8–10).

    DBSCAN is `pwa_pipeline.pwa.steps.dbscan.dbscan` (scikit-learn's labels, border points
    included, in bounded memory).

    Parameters
    ----------
    theta : ndarray of shape (n, d, m)
        Local parameter matrices (possibly rescaled by the caller).
    eps : float or None
        DBSCAN radius; None chooses it with `k_distance_eps`.
    min_pts : int
        DBSCAN MinPts (the point itself counts, as in scikit-learn's ``min_samples``).
    embedding : {"exact", "literal"}
        ``"literal"`` is Vθ of eq. (9); ``"exact"`` the d·m-dimensional map with the same
        distances (`pwa_pipeline.pwa.steps.embedding.exact_embedding`).
    clustered : ndarray of bool, optional
        Which local models to cluster; the others are labelled noise.

    Returns
    -------
    labels : ndarray of shape (n,)
        0 … s−1 by decreasing cluster size, −1 for noise and for rows not clustered.
    eps : float
        The ε used.

    Raises
    ------
    ValueError
        If DBSCAN finds no cluster; the message gives ε, MinPts and the noise share.
    """
    n = theta.shape[0]
    mask = np.ones(n, bool) if clustered is None else np.asarray(clustered, bool)
    if mask.sum() < min_pts:
        raise ValueError(
            f"only {int(mask.sum())} local models to cluster, fewer than min_pts = {min_pts}"
        )
    emb = EMBEDDINGS[embedding](theta[mask])
    if eps is None:
        eps = k_distance_eps(emb, min_pts)
    labels = np.full(n, -1)
    labels[mask] = dbscan(emb, eps, min_pts)
    labels = relabel_by_size(labels)
    if labels.max() < 0:
        raise ValueError(
            f"DBSCAN found no cluster with eps = {eps:.4g} and min_pts = {min_pts}: all "
            f"{n} local models are noise (noise share 100%). Increase eps, lower min_pts, "
            f"or leave eps unset to choose it from the data"
        )
    return labels, float(eps)


class DBSCANClustering(BaseClustering):
    """Step 4 of the method: DBSCAN on the local parameter matrices θ_k (section 4, eq. 8–10).

    Parameters
    ----------
    eps : float, optional
        DBSCAN radius ε. None: chosen from the k-distance curve (`k_distance_eps`).
    min_pts : int, optional
        DBSCAN MinPts (the point itself counts). None: 2·d.
    embedding : {"exact", "literal"}, default "exact"
        The literal Vθ of eq. (9), or the d·m-dimensional map with the same distances
        (faster, same labels).
    unit_free : bool, default True
        Cluster θ_k·rms(φ)/rms(y) instead of θ_k, so that ε does not depend on the units of
        the channels. The paper clusters θ_k as it is (False).
    confidence : float, optional, default 3
        Leave out local models whose residual variance exceeds ``confidence`` × the median
        (`confident_models`: mixed local sets). None (the paper) clusters every one.
    max_clustered : int, optional, default 3000
        Cluster at most this many local models (a seeded random subset of the confident
        ones), so DBSCAN's cost stays bounded on long records. None (the paper): all.
    random_state : int, default 0
        Seed of that subset.

    Attributes
    ----------
    labels_ : ndarray of shape (n,)
        Cluster of each local model, 0 … s−1 by decreasing size, −1 for noise (and for the
        local models not clustered).
    eps_ : float
        The ε used, given or chosen.
    eps_auto_ : bool
        Whether ε was chosen from the data.
    min_pts_ : int
    clustered_ : ndarray of shape (n,), bool
        The local models passed to DBSCAN, and their repeats.
    n_clusters_ : int
    noise_share_ : float
        Share of the clustered local models that DBSCAN labelled noise.
    """

    _parameter_constraints: dict = {
        "eps": [Interval(Real, 0, None, closed="neither"), None],
        "min_pts": [Interval(Integral, 1, None, closed="left"), None],
        "embedding": [StrOptions(set(EMBEDDINGS))],
        "unit_free": ["boolean"],
        "confidence": [Interval(Real, 0, None, closed="neither"), None],
        "max_clustered": [Interval(Integral, 1, None, closed="left"), None],
        "random_state": [Interval(Integral, 0, None, closed="left")],
    }

    def __init__(
        self,
        eps: float | None = None,
        min_pts: int | None = None,
        embedding: str = "exact",
        unit_free: bool = True,
        confidence: float | None = 3.0,
        max_clustered: int | None = 3000,
        random_state: int = 0,
    ):
        self.eps = eps
        self.min_pts = min_pts
        self.embedding = embedding
        self.unit_free = unit_free
        self.confidence = confidence
        self.max_clustered = max_clustered
        self.random_state = random_state

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, local, target: np.ndarray) -> "DBSCANClustering":
        """Cluster the local models of a fitted local-model step.

        Parameters
        ----------
        local : fitted LocalLeastSquares
            Its ``theta_``, ``residual_var_``, ``phi_scale_``, ``degenerate_``,
            ``estimated_`` and ``original_`` are used; only estimated local models are
            clustered, degenerate ones never, and each distinct sample is clustered once
            (MinPts, the confidence median and the subset count it once): a repeated sample
            takes its first occurrence's label, so a record repeated r times is clustered
            as the record once.
        target : ndarray of shape (n, m)
            The outputs y(k) (their RMS makes θ unit-free).
        """
        n = local.estimated_.size
        self.min_pts_ = self.min_pts if self.min_pts is not None else 2 * local.phi_scale_.size
        original = local.original_
        distinct = original == np.arange(n)
        estimated = distinct & local.estimated_
        available = int(estimated.sum()) if self.max_clustered is None else min(
            int(estimated.sum()), self.max_clustered)
        if self.min_pts_ > available:
            raise ValueError(
                f"clustering min_pts = {self.min_pts_} is larger than the {available} local "
                f"models there are to cluster (one per distinct regressor row, at most "
                f"local_models__max_sets estimated and clustering__max_clustered clustered): "
                f"no DBSCAN neighbourhood can hold that many; lower it (left out, it is "
                f"2d = {2 * local.phi_scale_.size})")
        keep = ~local.degenerate_ & estimated
        if keep.sum() < self.min_pts_:
            raise ValueError(
                f"{int((local.degenerate_ & distinct).sum())} of {int(estimated.sum())} "
                f"local sets are degenerate (their regressors "
                f"are linearly dependent, e.g. inputs held constant for longer than a local "
                f"set): too few left to cluster. Raise local_models__n_rho, lower na/nb, or "
                f"excite the system with an input that changes more often"
            )
        if self.confidence is not None:
            keep[keep] = confident_models(local.residual_var_[keep],
                                          self.confidence)
        if self.max_clustered is not None and keep.sum() > self.max_clustered:
            rows = np.random.default_rng(self.random_state).choice(
                np.nonzero(keep)[0], self.max_clustered, replace=False)
            keep = np.zeros(n, bool)
            keep[rows] = True
        rows = np.flatnonzero(keep)
        theta = local.theta_[rows]
        if self.unit_free:
            theta = theta * local.phi_scale_[None, :, None] / column_rms(target[distinct])
        labels = np.full(n, -1)
        labels[rows], self.eps_ = cluster_local_models(theta, self.eps, self.min_pts_,
                                                       self.embedding)
        # a repeated sample is clustered as its first occurrence, which it equals
        self.labels_ = relabel_by_size(labels[original])
        self.eps_auto_ = self.eps is None
        keep = keep[original]
        self.clustered_ = keep
        self.n_clusters_ = int(self.labels_.max()) + 1
        self.noise_share_ = float(np.mean(self.labels_[keep] < 0))
        return self

    def resolved_params(self) -> dict:
        """`get_params` with the values chosen at fit filled in (ε, MinPts)."""
        return {**self.get_params(), "eps": self.eps_, "min_pts": self.min_pts_}
