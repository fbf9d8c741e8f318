"""Compiled kernels of the exact neighbour search (`pwa_pipeline.pwa.steps.neighbours`).

numba, because each is one pass that numpy can only express as several over memory: a tile
of float32 distances is compared against both blocks' bounds and its few candidates kept in
the same pass, a row's k-th smallest is selected among its candidates without sorting them,
and only those float32 cannot put beyond the k-th are ranked on exact distances. Compiled
on first use and cached on disk (``cache=True``, next to this file); ``nogil`` so that the
search's threads run them side by side.
"""

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def sq_distance(x: np.ndarray, p: int, q: int) -> float:
    """Σ_j (x_pj − x_qj)² in float64, summed as numpy's ``einsum`` sums a contiguous row
    product on x86-64 (two interleaved partial sums, four terms each pass, added last), so
    that ties are broken on the same values as numpy's search before this kernel."""
    d = x.shape[1]
    s0 = 0.0
    s1 = 0.0
    j = 0
    while j + 8 <= d:
        for lane in range(2):
            s = s0 if lane == 0 else s1
            for u in range(3, -1, -1):
                v = x[p, j + 2 * u + lane] - x[q, j + 2 * u + lane]
                s = v * v + s
            if lane == 0:
                s0 = s
            else:
                s1 = s
        j += 8
    while j < d:
        v = x[p, j] - x[q, j]
        s0 = v * v + s0
        if j + 1 < d:
            v = x[p, j + 1] - x[q, j + 1]
            s1 = v * v + s1
        j += 2
    return s0 + s1


@njit(nogil=True, cache=True)
def kth_smallest_rows(d2: np.ndarray, k: int) -> np.ndarray:
    """The k-th smallest of each row of float32 distances, those below 0 taken as 0.

    Radix selection: a count of the values by their leading 12 bits (a non-negative
    float32's bits rank like its value) finds the k-th's bucket, and a quickselect among
    that bucket's values (a few, on distances) the k-th itself.

    Returns
    -------
    ndarray of shape (m,), float64
    """
    m, w = d2.shape
    out = np.empty(m)
    count = np.zeros(1 << 12, np.int32)
    bucket = np.empty(w, np.float32)
    bits = d2.view(np.uint32)
    for r in range(m):
        count[:] = 0
        for s in range(w):
            b = np.int64(bits[r, s])
            count[0 if b >> 31 else b >> 19] += 1
        below = 0
        h = 0
        while below + count[h] < k:
            below += count[h]
            h += 1
        size = 0
        for s in range(w):
            b = np.int64(bits[r, s])
            if (0 if b >> 31 else b >> 19) == h:
                bucket[size] = max(d2[r, s], np.float32(0.0))
                size += 1
        out[r] = kth_smallest(bucket[:size], k - 1 - below)
    return out


@njit(nogil=True, cache=True)
def tile_candidates(d2: np.ndarray, bound_rows: np.ndarray, bound_cols: np.ndarray,
                    diagonal: bool, row_side: np.ndarray, row_dist: np.ndarray,
                    col_side: np.ndarray, col_dist: np.ndarray) -> tuple[int, int]:
    """The entries of a tile of float32 distances within their row's or their column's bound.

    Parameters
    ----------
    d2 : ndarray of shape (m, w), float32
        Distances of a block of m rows to a block of w columns.
    bound_rows, bound_cols : ndarray of shape (m,) and (w,), float32
        Each row's and each column's bound.
    diagonal : bool
        The two blocks are one: only the rows' side is kept.
    row_side, col_side : ndarray of shape (m * w, 2), int32
        Filled: (row, column) of the entries within their row's bound, (column, row) of
        those within their column's bound, in the tile's numbering.
    row_dist, col_dist : ndarray of shape (m * w,), float32
        Filled: their distances, those below 0 lifted to 0 (nearer the truth).

    Returns
    -------
    n_row, n_col : int
        Entries filled in ``row_side`` and ``col_side``.
    """
    m, w = d2.shape
    words = (w + 7) // 8
    near = np.zeros(8 * words, np.uint8)  # one row's entries within either bound
    near_words = near.view(np.uint64)
    n_row = 0
    n_col = 0
    for r in range(m):
        br = bound_rows[r]
        if diagonal:
            for s in range(w):
                near[s] = d2[r, s] <= br
        else:
            for s in range(w):
                near[s] = d2[r, s] <= max(br, bound_cols[s])
        for q in range(words):  # eight entries at once: most are far
            if near_words[q] == 0:
                continue
            for s in range(8 * q, 8 * q + 8):
                if not near[s]:
                    continue
                v = max(d2[r, s], np.float32(0.0))
                row_side[n_row, 0] = r
                row_side[n_row, 1] = s
                row_dist[n_row] = v
                n_row += d2[r, s] <= br
                col_side[n_col, 0] = s
                col_side[n_col, 1] = r
                col_dist[n_col] = v
                n_col += (not diagonal) and d2[r, s] <= bound_cols[s]
    return n_row, n_col


@njit(nogil=True, cache=True)
def select_nearest(row: np.ndarray, col: np.ndarray, val: np.ndarray, x: np.ndarray,
                   first: int, band: np.ndarray, index: np.ndarray, out: np.ndarray,
                   out_sq: np.ndarray) -> None:
    """The k nearest of each row of a block among its candidates, by exact distance.

    Candidates whose float32 distance exceeds the row's k-th smallest by more than the band
    are surely farther than its k nearest; the others (those below the k-th less the band
    surely among them, the band undecided) are ranked by exact distance, then by index,
    and the first k kept.

    Parameters
    ----------
    row, col, val : ndarray of shape (n_candidates,)
        Candidates: row in the block, column (a row of ``x``), float32 distance.
    x : ndarray of shape (n, d), float64
        The points, in the search's order.
    first : int
        Row of ``x`` of the block's first row.
    band : ndarray of shape (m,)
        Half-width of each row's band: twice the bound on a float32 distance's rounding.
    index : ndarray of shape (n,), int
        Each row of ``x``'s index in the caller's numbering (ties go to the lower).
    out, out_sq : ndarray of shape (m, k)
        Filled: each row's neighbours (caller's numbering) and exact squared distances.
    """
    m, k = out.shape
    start = np.zeros(m + 1, np.int64)
    for r in row:
        start[r + 1] += 1
    for r in range(m):
        start[r + 1] += start[r]
    fill = start[:m].copy()
    by_row_col = np.empty(len(row), np.int64)
    by_row_val = np.empty(len(row), np.float32)
    for t in range(len(row)):
        r = row[t]
        by_row_col[fill[r]] = col[t]
        by_row_val[fill[r]] = val[t]
        fill[r] += 1
    most = 0
    for r in range(m):
        most = max(most, start[r + 1] - start[r])
    work = np.empty(most, np.float32)
    ids = np.empty(most, np.int64)
    dist = np.empty(most)
    for r in range(m):
        vals = by_row_val[start[r]:start[r + 1]]
        cols = by_row_col[start[r]:start[r + 1]]
        if len(vals) < k:  # cannot happen with valid bounds; guards the reads below
            raise RuntimeError("a row has fewer than k candidates")
        work[:len(vals)] = vals
        kth = np.float64(kth_smallest(work[:len(vals)], k - 1))
        high = kth + band[r]
        n = 0  # those surely among the k nearest and the band: by exact distance
        for t in range(len(vals)):
            if np.float64(vals[t]) <= high:
                ids[n] = cols[t]
                dist[n] = sq_distance(x, first + r, cols[t])
                n += 1
        _sort(ids[:n], dist[:n], index)
        for t in range(k):
            out[r, t] = index[ids[t]]
            out_sq[r, t] = dist[t]


@njit(nogil=True, cache=True)
def _sort(ids: np.ndarray, dist: np.ndarray, index: np.ndarray) -> None:
    """Sort ``ids`` and ``dist`` together by distance, equal ones by ``index[ids]`` (heap
    sort, in place)."""
    n = len(ids)
    for root in range(n // 2 - 1, -1, -1):
        _sift(ids, dist, index, root, n)
    for end in range(n - 1, 0, -1):
        ids[0], ids[end] = ids[end], ids[0]
        dist[0], dist[end] = dist[end], dist[0]
        _sift(ids, dist, index, 0, end)


@njit(nogil=True, cache=True)
def _sift(ids: np.ndarray, dist: np.ndarray, index: np.ndarray, root: int, end: int) -> None:
    """Move ``root`` down the heap ``[0, end)`` until its children are not after it."""
    while True:
        child = 2 * root + 1
        if child >= end:
            return
        if child + 1 < end and _before(dist[child], index[ids[child]], dist[child + 1],
                                       index[ids[child + 1]]):
            child += 1
        if not _before(dist[root], index[ids[root]], dist[child], index[ids[child]]):
            return
        ids[root], ids[child] = ids[child], ids[root]
        dist[root], dist[child] = dist[child], dist[root]
        root = child


@njit(nogil=True, cache=True)
def _before(d1: float, i1: int, d2: float, i2: int) -> bool:
    """(d1, i1) comes before (d2, i2): nearer, or as near and of lower index."""
    return d1 < d2 or (d1 == d2 and i1 < i2)


@njit(nogil=True, cache=True)
def kth_smallest(a: np.ndarray, kth: int) -> float:
    """The ``kth`` smallest (from 0) of ``a``, which it reorders (quickselect)."""
    lo, hi = 0, len(a) - 1
    while lo < hi:
        mid = (lo + hi) // 2  # median of three as the pivot
        if a[mid] < a[lo]:
            a[mid], a[lo] = a[lo], a[mid]
        if a[hi] < a[lo]:
            a[hi], a[lo] = a[lo], a[hi]
        if a[hi] < a[mid]:
            a[hi], a[mid] = a[mid], a[hi]
        pivot = a[mid]
        i, j = lo, hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while a[j] > pivot:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        if kth <= j:
            hi = j
        elif kth >= i:
            lo = i
        else:
            break
    return a[kth]
