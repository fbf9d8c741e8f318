"""Local sets and local least-squares parameter matrices (paper steps 2–3, eq. 6–7)."""

from dataclasses import dataclass

import numpy as np
from sklearn.neighbors import NearestNeighbors

from ._typing import Float2D

_RANK_TOL = 1e-10
_CHUNK = 4096


@dataclass(frozen=True)
class LocalModels:
    """One local ARX model per regressor row.

    Attributes
    ----------
    theta : ndarray of shape (n, d, m)
        θ_k of eq. (6), in the regressors' own units.
    residual_var : ndarray of shape (n, m)
        Residual variance of each local fit, SSR / (n_ρ − d), per output.
    neighbours : ndarray of shape (n, n_ρ)
        Row indices of each local set C_k (the row itself first).
    phi_scale : ndarray of shape (d,)
        Root-mean-square of each regressor column, used to make θ unit-free.
    """

    theta: np.ndarray
    residual_var: Float2D
    neighbours: np.ndarray
    phi_scale: np.ndarray


def check_n_rho(n_rho: int, d: int) -> None:
    """Raise a ValueError unless n_ρ > d (a local fit needs more points than parameters)."""
    if n_rho <= d:
        raise ValueError(
            f"n_rho = {n_rho} must exceed the regressor dimension d = {d}: each local set "
            f"needs more points than parameters per output"
        )


def column_rms(x: Float2D) -> np.ndarray:
    """Root mean square of each column, 1 where a column is all zeros."""
    rms = np.sqrt(np.mean(x**2, axis=0))
    return np.where(rms > 0, rms, 1.0)


def local_sets(phi: Float2D, n_rho: int, standardize: bool) -> np.ndarray:
    """Indices of the n_ρ nearest neighbours of every φ(k), φ(k) itself included (step 2).

    Parameters
    ----------
    phi : ndarray of shape (n, d)
    n_rho : int
        Cardinality of each local set C_k.
    standardize : bool
        Search on z-scored regressors (constant columns dropped) instead of raw ones, so that
        large-valued channels do not dominate the distance.
    """
    n, d = phi.shape
    if n_rho > n:
        raise ValueError(
            f"too few samples for n_rho = {n_rho}: the data give only {n} regressor rows"
        )
    x = phi
    if standardize:
        std = phi.std(axis=0)
        keep = std > 0
        if not keep.any():
            raise ValueError(
                "every regressor column is constant (the data do not vary): no local sets"
            )
        x = (phi[:, keep] - phi[:, keep].mean(axis=0)) / std[keep]
    nn = NearestNeighbors(n_neighbors=n_rho, algorithm="brute" if d > 12 else "auto")
    idx = nn.fit(x).kneighbors(x, return_distance=False)
    # Duplicated regressors can put another row first; keep C_k's own row at position 0.
    own = np.arange(n)
    not_first = idx[:, 0] != own
    if not_first.any():
        rows = np.nonzero(not_first)[0]
        has_own = idx[rows] == own[rows, None]
        swap = np.where(has_own.any(axis=1), has_own.argmax(axis=1), n_rho - 1)
        idx[rows, swap] = idx[rows, 0]
        idx[rows, 0] = rows
    return idx


def local_least_squares(
    phi: Float2D, target: Float2D, neighbours: np.ndarray, ridge: float = 0.0
) -> LocalModels:
    """Least-squares θ_k on every local set, batched over k (eq. 6–7).

    Each local problem is solved by a QR factorisation of the column-scaled local regressor
    matrix Φ_k; with ``ridge > 0`` the rows √ridge·I are appended (Tikhonov regularisation in
    scaled units), which keeps the problem solvable where a local set is degenerate.

    Raises
    ------
    ValueError
        If n_ρ ≤ d (an exact fit, no least squares), or a local problem is rank-deficient
        and ``ridge`` is 0; the message counts the singular local sets and names the first.
    """
    n, d = phi.shape
    n_rho = neighbours.shape[1]
    check_n_rho(n_rho, d)
    scale = column_rms(phi)
    xs = phi / scale
    m = target.shape[1]
    theta = np.empty((n, d, m))
    resvar = np.empty((n, m))
    damp = np.sqrt(ridge) * np.eye(d) if ridge > 0 else None
    for start in range(0, n, _CHUNK):
        idx = neighbours[start : start + _CHUNK]
        p, t = xs[idx], target[idx]
        if damp is not None:
            p = np.concatenate([p, np.broadcast_to(damp, (len(idx), d, d))], axis=1)
            t = np.concatenate([t, np.zeros((len(idx), d, m))], axis=1)
        q, r = np.linalg.qr(p)
        diag = np.abs(np.diagonal(r, axis1=1, axis2=2))
        singular = diag.min(axis=1) <= _RANK_TOL * diag.max(axis=1)
        if singular.any():
            first = start + int(np.argmax(singular))
            total = int(singular.sum())
            raise ValueError(
                f"local least-squares problem is singular for {total} local set(s) in rows "
                f"{start}..{start + len(idx) - 1} (first: regressor row {first}); the "
                f"regressors of those local sets are linearly dependent. Increase n_rho, "
                f"lower na/nb, or set ridge > 0"
            )
        th = np.linalg.solve(r, q.transpose(0, 2, 1) @ t)
        res = target[idx] - xs[idx] @ th
        theta[start : start + len(idx)] = th / scale[:, None]
        resvar[start : start + len(idx)] = (res**2).sum(axis=1) / (n_rho - d)
    return LocalModels(theta=theta, residual_var=resvar, neighbours=neighbours, phi_scale=scale)


def estimate_local_models(
    phi: Float2D, target: Float2D, n_rho: int, standardize: bool, ridge: float = 0.0
) -> LocalModels:
    """Steps 2–3 of the method: local sets, then a local θ_k per set.

    See :func:`local_sets` and :func:`local_least_squares`.
    """
    check_n_rho(n_rho, phi.shape[1])
    return local_least_squares(phi, target, local_sets(phi, n_rho, standardize), ridge)
