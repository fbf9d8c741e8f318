"""Exact DBSCAN in memory linear in the number of points (step 4, paper section 4).

scikit-learn's DBSCAN stores every ε-neighbourhood before clustering: 255 M pairs and 6 GB on
the robot's 40k local models. `dbscan` gives the same clustering from blocks of
distances, never holding more than one block, and skips most pairs with the triangle
inequality.
"""

import numpy as np
from scipy.sparse import coo_array
from scipy.sparse.csgraph import connected_components

from ..._arrays import sparse_nonzero
from ..._typing import Float2D

_PIVOTS = 64
"""Reference points whose distances to every point bound the others (triangle inequality)."""

_BUDGET = 1 << 23
"""Entries of one block of distances (32 MB in float32), when ``block`` is not given."""

_CHUNK = 256
"""Columns of one block against the largest certified cluster."""


def dbscan(x: Float2D, eps: float, min_pts: int, block: int | None = None) -> np.ndarray:
    """DBSCAN labels computed block by block (Ester et al. 1996), as scikit-learn defines them.

    A point is *core* when at least ``min_pts`` points, itself included, lie at Euclidean
    distance ``<= eps`` (scikit-learn's ``min_samples`` and its ``<=``). Clusters are the
    connected components of the core points under "within ``eps``". A non-core point within
    ``eps`` of a core point is a *border* point, the others are noise. With the exact
    embedding of the local parameter matrices, the Euclidean distance is the Vθ distance of
    Lassoued & Abderrahim (2023), section 4, eq. (8)–(10).

    Border rule: scikit-learn's. Its expansion visits the points in index order and finishes
    one cluster before starting the next, so clusters are numbered by their lowest-indexed
    core point and a border point within ``eps`` of core points of several clusters goes to
    the cluster of lowest such number (the first to reach it). Ties at ``eps``: a pair within
    rounding of ``eps`` (as when ε is a k-distance, see
    `k_distance_eps`) is decided by
    Σ_j (x_pj − x_qj)² ≤ ε² summed in feature order on the points as given, scikit-learn's
    k-d tree test bit for bit. The labels are then scikit-learn's, cluster numbers included,
    where it searches with its k-d tree (up to 15 dimensions; tested on ties in
    ``tests/pwa/steps/test_dbscan.py``), except for its shortcut that takes a whole tree node once the
    node's bounding box lies within ``eps``. Above 15 dimensions it searches by brute force
    with ‖p‖² − 2 p·q + ‖q‖² rounded by BLAS (the rounding depends on its chunking of the
    matrix product and on which point is the query), so a pair within ~1e-13 relative of
    ``eps`` may go either way there; the sum of squared differences used here is the more
    accurate of the two.

    How: the distances to 64 random pivot points certify most dense points as core at once (a
    pivot whose ``min_pts``-th nearest point is at ``r`` makes every point within
    ``eps − r`` of it core) and join them into clusters through the core pivots. The other
    points are compared with one another, and with the largest such cluster, by matrix
    products in float32 on blocks of at most ``block`` rows; pairs a triangle-inequality
    bound rules out (distances to a central point and to the pivots) are skipped, and pairs within
    the float32 rounding bound of ``eps`` are decided again in float64. Memory is a block of
    distances, the pivot distances (64 per point) and at most ``min_pts`` neighbours per
    non-core point: neighbourhoods are never stored.

    Parameters
    ----------
    x : ndarray of shape (n, d)
        The points (e.g. `pwa_pipeline.pwa.steps.embedding.exact_embedding`).
    eps : float
        Neighbourhood radius ε > 0.
    min_pts : int
        Least number of points within ``eps`` of a core point, itself included (≥ 1).
    block : int, optional
        Rows of a block of distances; by default as many as fit 2²³ entries. Any value gives
        the same labels.

    Returns
    -------
    labels : ndarray of shape (n,)
        Cluster 0 … s−1 of each point, −1 for noise; clusters are numbered by their
        lowest-indexed core point, as scikit-learn numbers them
        (`pwa_pipeline._arrays.relabel_by_size` numbers them by size).

    Raises
    ------
    ValueError
        If ``eps <= 0`` or ``min_pts < 1``.

    References
    ----------
    M. Ester, H.-P. Kriegel, J. Sander, X. Xu (1996). A density-based algorithm for
    discovering clusters in large spatial databases with noise. KDD-96, 226–231.
    """
    return _dbscan(x, eps, min_pts, block)[0]


def _dbscan(x: Float2D, eps: float, min_pts: int,
            block: int | None) -> tuple[np.ndarray, np.ndarray]:
    """`dbscan`'s labels and which points are core."""
    if eps <= 0 or min_pts < 1:
        raise ValueError(f"need eps > 0 and min_pts >= 1, got eps = {eps}, min_pts = {min_pts}")
    x = np.asarray(x, dtype=float)
    given = x
    n = x.shape[0]
    if n == 0:
        return np.empty(0, dtype=np.intp), np.empty(0, dtype=bool)
    # Centre on the point nearest the mean: shifting by a data point keeps integer data exact.
    x = x - x[np.argmin(np.einsum("ij,ij->i", x, x) - 2 * (x @ x.mean(0)))]
    sq = np.einsum("ij,ij->i", x, x)
    err2 = 4 * (x.shape[1] + 2) * np.finfo(float).eps * max(sq.max(), eps * eps)
    tol = 2 * np.sqrt(err2) + err2 / eps  # bounds the rounding of the distances below

    # Pivots: a point within eps − r of a pivot whose min_pts-th nearest point is at r is core.
    piv = np.sort(np.random.default_rng(0).choice(n, min(n, _PIVOTS), replace=False))
    dist = x[piv] @ x.T
    dist *= -2
    dist += sq[piv, None]
    dist += sq
    np.sqrt(np.maximum(dist, 0, out=dist), out=dist)
    kth = (np.partition(dist, min_pts - 1, axis=1)[:, min_pts - 1].copy() if min_pts <= n
           else np.full(len(piv), np.inf))
    slack, cert = np.full(n, np.inf), np.zeros(n, dtype=np.intp)
    for c, row in enumerate(dist):  # slack = min over pivots of dist + kth, cert the argmin
        better = row + kth[c] < slack
        slack[better], cert[better] = row[better] + kth[c], c
    known = slack <= eps - tol
    linked = (dist[:, piv] <= eps - tol) & known[piv] & known[piv, None]
    piv_comp = connected_components(linked, directed=False)[1]
    big = np.argmax(np.bincount(piv_comp[cert[known]], minlength=len(piv)))
    in_g = known & (piv_comp[cert] == big)  # G: the largest cluster the pivots certify
    g_piv = in_g[piv]
    cell = dist.argmin(0)
    # Q (all but G) by norm, then G by nearest pivot; `where` maps an index to its position.
    norm = np.sqrt(sq)
    order = np.lexsort((np.where(in_g, cell, norm), in_g))
    nq = n - int(in_g.sum())
    where = np.empty(n, dtype=np.intp)
    where[order] = np.arange(n)
    x, sq, norm, cell, known, cert = (v[order] for v in (x, sq, norm, cell, known, cert))
    dist_q = dist[:, order[:nq]]
    dist_g = dist[cell[nq:], order[nq:]]
    del dist

    geo = _Geometry(x, sq, norm, eps, tol, given[order])
    state = _State(known, min_pts)
    a, b = np.nonzero(linked)
    state.merge(np.r_[np.flatnonzero(known), where[piv[a]]],
                np.r_[where[piv[cert[known]]], where[piv[b]]])
    _sweep_q(geo, state, nq, block)
    if nq < n:
        _sweep_g(geo, state, nq, block, cell[nq:], dist_g, dist_q, g_piv)
    labels, core = state.labels_of(order)
    return labels[where], core[where]


class _Geometry:
    """The points with float32 copies for blocks of ``‖p − q‖² <= ε²`` tests."""

    def __init__(self, x: Float2D, sq: np.ndarray, norm: np.ndarray, eps: float, tol: float,
                 given: Float2D):
        self.x, self.sq, self.norm, self.eps, self.tol, self.eps2 = x, sq, norm, eps, tol, eps * eps
        self.given = given  # the points as passed (not centred), in this object's order
        # ‖p − q‖² <= ε²  ⇔  [p, 1]·[q, −‖q‖²/2] >= (‖p‖² − ε²)/2: one product and one test.
        self.left = np.ones((len(x), x.shape[1] + 1), dtype=np.float32)
        self.left[:, :-1] = x
        self.right = np.empty_like(self.left)
        self.right[:, :-1], self.right[:, -1] = x, -sq / 2
        self.thr = (sq - self.eps2) / 2
        # float32 rounding of such a product, per unit of Σ|terms| (Higham's γ, doubled)
        self.unit = 2 * (x.shape[1] + 3) * float(np.finfo(np.float32).eps)

    def within_eps(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """``Σ_j (x_pj − x_qj)² <= ε²`` for the pairs (p, q), summed in feature order on the
        points as given: scikit-learn's k-d tree test, bit for bit."""
        acc = np.zeros(len(p))
        for j in range(self.given.shape[1]):
            diff = self.given[p, j] - self.given[q, j]
            acc += diff * diff
        return acc <= self.eps2

    def near(self, rows: np.ndarray | slice, cols: slice) -> np.ndarray:
        """Boolean block ``‖x[rows] − x[cols]‖ <= ε``, pairs near ε by `within_eps`."""
        rows = np.arange(len(self.x))[rows]
        prod = self.left[rows] @ self.right[cols].T
        top = self.norm[cols].max()
        margin = self.unit * (self.norm[rows] * top + top * top / 2 + np.abs(self.thr[rows]))
        low = prod >= (self.thr[rows] - margin).astype(np.float32)[:, None]
        near = prod >= (self.thr[rows] + margin).astype(np.float32)[:, None]
        i, j = sparse_nonzero(np.not_equal(low, near, out=low))  # within rounding of ε: decide again
        near[i, j] = self.within_eps(rows[i], np.arange(len(self.x))[cols][j])
        return near


class _State:
    """Neighbour counts, clusters of core points (labels) and kept pairs."""

    def __init__(self, known: np.ndarray, min_pts: int):
        self.known, self.min_pts = known, min_pts
        self.count = np.ones(len(known), dtype=np.intp)  # each point is its own neighbour
        self.labels = np.arange(len(known))
        self.kept: list[np.ndarray] = []

    def sure(self) -> np.ndarray:
        """Points known to be core so far."""
        return self.known | (self.count >= self.min_pts)

    def merge(self, a: np.ndarray, b: np.ndarray) -> None:
        """Join the clusters of a[k] and b[k] for every k."""
        la, lb = self.labels[a], self.labels[b]
        diff = la != lb
        if diff.any():
            n = len(self.labels)
            graph = coo_array((np.ones(diff.sum(), np.int8), (la[diff], lb[diff])), shape=(n, n))
            self.labels = connected_components(graph, directed=False)[1][self.labels]

    def add(self, p: np.ndarray, q: np.ndarray) -> None:
        """Count the neighbour pairs (p, q), join those of two core points and keep the rest.

        A pair is kept only while one of its points has fewer than ``min_pts`` neighbours so
        far, so at most ``min_pts`` pairs are kept per point.
        """
        n = len(self.count)
        self.count += np.bincount(p, minlength=n) + np.bincount(q, minlength=n)
        sure = self.sure()
        both = sure[p] & sure[q]
        self.merge(p[both], q[both])
        self.kept.append(np.stack([p[~both], q[~both]]))

    def labels_of(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Final labels, numbered and with border points assigned as scikit-learn does, and
        the core points.

        ``ids`` are the points' original indices: a cluster's number is the rank of its
        lowest-indexed core point, and a border point takes the lowest number among the
        clusters of its core neighbours (scikit-learn's first cluster to reach it).
        """
        core = self.sure()
        p, q = np.concatenate(self.kept, axis=1) if self.kept else np.empty((2, 0), np.intp)
        both = core[p] & core[q]
        self.merge(p[both], q[both])

        out = np.full(len(core), -1)
        comp = np.unique(self.labels[core], return_inverse=True)[1]
        lowest = np.full(comp.max(initial=-1) + 1, len(core))
        np.minimum.at(lowest, comp, ids[core])
        rank = np.empty(lowest.size, dtype=np.intp)
        rank[np.argsort(lowest)] = np.arange(lowest.size)
        out[core] = rank[comp]
        one = core[p] != core[q]
        border, nearest = np.where(core[p], q, p)[one], np.where(core[p], p, q)[one]
        first = np.full(len(core), len(core))
        np.minimum.at(first, border, out[nearest])
        reached = first < len(core)
        out[reached] = first[reached]
        return out, core


def _sweep_q(geo: _Geometry, state: _State, nq: int, block: int | None) -> None:
    """Pairs among the first ``nq`` points (sorted by norm), each once.

    ``|‖p‖ − ‖q‖| <= ‖p − q‖``, so a row meets only the columns of norm at most ε above its own.
    """
    end = np.searchsorted(geo.norm[:nq], geo.norm[:nq] + geo.eps + geo.tol, "right")
    r0 = 0
    while r0 < nq:
        if block:
            r1 = min(nq, r0 + block)
        else:  # the most rows whose block (rows × columns up to the last row's end) fits
            size = np.arange(1, nq - r0 + 1) * (end[r0:] - r0)
            r1 = r0 + max(1, int(np.searchsorted(size, _BUDGET, "right")))
        i, j = sparse_nonzero(geo.near(slice(r0, r1), slice(r0, end[r1 - 1])))
        upper = j > i
        state.add(r0 + i[upper], r0 + j[upper])
        r0 = r1


def _sweep_g(geo: _Geometry, state: _State, nq: int, block: int | None,
             cell: np.ndarray, dist_g: np.ndarray, dist_q: np.ndarray, g_piv: np.ndarray) -> None:
    """Pairs between the first ``nq`` points and G (the rest, sorted by nearest pivot ``cell``).

    G is one cluster of core points: a point of the first part needs G's points only to count
    its neighbours while it is not known to be core, to join G once it is, and to find its
    nearest core point if it is not. ``dist_g`` is each G point's distance to its pivot,
    ``dist_q`` the pivots' distances to the first part, ``g_piv`` marks the pivots in G. A
    point meets a pivot's G points only if neither its distance to the pivot nor its norm
    is more than ε beyond theirs.
    """
    k, n, eps, tol = dist_q.shape[0], len(geo.x), geo.eps, geo.tol
    radius, low, high = np.full(k, -np.inf), np.full(k, np.inf), np.full(k, -np.inf)
    np.maximum.at(radius, cell, dist_g)
    np.minimum.at(low, cell, geo.norm[nq:])
    np.maximum.at(high, cell, geo.norm[nq:])
    norm = geo.norm[:nq]
    reach = ((dist_q <= (radius + eps + tol)[:, None]) & (norm >= (low - eps - tol)[:, None])
             & (norm <= (high + eps + tol)[:, None]))
    # Core points within eps of a pivot in G join G at once.
    todo = ~(state.sure()[:nq] & (dist_q[g_piv] <= eps - tol).any(0))
    state.merge(np.flatnonzero(~todo), np.full(nq - todo.sum(), nq))
    for a in range(nq, n, _CHUNK):
        b = min(n, a + _CHUNK)
        rows_all = np.flatnonzero(reach[cell[a - nq]:cell[b - 1 - nq] + 1].any(0) & todo)
        step = block or max(1, _BUDGET // (b - a))
        for s in range(0, rows_all.size, step):
            rows = rows_all[s:s + step]
            near = geo.near(rows, slice(a, b))
            hits = np.count_nonzero(near, axis=1)
            state.count[rows] += hits
            sure = state.sure()[rows]
            joined = rows[sure & (hits > 0)]
            state.merge(joined, np.full(joined.size, nq))
            todo[joined] = False
            alone = np.flatnonzero(~sure & (hits > 0))
            i, j = np.nonzero(near[alone])
            state.kept.append(np.stack([rows[alone[i]], a + j]))
