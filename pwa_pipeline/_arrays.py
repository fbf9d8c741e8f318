"""Small array helpers shared across the numerical core (no step of the method lives here)."""

import hashlib

import numpy as np

from ._typing import Float2D


def array_digest(*arrays: np.ndarray) -> str:
    """SHA-256 (hex) of the arrays' shapes, types and bytes, in order: what caches key on in
    place of arrays (cheaper than joblib's hash on the tens of MB of a long record's local
    models)."""
    h = hashlib.sha256()
    for a in map(np.ascontiguousarray, arrays):
        h.update(f"{a.shape}{a.dtype}".encode())
        h.update(memoryview(a).cast("B"))
    return h.hexdigest()


def column_rms(x: Float2D) -> np.ndarray:
    """Root mean square of each column, 1 where a column is all zeros."""
    rms = np.sqrt(np.mean(x**2, axis=0))
    return np.where(rms > 0, rms, 1.0)


def relabel_by_size(labels: np.ndarray) -> np.ndarray:
    """Renumber non-negative labels 0 … s−1 by decreasing group size; −1 stays −1."""
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


def sparse_nonzero(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.nonzero`` of a sparse C-contiguous 2-D boolean array, reading 8 entries at once."""
    flat = mask.reshape(-1)
    n8 = flat.size // 8 * 8
    words = flat[:n8].view(np.uint64)
    hit = np.flatnonzero(words)
    w, b = np.nonzero(words[hit].view(np.uint8).reshape(-1, 8))
    pos = np.concatenate([hit[w] * 8 + b, n8 + np.flatnonzero(flat[n8:])])
    return np.divmod(pos, mask.shape[1])
