"""Local sets and local least-squares parameter matrices (paper steps 2–3, eq. 6–7)."""

import os
from concurrent.futures import ThreadPoolExecutor
from numbers import Integral, Real

import numpy as np
from scipy.spatial import cKDTree
from sklearn.base import _fit_context, clone
from sklearn.utils._param_validation import HasMethods, Interval
from sklearn.utils.validation import check_memory

from ..._arrays import column_rms
from ..._blas import single_threaded_blas
from ..._threads import map_in_threads
from ..._typing import Float2D
from ..kernels.qr import local_solve
from .base import BaseLocalModels
from .neighbours import distinct_rows, nearest_neighbours

_RANK_TOL = 1e-10
_CHUNK = 256
"""Local sets per task of the solve (its θ_k and, where singular, R blocks: 256 × d × (d + m)
floats each); the results do not depend on it, bit for bit."""
_PER_SAMPLE = {"neighbours_": -1, "theta_": np.nan, "residual_var_": np.nan}
"""The per-sample arrays of [`LocalLeastSquares`][pwa_pipeline.pwa.LocalLeastSquares] and their value on the
samples whose local model was not estimated."""
_CONSTANT = "every regressor column is constant (the data do not vary): no local sets"


def check_n_rho(n_rho: int, d: int) -> None:
    """Raise a ValueError unless n_ρ > d (a local fit needs more points than parameters)."""
    if n_rho <= d:
        raise ValueError(
            f"n_rho = {n_rho} must exceed the regressor dimension d = {d}: each local set "
            f"needs more points than parameters per output"
        )


def local_sets(phi: Float2D, n_rho: int, standardize: bool, rows: np.ndarray | None = None
               ) -> np.ndarray:
    """Indices of the n_ρ nearest neighbours of every φ(k), φ(k) itself included (step 2),
    or of the rows ``rows`` only (their neighbours among every row).

    Parameters
    ----------
    phi : ndarray of shape (n, d)
    n_rho : int
        Cardinality of each local set C_k.
    standardize : bool
        Search on z-scored regressors (constant columns dropped) instead of raw ones, so that
        large-valued channels do not dominate the distance.
    rows : ndarray of shape (q,), int, optional
        The rows whose local sets are formed. None: every row.

    Returns
    -------
    ndarray of shape (n, n_ρ) or (q, n_ρ), int

    Above 12 dimensions the search is `nearest_neighbours`
    (exact, blocked float32 products; equal distances go to the lower row index), below it
    SciPy's k-d tree on every CPU (the neighbours of scikit-learn's, 4x faster on 400k rows).
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
            raise ValueError(_CONSTANT)
        x = (phi[:, keep] - phi[:, keep].mean(axis=0)) / std[keep]
    own = np.arange(n) if rows is None else np.asarray(rows)
    if d > 12:  # blocked float32 products (exact); trees lose to brute force there
        idx = nearest_neighbours(x, n_rho, queries=rows)
    else:  # a k-d tree, queried on every CPU
        idx = cKDTree(x).query(x[own], k=n_rho, workers=-1)[1].reshape(len(own), n_rho)
    # Duplicated regressors can put another row first; keep C_k's own row at position 0.
    not_first = idx[:, 0] != own
    if not_first.any():
        at = np.nonzero(not_first)[0]
        has_own = idx[at] == own[at, None]
        swap = np.where(has_own.any(axis=1), has_own.argmax(axis=1), n_rho - 1)
        idx[at, swap] = idx[at, 0]
        idx[at, 0] = own[at]
    return idx


def local_least_squares(
    phi: Float2D, target: Float2D, neighbours: np.ndarray, ridge: float = 0.0,
    workers: int | None = None,
) -> tuple[np.ndarray, Float2D, np.ndarray, np.ndarray]:
    """Least-squares θ_k on every local set (each row of ``neighbours``), batched over k
    (eq. 6–7).

    Each local problem is solved by a QR factorisation of the column-scaled local regressor
    matrix Φ_k with the targets appended as columns, [Φ_k | Y_k] = QR: the leading block
    R₁₁ is Φ_k's R, θ_k solves R₁₁ θ_k = R₁₂, and what the reflections leave below R₁₂
    has the residual norms. Only R is formed (Householder reflections and the back
    substitution compiled, `_qr_kernels`, on blocks of local sets, one thread
    each). With ``ridge > 0`` the rows √ridge·I are appended (Tikhonov
    regularisation in scaled units). A local set whose Φ_k is rank-deficient (e.g. every
    row inside one hold of a piecewise-constant input) has no unique θ_k: it gets the
    minimum-norm solution (in the unit-RMS columns, so independent of the channels' units)
    and is marked degenerate, never an error; unless its only dependent columns are zero
    throughout the set (an input at rest, as a vehicle's brake while it accelerates): θ_k is
    then identified on the other columns, 0 on those (the minimum norm), and not marked.

    Parameters
    ----------
    phi : ndarray of shape (n, d)
    target : ndarray of shape (n, m)
    neighbours : ndarray of shape (q, n_ρ), int
        Rows of ``phi`` in each local set.
    ridge : float
    workers : int, optional
        Threads (default: the CPUs this process may use).

    Returns
    -------
    theta : ndarray of shape (q, d, m)
        θ_k of eq. (6), in the regressors' own units.
    residual_var : ndarray of shape (q, m)
        SSR / (n_ρ − d) of each local fit, per output (the n_ρ data rows only).
    phi_scale : ndarray of shape (d,)
        Root mean square of each regressor column (the column scaling of the solve).
    degenerate : ndarray of shape (q,), bool
        Local sets whose (scaled, ridge-extended) Φ_k has a diagonal entry of R at most 1e-10
        of its largest (rank-deficient), other than those whose rank is the number of their
        columns that are not zero throughout.

    Raises
    ------
    ValueError
        If n_ρ ≤ d (an exact fit, no least squares).
    """
    n, d = phi.shape
    q, n_rho = neighbours.shape
    check_n_rho(n_rho, d)
    scale = column_rms(phi)
    m = target.shape[1]
    both = np.empty((n, d + m))
    both[:, :d], both[:, d:] = phi / scale, target
    theta = np.empty((q, d, m))
    resvar = np.empty((q, m))
    degenerate = np.zeros(q, bool)

    def solve(start: int) -> None:
        idx = neighbours[start : start + _CHUNK]
        c, rows = len(idx), slice(start, start + len(idx))
        th, ssr, singular = np.empty((c, d, m)), np.empty((c, m)), np.empty(c, bool)
        r11, r12 = np.empty((c, d, d)), np.empty((c, d, m))  # filled where singular
        local_solve(both, idx, d, np.sqrt(ridge), _RANK_TOL, th, ssr, singular, r11, r12)
        if singular.any():  # minimum norm: Φ_k = Q R₁₁, so pinv(Φ_k) Y_k = pinv(R₁₁) R₁₂
            th[singular] = np.linalg.pinv(r11[singular], rtol=_RANK_TOL) @ r12[singular]
        if ridge > 0:  # the n_ρ data rows only
            a = np.take(both, idx, axis=0)
            res = a[:, :, d:] - a[:, :, :d] @ th
            ssr = np.einsum("kij,kij->kj", res, res)
        elif singular.any():  # plus what R₁₁ θ_k leaves of R₁₂
            top = r12[singular] - r11[singular] @ th[singular]
            ssr[singular] += np.einsum("kij,kij->kj", top, top)
        if singular.any():  # singular only by columns zero throughout: identified on the rest
            rank = np.linalg.matrix_rank(r11[singular], rtol=_RANK_TOL)
            at_rest = ~np.take(both[:, :d], idx[singular], axis=0).any(axis=1)
            singular[np.flatnonzero(singular)[rank == d - at_rest.sum(axis=1)]] = False
        degenerate[rows] = singular
        theta[rows] = th / scale[:, None]
        resvar[rows] = ssr / (n_rho - d)

    with single_threaded_blas(), \
            ThreadPoolExecutor(workers or len(os.sched_getaffinity(0))) as pool:
        map_in_threads(pool, solve, range(0, q, _CHUNK))
    return theta, resvar, scale, degenerate


class LocalLeastSquares(BaseLocalModels):
    """Steps 2–3 of the method: a local set of n_ρ neighbours around every φ(k) and its
    least-squares parameter matrix θ_k (eq. 6–7).

    A sample that repeats an earlier one exactly (equal φ(k) and y(k)) counts once: the local
    sets hold distinct samples, and a copy gets its original's local model
    ([`fit`][pwa_pipeline.pwa.LocalLeastSquares.fit]).

    Parameters
    ----------
    n_rho : int, optional
        Local set size n_ρ (> d). None: 3·d, resolved at fit as ``n_rho_``.
    standardize : bool, default True
        Search neighbours on z-scored regressors. The paper searches on raw regressors
        (False), where large-valued channels (the inputs of its section 5 system) dominate the
        distance and few local sets are pure (``shared/paper/NOTES.md``).
    ridge : float, default 0
        Tikhonov term in column-scaled units (0: none; a rank-deficient local set then gets
        the minimum-norm solution and is marked in ``degenerate_``).
    max_sets : int, optional, default 5000
        Estimate the local models of at most this many distinct samples, a seeded random
        subset (each local set still holds its n_ρ nearest among every sample); the others
        get none (``estimated_``). The clustering step uses at most 3,000 local models
        (``DBSCANClustering.max_clustered``), so on a long record most local models would
        be estimated only to be left out, and on long records estimating them all takes
        most of the fit's time. None (the paper): every sample.
    random_state : int, default 0
        Seed of that subset.
    memory : str, object with the joblib.Memory interface, or None
        Where to keep the fitted local models (``joblib.Memory``'s ``cache``), keyed by the
        regressors, the outputs and the other parameters: the sets of a sweep whose later
        steps alone differ estimate them once. None: no cache.

    Attributes
    ----------
    theta_ : ndarray of shape (n, d, m)
        θ_k of every local set, in the regressors' own units; NaN for the samples whose local
        model was not estimated.
    residual_var_ : ndarray of shape (n, m)
        Residual variance of each local fit, SSR / (n_ρ − d), per output (NaN where not
        estimated).
    neighbours_ : ndarray of shape (n, n_ρ)
        Row indices of each local set C_k (the row itself first, then first occurrences of
        distinct samples); −1 where not estimated.
    estimated_ : ndarray of shape (n,), bool
        The samples whose local model was estimated (all of them with ``max_sets=None`` or
        at most ``max_sets`` distinct samples).
    phi_scale_ : ndarray of shape (d,)
        Root mean square of each regressor column (over the distinct rows), used to make θ
        unit-free.
    n_rho_ : int
        The n_ρ used.
    degenerate_ : ndarray of shape (n,), bool
        Local sets whose regressors are linearly dependent (rank-deficient Φ_k, e.g. inside
        one hold of a piecewise-constant input): θ_k is not identified there, and the
        clustering step leaves them out. A set whose only dependent columns are zero
        throughout (an input at rest) is not degenerate: its θ_k is 0 on those columns.
    n_degenerate_ : int
    n_estimated_ : int
        Local models estimated (each repeat of a sample counted).
    original_ : ndarray of shape (n,), int
        The first row with the same (φ(k), y(k)) as row k (k itself for a row met first);
        the clustering step counts each distinct sample once.

    Examples
    --------
    >>> import numpy as np
    >>> phi = np.random.default_rng(0).normal(size=(200, 2))
    >>> step = LocalLeastSquares(n_rho=10).fit(phi, phi @ np.array([[1.0], [-2.0]]))
    >>> step.theta_.shape, bool(np.allclose(step.theta_[:, :, 0], [1.0, -2.0]))
    ((200, 2, 1), True)
    """

    _parameter_constraints: dict = {
        "n_rho": [Interval(Integral, 2, None, closed="left"), None],
        "standardize": ["boolean"],
        "ridge": [Interval(Real, 0, None, closed="left")],
        "max_sets": [Interval(Integral, 1, None, closed="left"), None],
        "random_state": [Interval(Integral, 0, None, closed="left")],
        "memory": [None, str, HasMethods(["cache"])],
    }

    def __init__(self, n_rho: int | None = None, standardize: bool = True, ridge: float = 0.0,
                 max_sets: int | None = 5000, random_state: int = 0, memory=None):
        self.n_rho = n_rho
        self.standardize = standardize
        self.ridge = ridge
        self.max_sets = max_sets
        self.random_state = random_state
        self.memory = memory

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, phi: Float2D, target: Float2D) -> "LocalLeastSquares":
        """Local sets (`local_sets`) and local least squares (`local_least_squares`)
        on the distinct samples (φ(k), y(k)); a repeated sample gets its first occurrence's.

        A sample that repeats another exactly (the same experiment given twice, a record
        tiled) is the same measurement, not a new one: counted again, its copies would fill
        the local sets (ten copies of each row leave n_ρ/10 distinct rows in a set of n_ρ, a
        rank-deficient Φ_k when that is below d). So the search and the fits run on the
        distinct rows and every copy gets its original's local set (its own index first),
        θ_k and residual variance: a record repeated r times gives the local models of the
        record once, r times over. Rows with equal φ(k) but different y(k) stay distinct.
        Above ``max_sets`` distinct samples, the local models of a seeded random
        ``max_sets`` of them are estimated (drawn among the distinct samples in order of
        first occurrence, so a record repeated is sampled as the record once).

        Parameters
        ----------
        phi : ndarray of shape (n, d)
        target : ndarray of shape (n, m)
        """
        plain = clone(self).set_params(memory=None)
        fitted = check_memory(self.memory).cache(_fitted)(plain, phi, target)
        self.__dict__.update({k: v for k, v in vars(fitted).items() if k.endswith("_")})
        return self

    def _fit(self, phi: Float2D, target: Float2D) -> "LocalLeastSquares":
        """[`fit`][pwa_pipeline.pwa.LocalLeastSquares.fit] without the cache."""
        n, d = phi.shape
        self.n_rho_ = self.n_rho if self.n_rho is not None else 3 * d
        check_n_rho(self.n_rho_, d)
        first, inverse = distinct_rows(np.concatenate([phi, target], axis=1))
        if len(first) == 1 < n:
            raise ValueError(_CONSTANT)
        if self.n_rho_ > len(first):
            raise ValueError(
                f"too few samples for n_rho = {self.n_rho_}: the data give only {len(first)} "
                f"distinct regressor rows" + (f" ({n} with repeats)" if len(first) < n else "")
            )
        repeats = len(first) < n
        p, t = (phi[first], target[first]) if repeats else (phi, target)
        sets = None
        if self.max_sets is not None and len(first) > self.max_sets:
            sets = np.sort(np.random.default_rng(self.random_state).choice(
                len(first), self.max_sets, replace=False))
        idx = local_sets(p, self.n_rho_, self.standardize, sets)
        theta, resvar, self.phi_scale_, degenerate = local_least_squares(p, t, idx, self.ridge)
        estimated = np.ones(len(first), bool)
        if sets is not None:  # the samples not in the subset: no local model
            estimated = np.zeros(len(first), bool)
            estimated[sets] = True
            degenerate = _spread(degenerate, sets, len(first), False)
        if repeats:  # every copy of an estimated sample: its original's, its own index first
            at = (np.cumsum(estimated) - 1)[inverse]  # row → its original's estimated row
            degenerate, estimated = degenerate[inverse], estimated[inverse]
            at = at[estimated]
            idx, theta, resvar = first[idx][at], theta[at], resvar[at]
            idx[:, 0] = np.flatnonzero(estimated)
        self.degenerate_, self.original_ = degenerate, first[inverse]
        self.estimated_ = estimated
        if not estimated.all():  # the samples without a local model: −1 and NaN
            at = np.flatnonzero(estimated)
            idx = _spread(idx, at, n, -1)
            theta = _spread(theta, at, n, np.nan)
            resvar = _spread(resvar, at, n, np.nan)
        self.neighbours_, self.theta_, self.residual_var_ = idx, theta, resvar
        self.n_degenerate_ = int(degenerate.sum())
        self.n_estimated_ = int(estimated.sum())
        return self

    def resolved_params(self) -> dict:
        """`get_params` with the values chosen at fit filled in (n_ρ)."""
        return {**self.get_params(), "n_rho": self.n_rho_}

    def __getstate__(self) -> dict:
        """The state to pickle, the per-sample arrays (`_PER_SAMPLE`) on the estimated
        samples only: their other rows hold no information, so a stored or cached step fitted
        with ``max_sets`` takes about ``max_sets`` / n of the room."""
        state = dict(super().__getstate__())
        estimated = state.get("estimated_")
        if estimated is not None and not estimated.all():
            state.update({name: state[name][estimated] for name in _PER_SAMPLE})
        return state

    def __setstate__(self, state: dict) -> None:
        """The pickled state (`__getstate__`), its per-sample arrays spread back to
        every sample."""
        estimated = state.get("estimated_")
        if estimated is not None and len(state.get("theta_", estimated)) < len(estimated):
            rows = np.flatnonzero(estimated)
            state = {**state, **{name: _spread(state[name], rows, len(estimated), fill)
                                 for name, fill in _PER_SAMPLE.items()}}
        super().__setstate__(state)


def _fitted(step: LocalLeastSquares, phi: Float2D, target: Float2D) -> LocalLeastSquares:
    """``step`` (without a cache) fitted: what ``memory`` keeps."""
    return step._fit(phi, target)


def _spread(values: np.ndarray, rows: np.ndarray, n: int, fill) -> np.ndarray:
    """An array of ``n`` rows holding ``values`` at ``rows`` and ``fill`` elsewhere."""
    out = np.full((n, *values.shape[1:]), fill, dtype=values.dtype)
    out[rows] = values
    return out
