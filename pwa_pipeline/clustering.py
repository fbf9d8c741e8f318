"""Extended DBSCAN on the local parameter matrices (paper step 4, section 4)."""

from dataclasses import dataclass

import numpy as np
from sklearn.cluster import DBSCAN
from sklearn.neighbors import NearestNeighbors

from .embedding import EMBEDDINGS

_EPS_SAMPLE = 5000


@dataclass(frozen=True)
class Clustering:
    """DBSCAN result on the local models.

    Attributes
    ----------
    labels : ndarray of shape (n,)
        Cluster of each local model, 0 … s−1 by decreasing size, −1 for noise (and for the
        local models left out by the confidence filter).
    eps : float
        The ε used, given or chosen from the data.
    min_pts : int
        The MinPts used.
    eps_auto : bool
        Whether ε was chosen by :func:`k_distance_eps`.
    clustered : ndarray of shape (n,), bool
        The local models passed to DBSCAN.
    """

    labels: np.ndarray
    eps: float
    min_pts: int
    eps_auto: bool
    clustered: np.ndarray

    @property
    def n_clusters(self) -> int:
        """Number of clusters found."""
        return int(self.labels.max()) + 1 if self.labels.size else 0

    @property
    def noise_share(self) -> float:
        """Share of the local models passed to DBSCAN that it labelled noise (−1)."""
        return float(np.mean(self.labels[self.clustered] < 0))


def confident_models(residual_var: np.ndarray, factor: float) -> np.ndarray:
    """Local models whose residual variance is at most ``factor`` × the median, per output.

    A local set that mixes modes fits badly, so its residual variance is large
    (Ferrari-Trecate et al. 2003 weight local models by this confidence); pure local sets
    have a residual variance near the noise variance, i.e. near the median.
    """
    ratio = residual_var / np.maximum(np.median(residual_var, axis=0), np.finfo(float).tiny)
    return np.all(ratio <= factor, axis=1)


def k_distances(emb: np.ndarray, min_pts: int, seed: int = 0) -> np.ndarray:
    """Sorted distance of each point to its MinPts-th neighbour, the point itself included.

    That distance decides whether a point is a DBSCAN core point: the curve is flat inside
    dense clusters and rises for points between them. At most 5,000 points are queried
    (against all points) to bound the cost.
    """
    n = emb.shape[0]
    rng = np.random.default_rng(seed)
    query = emb if n <= _EPS_SAMPLE else emb[rng.choice(n, _EPS_SAMPLE, replace=False)]
    nn = NearestNeighbors(n_neighbors=min(min_pts, n)).fit(emb)
    return np.sort(nn.kneighbors(query)[0][:, -1])


def k_distance_eps(emb: np.ndarray, min_pts: int, n_grid: int = 20) -> float:
    """ε from the k-distance curve: the candidate that separates the most clusters.

    Candidates are the 2 % … 60 % quantiles of :func:`k_distances`. DBSCAN runs at each (on
    one radius-neighbour graph computed once at the largest), and the largest ε giving the
    most clusters wins. Over-splitting a mode is harmless where sub-models that predict
    alike are merged afterwards (as :class:`pwa_pipeline.identification.PWARX` does);
    merging two modes is not repairable, and the classic knee of the curve does that when one
    mode is much larger than another.
    """
    dist = k_distances(emb, min_pts)
    # Distances below 1e-6 of the parameters' size are rounding error (noise-free data).
    floor = 1e-6 * max(float(np.median(np.linalg.norm(emb, axis=1))), np.finfo(float).tiny)
    grid = np.unique(np.maximum(np.quantile(dist, np.linspace(0.02, 0.6, n_grid)), floor))
    graph = NearestNeighbors(radius=grid[-1]).fit(emb).radius_neighbors_graph(
        mode="distance", sort_results=True
    )
    graph.data = np.maximum(graph.data, np.finfo(float).tiny)  # keep exact duplicates
    counts = [
        DBSCAN(eps=eps, min_samples=min_pts, metric="precomputed").fit(graph).labels_.max() + 1
        for eps in grid
    ]
    best = max(range(len(grid)), key=lambda i: (counts[i], i))
    return float(grid[best])


def relabel_by_size(labels: np.ndarray) -> np.ndarray:
    """Renumber non-negative labels 0 … s−1 by decreasing cluster size; −1 stays −1."""
    out = np.full_like(labels, -1)
    kept = labels[labels >= 0]
    if kept.size == 0:
        return out
    uniq, counts = np.unique(kept, return_counts=True)
    order = uniq[np.argsort(-counts, kind="stable")]
    lookup = np.full(int(uniq.max()) + 1, -1)
    lookup[order] = np.arange(order.size)
    mask = labels >= 0
    out[mask] = lookup[labels[mask]]
    return out


def cluster_local_models(
    theta: np.ndarray,
    eps: float | None,
    min_pts: int,
    embedding: str = "exact",
    clustered: np.ndarray | None = None,
) -> Clustering:
    """Cluster local parameter matrices with DBSCAN on the Vθ distance (eq. 8–10).

    Parameters
    ----------
    theta : ndarray of shape (n, d, m)
        Local parameter matrices (possibly rescaled by the caller).
    eps : float or None
        DBSCAN radius; None chooses it with :func:`k_distance_eps`.
    min_pts : int
        DBSCAN MinPts (the point itself counts, as in scikit-learn's ``min_samples``).
    embedding : {"exact", "literal"}
        ``"literal"`` is Vθ of eq. (9); ``"exact"`` the d·m-dimensional map with the same
        distances (:func:`pwa_pipeline.embedding.exact_embedding`).
    clustered : ndarray of bool, optional
        Which local models to cluster; the others are labelled noise.

    Raises
    ------
    ValueError
        If DBSCAN finds no cluster; the message gives ε, MinPts and the noise share.
    """
    if embedding not in EMBEDDINGS:
        raise ValueError(f"embedding must be one of {sorted(EMBEDDINGS)}, got {embedding!r}")
    if min_pts < 1:
        raise ValueError(f"min_pts must be at least 1, got {min_pts}")
    n = theta.shape[0]
    mask = np.ones(n, bool) if clustered is None else np.asarray(clustered, bool)
    if mask.sum() < min_pts:
        raise ValueError(
            f"only {int(mask.sum())} local models to cluster, fewer than min_pts = {min_pts}"
        )
    emb = EMBEDDINGS[embedding](theta[mask])
    eps_auto = eps is None
    if eps_auto:
        eps = k_distance_eps(emb, min_pts)
    elif not eps > 0:
        raise ValueError(f"eps must be positive, got {eps}")
    labels = np.full(n, -1)
    labels[mask] = DBSCAN(eps=eps, min_samples=min_pts).fit_predict(emb)
    labels = relabel_by_size(labels)
    if labels.max() < 0:
        raise ValueError(
            f"DBSCAN found no cluster with eps = {eps:.4g} and min_pts = {min_pts}: all "
            f"{n} local models are noise (noise share 100%). Increase eps, lower min_pts, "
            f"or leave eps unset to choose it from the data"
        )
    return Clustering(labels=labels, eps=float(eps), min_pts=min_pts, eps_auto=eps_auto,
                      clustered=mask)
