"""A plain numpy/scikit-learn version of steps 1–4 of the default: the speed benchmark's reference.

Written as one would first write it: regressors, scikit-learn's brute-force neighbours on
z-scored regressors, one ``np.linalg.lstsq`` per local set, the default's unit-free θ,
confidence filter and 3,000-model subset, ε from the k-distance curve by scikit-learn's
DBSCAN on one radius graph at each of 20 candidates, then scikit-learn's DBSCAN. It gives
the library's clustering (the benchmarks check the labels) at the cost of the obvious code.
"""

import numpy as np
from sklearn.cluster import DBSCAN
from sklearn.neighbors import NearestNeighbors

from pwa_pipeline._arrays import column_rms, relabel_by_size
from pwa_pipeline._validation import as_experiments
from pwa_pipeline.pwa.steps.clustering import confident_models, k_distances
from pwa_pipeline.pwa.steps.embedding import exact_embedding
from pwa_pipeline.regressors import build_regressors


def plain_eps(emb: np.ndarray, min_pts: int, n_grid: int = 20) -> float:
    """The k-distance ε with scikit-learn's DBSCAN run at each candidate."""
    dist = k_distances(emb, min_pts)
    floor = 1e-6 * max(float(np.median(np.linalg.norm(emb, axis=1))), np.finfo(float).tiny)
    grid = np.unique(np.maximum(np.quantile(dist, np.linspace(0.02, 0.6, n_grid)), floor))
    graph = NearestNeighbors(radius=grid[-1]).fit(emb).radius_neighbors_graph(
        mode="distance", sort_results=True)
    graph.data = np.maximum(graph.data, np.finfo(float).tiny)
    counts = [DBSCAN(eps=e, min_samples=min_pts, metric="precomputed").fit(graph).labels_.max()
              + 1 for e in grid]
    return float(grid[max(range(len(grid)), key=lambda i: (counts[i], i))])


def plain_steps_1_to_4(u, y, na: int, nb: int, n_rho: int | None = None,
                       eps: float | None = None, min_pts: int | None = None,
                       confidence: float = 3.0, max_clustered: int = 3000,
                       seed: int = 0) -> tuple[np.ndarray, float]:
    """DBSCAN labels of the local models (−1: noise or not clustered) and the ε used."""
    reg = build_regressors(as_experiments(u, y), na, nb, False)  # step 1
    phi, target = reg.phi, reg.target
    n, d = phi.shape
    n_rho = n_rho or 3 * d
    min_pts = min_pts or 2 * d
    std = phi.std(axis=0)
    x = (phi[:, std > 0] - phi[:, std > 0].mean(axis=0)) / std[std > 0]
    nn = NearestNeighbors(n_neighbors=n_rho, algorithm="brute").fit(x)  # step 2
    sets = nn.kneighbors(x, return_distance=False)
    scale = column_rms(phi)
    xs = phi / scale
    theta = np.empty((n, d, target.shape[1]))
    resvar = np.empty((n, target.shape[1]))
    for k in range(n):  # step 3
        th, *_ = np.linalg.lstsq(xs[sets[k]], target[sets[k]], rcond=None)
        theta[k] = th / scale[:, None]
        resvar[k] = ((target[sets[k]] - xs[sets[k]] @ th) ** 2).sum(axis=0) / (n_rho - d)
    keep = confident_models(resvar, confidence)  # step 4
    if keep.sum() > max_clustered:
        rows = np.random.default_rng(seed).choice(np.nonzero(keep)[0], max_clustered,
                                                  replace=False)
        keep = np.zeros(n, bool)
        keep[rows] = True
    emb = exact_embedding(theta[keep] * scale[None, :, None] / column_rms(target))
    eps = plain_eps(emb, min_pts) if eps is None else eps
    labels = np.full(n, -1)
    labels[keep] = DBSCAN(eps=eps, min_samples=min_pts).fit_predict(emb)
    return relabel_by_size(labels), eps
