"""Compiled kernels of the ε search's cluster counts (`clustering.dbscan_cluster_counts`).

numba, because Prim's algorithm is n steps of a few passes over n points each, which numpy
pays as n · (several calls and temporaries): about 0.2 s at n = 3000 against 0.02 s
compiled. Compiled on first use and cached on disk (``cache=True``, next to this
file).

A point's distances (``row``) come from ``dense`` when it is given (n × n, computed once by
the caller), else from ``x``: Σ_j (x_pj − x_qj)² summed in feature order when ``sq`` is empty,
else (‖p‖² − 2 p·q) + ‖q‖² clipped at 0; as a distance (square root) where it is at most
``r2``, inf beyond.
"""

import numpy as np
from numba import njit

from .knn import kth_smallest


@njit(nogil=True, cache=True)
def squared_distances(xt: np.ndarray) -> np.ndarray:
    """Σ_j (x_pj − x_qj)² of every pair, summed in feature order (scikit-learn's k-d tree
    rounding), from the points' transpose ``xt`` (d, n).

    Returns
    -------
    ndarray of shape (n, n)
    """
    d, n = xt.shape
    out = np.empty((n, n))
    for p in range(n):
        row = out[p]
        for q in range(n):
            v = xt[0, q] - xt[0, p]
            row[q] = v * v
        for j in range(1, d):
            for q in range(n):
                v = xt[j, q] - xt[j, p]
                row[q] += v * v
    return out


@njit(nogil=True, cache=True)
def to_distances(d2: np.ndarray, sq: np.ndarray, r2: float) -> None:
    """Squared distances (or, when ``sq`` is not empty, the Gram matrix p·q, made
    (‖p‖² − 2 p·q) + ‖q‖² clipped at 0 first) into distances where at most ``r2``, inf
    beyond; in place, one pass."""
    n = d2.shape[0]
    for p in range(n):
        for q in range(n):
            s = d2[p, q]
            d2[p, q] = _distance(_from_gram(s, sq[p], sq[q]) if len(sq) else s, r2)


@njit(nogil=True, cache=True)
def _from_gram(dot: float, sq_p: float, sq_q: float) -> float:
    """(‖p‖² − 2 p·q) + ‖q‖² clipped at 0, rounded as scikit-learn's brute force rounds it."""
    return max((sq_p - 2 * dot) + sq_q, 0.0)


@njit(nogil=True, cache=True)
def _distance(s: float, r2: float) -> float:
    """A squared distance as a distance where it is at most ``r2``, inf beyond."""
    return np.sqrt(s) if s <= r2 else np.inf


@njit(nogil=True, cache=True)
def _row(x: np.ndarray, sq: np.ndarray, dense: np.ndarray, r2: float, u: int,
         out: np.ndarray) -> None:
    """Distances of point ``u`` to every point into ``out`` (see the module's docstring)."""
    if dense.shape[0]:
        out[:] = dense[u]
        return
    n, d = x.shape
    for q in range(n):
        if len(sq):
            s = 0.0
            for j in range(d):
                s += x[u, j] * x[q, j]
            s = _from_gram(s, sq[u], sq[q])
        else:
            s = (x[q, 0] - x[u, 0]) * (x[q, 0] - x[u, 0])
            for j in range(1, d):
                v = x[q, j] - x[u, j]
                s += v * v
        out[q] = _distance(s, r2)


@njit(nogil=True, cache=True)
def core_distances(x: np.ndarray, sq: np.ndarray, dense: np.ndarray, r2: float,
                   min_pts: int) -> np.ndarray:
    """Each point's distance to its (MinPts − 1)-th nearest other point (its core distance):
    0 when MinPts is 1, inf when there are fewer other points or that one lies beyond √r2.

    Returns
    -------
    ndarray of shape (n,)
    """
    n = x.shape[0] if dense.shape[0] == 0 else dense.shape[0]
    core = np.zeros(n)
    if min_pts == 1:
        return core
    if min_pts - 1 >= n:
        core[:] = np.inf
        return core
    row = np.empty(n)
    others = np.empty(n - 1)
    for u in range(n):
        _row(x, sq, dense, r2, u, row)
        others[:u] = row[:u]
        others[u:] = row[u + 1:]
        core[u] = kth_smallest(others, min_pts - 2)
    return core


@njit(nogil=True, cache=True)
def spanning_tree_edges(x: np.ndarray, sq: np.ndarray, dense: np.ndarray, r2: float,
                        core: np.ndarray) -> np.ndarray:
    """Edge weights of a minimum spanning forest of the mutual reachability distances
    max(c_p, c_q, ‖p − q‖) (Prim's algorithm; an inf weight where a new tree starts).

    All minimum spanning forests have the same weights, so these do not depend on the
    order in which equal weights are met.

    Returns
    -------
    ndarray of shape (n − 1,)
    """
    n = len(core)
    best = np.full(n, np.inf)
    done = np.zeros(n, np.bool_)
    edges = np.empty(max(n - 1, 0))
    row = np.empty(n)
    u = 0
    for it in range(n):
        done[u] = True
        if it:
            edges[it - 1] = best[u]
        _row(x, sq, dense, r2, u, row)
        nxt = -1
        for v in range(n):
            if done[v]:
                continue
            w = max(row[v], core[u], core[v])
            if w < best[v]:
                best[v] = w
            if nxt < 0 or best[v] < best[nxt]:
                nxt = v
        if nxt < 0:
            break
        u = nxt  # when best[u] is inf, u starts a new tree
    return edges
