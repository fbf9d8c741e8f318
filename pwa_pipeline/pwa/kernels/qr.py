"""Compiled Householder QR of the local least-squares problems (step 3,
`local_models.local_least_squares`).

LAPACK's ``geqrf`` spends most of its time on a small matrix (72 × 30 on the robot: about
19 µs, a sixth of the machine's speed) in the calls of its level-2 steps on short vectors.
Compiled, the reflections of one local problem run as plain loops over contiguous columns,
vectorised (reassociated sums), and the local set is gathered in the same pass: the solve
takes 0.7× the CPU time of LAPACK's on the robot (``benchmarks.local_solve``). numba,
compiled on first use and cached on disk (``cache=True``); ``nogil`` so that threads run it
side by side.
"""

import numpy as np
from numba import njit


@njit(nogil=True, cache=True, fastmath={"reassoc", "contract"})
def local_solve(both: np.ndarray, rows: np.ndarray, n_params: int, damp: float,
                rank_tol: float, theta: np.ndarray, ssr: np.ndarray, singular: np.ndarray,
                r_left: np.ndarray, r_right: np.ndarray) -> None:
    """θ_k of each local set k from the QR of [Φ_k | Y_k]: Householder reflections of its
    ``n_params`` regressor columns (applied to the target columns too), then R₁₁ θ_k = R₁₂
    by back substitution.

    Parameters
    ----------
    both : ndarray of shape (n, d + m)
        The column-scaled regressors and the targets, one row per sample.
    rows : ndarray of shape (c, n_ρ), int
        Each local set's rows of ``both``.
    n_params : int
        d.
    damp : float
        √ridge: the rows √ridge·I (zeros under the targets) are appended to each Φ_k when
        positive.
    rank_tol : float
        Φ_k is rank-deficient (singular) when R₁₁'s smallest diagonal entry is at most
        ``rank_tol`` of its largest.
    theta : ndarray of shape (c, d, m)
        Filled: θ_k where Φ_k is not singular (in the scaled columns).
    ssr : ndarray of shape (c, m)
        Filled: the squared norm of what the reflections leave below R₁₂, per target: the
        residual sum of squares of the least-squares fit (appended rows included) where
        Φ_k is not singular.
    singular : ndarray of shape (c,), bool
        Filled.
    r_left, r_right : ndarray of shape (c, d, d) and (c, d, m)
        Filled where Φ_k is singular: R₁₁ (upper triangular; its diagonal's signs are not
        made positive) and R₁₂, for the caller's minimum-norm solution.
    """
    c, n_rho = rows.shape
    d = n_params
    cols = both.shape[1]
    m = cols - d
    height = n_rho + (d if damp > 0 else 0)
    a = np.empty((cols, height))  # one local problem, column by column
    for k in range(c):
        for i in range(n_rho):
            r = rows[k, i]
            for j in range(cols):
                a[j, i] = both[r, j]
        for i in range(n_rho, height):
            for j in range(cols):
                a[j, i] = damp if j == i - n_rho else 0.0
        for j in range(d):
            v = a[j, j:]  # x, then v = x − α e₁ with α = −sign(x₀)‖x‖
            s = 0.0
            for i in range(height - j):
                s += v[i] * v[i]
            x0 = v[0]
            alpha = -np.sqrt(s) if x0 >= 0 else np.sqrt(s)
            v[0] = x0 - alpha
            vv = s - x0 * x0 + v[0] * v[0]
            tau = 2.0 / vv if vv > 0 else 0.0
            for col in range(j + 1, cols):  # a ← (I − τ v vᵀ) a
                w = a[col, j:]
                t = 0.0
                for i in range(height - j):
                    t += v[i] * w[i]
                t *= tau
                for i in range(height - j):
                    w[i] -= t * v[i]
            v[0] = alpha
        low, high = np.inf, 0.0
        for i in range(d):
            low, high = min(low, abs(a[i, i])), max(high, abs(a[i, i]))
        singular[k] = low <= rank_tol * high
        for j in range(m):
            s = 0.0
            for i in range(d, height):
                s += a[d + j, i] * a[d + j, i]
            ssr[k, j] = s
        if singular[k]:
            for i in range(d):
                for j in range(d):
                    r_left[k, i, j] = a[j, i] if j >= i else 0.0
                for j in range(m):
                    r_right[k, i, j] = a[d + j, i]
            continue
        for i in range(d - 1, -1, -1):  # R₁₁[i, j] is a[j, i], R₁₂[i, t] is a[d + t, i]
            for t in range(m):
                s = a[d + t, i]
                for j in range(i + 1, d):
                    s -= a[j, i] * theta[k, j, t]
                theta[k, i, t] = s / a[i, i]
