"""Exact k nearest neighbours by blocks of float32 matrix products (local sets, step 2).

scikit-learn's brute-force search ranks every row of the distance matrix in float64 (about
7 s on the robot's 40k regressor rows in 24 dimensions at k = 72). `nearest_neighbours`
gives the same neighbours from float32 products on tiles that fit in cache, each computed
once for both of its row blocks, with two threads, deciding in float64 only the pairs that
float32 cannot rank. BLAS computes the tiles; compiled kernels (`_knn_kernels`) read
each tile once to keep its candidates and rank each row's.
"""

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..._blas import single_threaded_blas
from ..._threads import map_in_threads
from ..._typing import Float2D
from ..kernels.knn import kth_smallest_rows, select_nearest, tile_candidates

_BLOCK = 512
"""Rows of a block; a tile is one block of rows against one block of columns."""

_WINDOW = 2048
"""Columns, near a block in the spatial order, whose k-th nearest bounds each row's k-th."""


def nearest_neighbours(x: Float2D, k: int, workers: int | None = None,
                       queries: np.ndarray | None = None) -> np.ndarray:
    """Indices of the k nearest points of every point (Euclidean), the point itself included,
    or of the points ``queries`` only.

    Each row is sorted by distance, equal distances by index; a point's own index comes
    first unless other points coincide with it (those of lower index then come first).
    Exact: the result is the k smallest exact distances; scikit-learn's brute force ranks
    ‖p‖² − 2 p·q + ‖q‖² in float64 instead, so the two can differ where two candidates for
    the k-th place lie within ~1e-15 relative of each other, and at exact ties (broken by
    index here, by its heap there).

    How: points are put in a spatial order (recursive median splits, each along the
    principal axis of the points it splits), so that a block of rows meets most of its
    neighbours in the columns next to it. Each row's k-th smallest distance among
    ``_WINDOW`` such columns bounds its k-th nearest from above; then every tile of the
    distance matrix above the diagonal is computed once, in float32 (‖p‖² + ‖q‖² − 2 p·q as
    one product), and kept only where a distance is within its row's bound, for both of the
    tile's row blocks, in one pass over the tile. Among a row's kept candidates (about three
    times k a row on the robot), those below its k-th float32 distance plus twice the
    rounding bound (the others are surely farther than the k nearest) are ranked on exact
    float64 distances Σ_j (x_pj − x_qj)², then by index.
    Coinciding points are searched once, with their multiplicity.

    With ``queries``, only the tiles of the queried points (in the same spatial order)
    against every point are computed: q·n·(d + 2)·2 operations for q queried points, where
    every point's search shares each tile between its two row blocks.

    Memory: the candidates (12 bytes each, a few hundred a point) and one tile with room for
    all its entries as candidates (24 bytes each) per thread; time n²·(d + 2)·2
    floating-point operations over 2 (symmetry).

    Parameters
    ----------
    x : ndarray of shape (n, d)
    k : int
        1 ≤ k ≤ n.
    workers : int, optional
        Threads (default: the CPUs this process may use); BLAS runs single-threaded inside.
    queries : ndarray of shape (q,), int, optional
        Rows of ``x`` whose neighbours are sought (among all points). None: every row.

    Returns
    -------
    ndarray of shape (n, k) or (q, k), int64
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    if not 1 <= k <= n:
        raise ValueError(f"need 1 <= k <= n, got k = {k} for n = {n} points")
    if not np.isfinite(x).all():
        raise ValueError("x has NaN or infinite values: distances are undefined")
    workers = workers or len(os.sched_getaffinity(0))
    # Coinciding points: search the distinct ones, then expand by multiplicity.
    first, inverse = distinct_rows(x)
    if len(first) == n:
        return _distinct(x, k, workers, queries)[0]
    counts = np.bincount(inverse, minlength=len(first))
    sought, back = (None, inverse) if queries is None else np.unique(
        inverse[queries], return_inverse=True)
    idx, sq = _distinct(x[first], min(k, len(first)), workers, sought)
    # Rows of each distinct point, by index; the k nearest rows are the first k of the
    # distinct neighbours' rows in order of (distance, row index).
    members = np.argsort(inverse, kind="stable")
    start = np.r_[0, np.cumsum(counts)]
    cum = np.cumsum(counts[idx], axis=1)
    enough = np.minimum((cum < k).sum(axis=1), idx.shape[1] - 1)
    last = sq[np.arange(len(idx)), enough]
    u, j = np.nonzero(sq <= last[:, None])  # each point's neighbours through the k-th row
    v = idx[u, j]
    size = counts[v]
    total = np.cumsum(size)
    flat = np.arange(total[-1]) + np.repeat(start[v] - (total - size), size)
    rows, owner, dist = members[flat], np.repeat(u, size), np.repeat(sq[u, j], size)
    srt = np.lexsort((rows, dist, owner))
    owned = np.bincount(owner, minlength=len(idx))
    out = rows[srt][(np.cumsum(owned) - owned)[:, None] + np.arange(k)]
    return out[back]


def distinct_rows(x: Float2D) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of ``x`` (rows of equal values are one), in order of first occurrence.

    Returns
    -------
    first : ndarray of shape (n_distinct,), int
        Index of each distinct row's first occurrence, increasing.
    inverse : ndarray of shape (n,), int
        The distinct row of every row: ``x[first][inverse]`` is ``x``.
    """
    x = np.ascontiguousarray(x) + 0.0  # −0.0 becomes 0.0: compared by their bytes below
    rows = x.view(np.dtype((np.void, x.dtype.itemsize * x.shape[1]))).ravel()
    _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return first[order], rank[inverse.ravel()]


def _distinct(x: Float2D, k: int, workers: int, queries: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """`nearest_neighbours` of distinct points, and their exact squared distances."""
    if queries is not None:
        return _queried(x, k, workers, queries)
    n = x.shape[0]
    order, xs, left, right, err = _tile_factors(x)
    blocks = [(a, min(n, a + _BLOCK)) for a in range(0, n, _BLOCK)]
    window = min(n, max(_WINDOW, 2 * k))

    def bound(block):  # k-th smallest distance among the window's columns, plus rounding
        a, b = block
        c = _window_start(a, b, n, window)
        d2 = left[a:b] @ right[c:c + window].T
        return kth_smallest_rows(d2, k) + 2 * err[a:b]

    found: list[list] = [[] for _ in blocks]
    buffers = threading.local()  # each thread's room for one tile's candidates

    def row_of_tiles(i):  # the tiles of block i's rows against blocks i, i + 1, …
        if not hasattr(buffers, "side"):
            buffers.side = np.empty((2, _BLOCK * _BLOCK, 2), dtype=np.int32)
            buffers.dist = np.empty((2, _BLOCK * _BLOCK), dtype=np.float32)
        row_side, col_side = buffers.side
        row_dist, col_dist = buffers.dist
        a, b = blocks[i]
        for j in range(i, len(blocks)):
            c, e = blocks[j]
            d2 = left[a:b] @ right[c:e].T
            n_row, n_col = tile_candidates(d2, thr32[a:b], thr32[c:e], i == j, row_side,
                                           row_dist, col_side, col_dist)
            found[i].append((row_side[:n_row] + (0, c), row_dist[:n_row].copy()))
            if i != j:
                found[j].append((col_side[:n_col] + (0, a), col_dist[:n_col].copy()))

    out = np.empty((n, k), dtype=np.intp)
    out_sq = np.empty((n, k))

    def select(i):  # the k nearest of each row of block i among its candidates
        a, b = blocks[i]
        pairs, val = (np.concatenate(part) for part in zip(*found[i]))
        found[i] = []
        select_nearest(pairs[:, 0], pairs[:, 1], val, xs, a, 2 * err[a:b], order, out[a:b],
                       out_sq[a:b])

    with single_threaded_blas(), ThreadPoolExecutor(workers) as pool:
        thr32 = _bound32(np.concatenate(map_in_threads(pool, bound, blocks)))
        map_in_threads(pool, row_of_tiles, range(len(blocks)))  # the longest rows first
        map_in_threads(pool, select, range(len(blocks)))
    back = np.empty(n, dtype=np.intp)
    back[order] = np.arange(n)
    return out[back], out_sq[back]


def _tile_factors(x: Float2D) -> tuple[np.ndarray, Float2D, np.ndarray, np.ndarray,
                                       np.ndarray]:
    """The points centred in their spatial order (``order``, ``xs``), the float32 factors
    of their squared distances (``left[p] @ right[q]``) and each row's bound on that
    float32 value's rounding error (``err``)."""
    n, d = x.shape
    x = x - x.mean(axis=0)
    order = _spatial_order(x, leaf=_BLOCK // 2)  # finer splits only reorder within blocks
    xs = np.ascontiguousarray(x[order])
    sq = np.einsum("ij,ij->i", xs, xs)
    norm = np.sqrt(sq)
    # d² = [p, ‖p‖², 1]·[−2q, 1, ‖q‖²]; its float32 rounding is at most err_p for a row p
    left = np.empty((n, d + 2), dtype=np.float32)
    left[:, :d], left[:, d], left[:, d + 1] = xs, sq, 1
    right = np.empty_like(left)
    right[:, :d], right[:, d], right[:, d + 1] = -2 * xs, 1, sq
    err = 2 * (d + 4) * float(np.finfo(np.float32).eps) * (norm + norm.max()) ** 2
    return order, xs, left, right, err


def _window_start(a: int, b: int, n: int, window: int) -> int:
    """First column of the ``window`` columns centred on the block of rows ``a:b`` (within
    the n points), whose k-th nearest bounds each of the block's rows' k-th."""
    return min(max(0, (a + b - window) // 2), n - window)


def _bound32(bound: np.ndarray) -> np.ndarray:
    """Float32 bounds never below the float64 ones."""
    out = bound.astype(np.float32)
    return np.nextafter(out, np.float32(np.inf), out=out)


def _queried(x: Float2D, k: int, workers: int, queries: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """`_distinct` of the rows ``queries`` only: each block of them (in the spatial
    order, so that a block is compact) against every block of points, the rows' side of each
    tile kept; bounds, candidates and selection as `_distinct`'s."""
    n = x.shape[0]
    order, xs, left, right, err = _tile_factors(x)
    place = np.empty(n, dtype=np.intp)
    place[order] = np.arange(n)
    sorter = np.argsort(place[queries], kind="stable")
    pos = place[queries][sorter]  # the queried rows in the spatial order
    xq = np.concatenate([xs, xs[pos]])  # each queried row again after the points
    lq, band = left[pos], 2 * err[pos]
    q = len(pos)
    window = min(n, max(_WINDOW, 2 * k))
    never = np.full(_BLOCK, -np.inf, dtype=np.float32)  # no column's side is kept
    out = np.empty((q, k), dtype=np.intp)
    out_sq = np.empty((q, k))

    group = np.r_[0, np.flatnonzero(np.diff(pos // _BLOCK)) + 1, q]

    def bound(g):  # each row's bound from the window of the block it is in, as _distinct's
        a, b = group[g], group[g + 1]
        start = pos[a] // _BLOCK * _BLOCK
        c = _window_start(start, min(n, start + _BLOCK), n, window)
        return kth_smallest_rows(lq[a:b] @ right[c:c + window].T, k) + band[a:b]

    def search(a):
        b = min(q, a + _BLOCK)
        side = np.empty((_BLOCK * _BLOCK, 2), dtype=np.int32)
        dist = np.empty(_BLOCK * _BLOCK, dtype=np.float32)
        spare = np.empty((1, 2), dtype=np.int32), np.empty(1, dtype=np.float32)
        parts = []
        for c in range(0, n, _BLOCK):
            e = min(n, c + _BLOCK)
            n_row = tile_candidates(lq[a:b] @ right[c:e].T, thr32[a:b], never[:e - c], True,
                                    side, dist, *spare)[0]
            parts.append((side[:n_row] + (0, c), dist[:n_row].copy()))
        pairs, val = (np.concatenate(part) for part in zip(*parts))
        select_nearest(pairs[:, 0], pairs[:, 1], val, xq, n + a, band[a:b], order, out[a:b],
                       out_sq[a:b])

    with single_threaded_blas(), ThreadPoolExecutor(workers) as pool:
        thr32 = _bound32(np.concatenate(map_in_threads(pool, bound, range(len(group) - 1))))
        map_in_threads(pool, search, range(0, q, _BLOCK))
    back = np.empty(q, dtype=np.intp)
    back[sorter] = np.arange(q)
    return out[back], out_sq[back]


def _spatial_order(x: Float2D, leaf: int) -> np.ndarray:
    """An order of the points in which nearby points tend to be close: recursive median
    splits, each along the principal axis of the points being split (their widest spread
    in any direction, so that a block of the order is compact in all of them), down to
    groups of at most ``leaf`` points."""
    order = np.arange(len(x))
    todo = [(0, len(x))]
    while todo:
        a, b = todo.pop()
        if b - a <= leaf:
            continue
        seg = x[order[a:b]]
        seg = seg - seg.mean(axis=0)
        axis = np.linalg.eigh(seg.T @ seg)[1][:, -1]
        mid = (b - a) // 2
        order[a:b] = order[a:b][np.argpartition(seg @ axis, mid)]
        todo += [(a, a + mid), (a + mid, b)]
    return order
