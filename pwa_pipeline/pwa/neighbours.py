"""Exact k nearest neighbours by blocks of float32 matrix products (local sets, step 2).

scikit-learn's brute-force search ranks every row of the distance matrix in float64 (about
7 s on the robot's 40k regressor rows in 24 dimensions at k = 72). :func:`nearest_neighbours`
gives the same neighbours from float32 products on tiles that fit in cache, each computed
once for both of its row blocks, with two threads, deciding in float64 only the pairs that
float32 cannot rank.
"""

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .._arrays import sparse_nonzero
from .._typing import Float2D
from ._blas import single_threaded_blas

_BLOCK = 512
"""Rows of a block; a tile is one block of rows against one block of columns."""

_WINDOW = 2048
"""Columns, near a block in the spatial order, whose k-th nearest bounds each row's k-th."""


def nearest_neighbours(x: Float2D, k: int, workers: int | None = None) -> np.ndarray:
    """Indices of the k nearest points of every point (Euclidean), the point itself included.

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
    tile's row blocks. Among the kept candidates (about three times k a row on the robot),
    those float32 cannot rank against the k-th (within its rounding bound) are decided on
    exact float64 distances Σ_j (x_pj − x_qj)².
    Coinciding points are searched once, with their multiplicity.

    Memory: the candidates (about 12 bytes each, a few hundred a point) and one tile per
    thread; time n²·(d + 2)·2 floating-point operations over 2 (symmetry).

    Parameters
    ----------
    x : ndarray of shape (n, d)
    k : int
        1 ≤ k ≤ n.
    workers : int, optional
        Threads (default: the CPUs this process may use); BLAS runs single-threaded inside.

    Returns
    -------
    ndarray of shape (n, k), int64
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    if not 1 <= k <= n:
        raise ValueError(f"need 1 <= k <= n, got k = {k} for n = {n} points")
    workers = workers or len(os.sched_getaffinity(0))
    # Coinciding points: search the distinct ones, then expand by multiplicity.
    first, inverse = distinct_rows(x)
    if len(first) == n:
        return _distinct(x, k, workers)[0]
    counts = np.bincount(inverse, minlength=len(first))
    idx, sq = _distinct(x[first], min(k, len(first)), workers)
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
    return out[inverse]


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


def _distinct(x: Float2D, k: int, workers: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_neighbours` of distinct points, and their exact squared distances."""
    n, d = x.shape
    x = x - x.mean(axis=0)
    order = _spatial_order(x)
    xs = np.ascontiguousarray(x[order])
    sq = np.einsum("ij,ij->i", xs, xs)
    norm = np.sqrt(sq)
    # d² = [p, ‖p‖², 1]·[−2q, 1, ‖q‖²]; its float32 rounding is at most err_p for a row p
    left = np.empty((n, d + 2), dtype=np.float32)
    left[:, :d], left[:, d], left[:, d + 1] = xs, sq, 1
    right = np.empty_like(left)
    right[:, :d], right[:, d], right[:, d + 1] = -2 * xs, 1, sq
    err = 2 * (d + 4) * float(np.finfo(np.float32).eps) * (norm + norm.max()) ** 2
    blocks = [(a, min(n, a + _BLOCK)) for a in range(0, n, _BLOCK)]
    window = min(n, max(_WINDOW, 2 * k))

    def bound(block):  # k-th smallest distance among the window's columns, plus rounding
        a, b = block
        c = min(max(0, (a + b - window) // 2), n - window)
        d2 = left[a:b] @ right[c:c + window].T
        kth = np.partition(d2, k - 1, axis=1)[:, k - 1].astype(float)
        return kth + 2 * err[a:b]

    # A candidate is one integer, (row in its block, float32 distance, column) from the high
    # bits down: sorting those sorts by row, then distance. A non-negative float32's bits
    # rank like its value; a distance rounded below 0 is lifted to 0 (nearer the truth).
    col_bits = max(n - 1, 1).bit_length()
    dist_shift, row_shift = np.uint64(col_bits), np.uint64(col_bits + 31)
    if col_bits + 31 + (_BLOCK - 1).bit_length() > 64:
        raise ValueError(f"at most 2**{64 - 31 - (_BLOCK - 1).bit_length()} distinct points, "
                         f"got {n}")
    found: list[list] = [[] for _ in blocks]

    def pack(row: np.ndarray, col: np.ndarray, val: np.ndarray) -> np.ndarray:
        bits = np.maximum(val, 0).view(np.uint32) & np.uint32(0x7FFFFFFF)  # −0.0 as 0.0
        return (row.astype(np.uint64) << row_shift) | (bits.astype(np.uint64) << dist_shift) \
            | col.astype(np.uint64)

    def tile(pair):  # one tile, for the rows of both of its blocks
        i, j = pair
        (a, b), (c, e) = blocks[i], blocks[j]
        d2 = left[a:b] @ right[c:e].T
        near_row = d2 <= thr32[a:b, None]
        if i != j:
            near_row |= d2 <= thr32[None, c:e]
        r, s = sparse_nonzero(near_row)
        val = d2[r, s]
        keep = val <= thr32[a + r]
        found[i].append(pack(r[keep], c + s[keep], val[keep]))
        if i != j:
            keep = val <= thr32[c + s]
            found[j].append(pack(s[keep], a + r[keep], val[keep]))

    out = np.empty((n, k), dtype=np.intp)
    out_sq = np.empty((n, k))

    def select(i):  # the k nearest of each row of block i among its candidates
        a, b = blocks[i]
        key = np.concatenate(found[i])
        found[i] = []
        key.sort()  # by row, then distance
        r = (key >> row_shift).astype(np.intp)
        s = (key & np.uint64((1 << col_bits) - 1)).astype(np.intp)
        val = ((key >> dist_shift).astype(np.uint32) & np.uint32(0x7FFFFFFF)).view(np.float32)
        del key
        count = np.bincount(r, minlength=b - a)
        start = np.cumsum(count) - count
        kth = val[start + k - 1].astype(float)[r]
        e = 2 * err[a + r]
        inside = val < kth - e  # surely among the k nearest (fewer than k a row)
        use = np.flatnonzero(val <= kth + e)  # those and the band float32 cannot rank
        r, s, val, inside = r[use], s[use], val[use], inside[use]
        # In each row the inside candidates come first (by float32 distance, their order
        # is not needed); the band after them is ranked by exact distance, then index.
        band = np.flatnonzero(~inside)
        rb, sb = r[band], s[band]
        pick = np.arange(len(r))
        pick[band] = band[np.lexsort((order[sb], _exact_sq(xs, a + rb, sb), rb))]
        count = np.bincount(r, minlength=b - a)
        first = (np.cumsum(count) - count)[:, None] + np.arange(k)
        chosen = s[pick][first]
        diff = xs[chosen] - xs[a:b, None, :]
        dist = np.einsum("ijk,ijk->ij", diff, diff)  # exact, for the order and ties
        ranked = np.lexsort((order[chosen], dist), axis=1)
        out[a:b] = order[np.take_along_axis(chosen, ranked, 1)]
        out_sq[a:b] = np.take_along_axis(dist, ranked, 1)

    with single_threaded_blas(), ThreadPoolExecutor(workers) as pool:
        thr = np.concatenate(list(pool.map(bound, blocks)))
        thr32 = thr.astype(np.float32)
        np.nextafter(thr32, np.float32(np.inf), out=thr32)  # float32 never below the bound
        pairs = [(i, j) for i in range(len(blocks)) for j in range(i, len(blocks))]
        list(pool.map(tile, pairs))
        list(pool.map(select, range(len(blocks))))
    back = np.empty(n, dtype=np.intp)
    back[order] = np.arange(n)
    return out[back], out_sq[back]


def _exact_sq(x: Float2D, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Σ_j (x_pj − x_qj)² of the pairs (p, q), in float64."""
    diff = x[p] - x[q]
    return np.einsum("ij,ij->i", diff, diff)


def _spatial_order(x: Float2D, leaf: int = 64) -> np.ndarray:
    """An order of the points in which nearby points tend to be close: recursive median
    splits, each along the principal axis of the points being split (their widest spread
    in any direction, so that a block of the order is compact in all of them)."""
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
