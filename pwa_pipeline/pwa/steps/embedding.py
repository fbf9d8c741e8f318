"""Vector embeddings of the local parameter matrices for DBSCAN (paper section 4, eq. 8–10)."""

import numpy as np


def literal_embedding(theta: np.ndarray) -> np.ndarray:
    """Vθ_k of eq. (9): the m columns of θ_k, then θ_(p),k − θ_(q),k for every p ≠ q (eq. 10).

    Parameters
    ----------
    theta : ndarray of shape (n, d, m)

    Returns
    -------
    ndarray of shape (n, d·m²)
        m columns and m(m − 1) differences of d entries each.
    """
    n, d, m = theta.shape
    cols = [theta[:, :, p] for p in range(m)]
    cols += [theta[:, :, p] - theta[:, :, q] for p in range(m) for q in range(m) if p != q]
    return np.concatenate(cols, axis=1)


def exact_transform(m: int) -> np.ndarray:
    """The m × m matrix S with ‖(θ_k − θ_l)·S‖_F = ‖Vθ_k − Vθ_l‖ for every pair.

    With a_p the column differences, ‖Vθ_k − Vθ_l‖² = (1 + 2m)·Σ‖a_p‖² − 2·‖Σ a_p‖², the
    quadratic form of M = (1 + 2m)·I − 2·11ᵀ (eigenvalues 1 and 1 + 2m); S = M^½.
    """
    avg = np.full((m, m), 1.0 / m)
    return np.sqrt(1.0 + 2.0 * m) * (np.eye(m) - avg) + avg


def exact_embedding(theta: np.ndarray) -> np.ndarray:
    """An embedding of θ_k in d·m dimensions with exactly the distances of eq. (8)–(10).

    m² times smaller than `literal_embedding` (e.g. 144 instead of 864 entries for
    d = 24, m = 6), hence faster DBSCAN, with the same labels.

    Returns
    -------
    ndarray of shape (n, d·m)
    """
    n, d, m = theta.shape
    return (theta @ exact_transform(m)).reshape(n, d * m)


EMBEDDINGS = {"exact": exact_embedding, "literal": literal_embedding}
