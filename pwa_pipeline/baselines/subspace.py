"""Linear state-space baseline identified by a subspace (N4SID-type) method.

x(k+1) = A x(k) + B u(k) + K e(k),  y(k) = C x(k) + D u(k) + e(k)   (paper eq. 20, discrete)

The state sequence is estimated from an LQ factorisation of block Hankel matrices and an
oblique projection (Van Overschee & De Moor 1996, ch. 4; "robust" state-sequence variant),
then (A, B, C, D) by least squares on consecutive states, and K from the residual covariances
through the Riccati equation. Only (k·(r+m)) × (k·(r+m)) matrices are factorised, never
N × N ones, so 40k samples need a few hundred MB at most.
"""

import time
from numbers import Integral, Real

import numpy as np
from scipy.linalg import solve_discrete_are
from sklearn.base import BaseEstimator, _fit_context
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from .._arrays import column_rms
from .._blas import single_threaded_blas
from .._typing import Float2D, Signals
from .._validation import (
    _is_experiment_list,
    as_experiments,
    as_signal,
    check_n_init,
    check_width,
)
from ..control.state_space import PWAStateSpace
from ..envelope import PADDING, channel_bounds, outside_box, training_range
from ..scoring.metrics import r2_score


def _block_hankel(x: Float2D, start: int, rows: int, cols: int) -> Float2D:
    """Block Hankel matrix with ``rows`` block rows of x(start + i + j), j < cols."""
    return np.vstack([x[start + i : start + i + cols].T for i in range(rows)])


class SubspaceSS(BaseEstimator):
    """Linear innovation state-space model identified by a subspace method.

    Parameters
    ----------
    order : int, optional
        State dimension n. None chooses it at the largest gap of the singular values
        (``singular_values_``), at most ``horizon``·m.
    horizon : int, default 10
        Past and future block rows k of the Hankel matrices (k·m ≥ n).
    warmup : int, default 10
        Samples used to estimate the initial state when [`predict`][pwa_pipeline.baselines.SubspaceSS.predict]
        is not told.
    refit : {"none", "simulation"}, default "none"
        ``"simulation"``: after the subspace step, A's eigenvalues are pulled inside the
        radius ``max_radius`` and B, D refitted by least squares on the free-run (simulation)
        error of the training experiments, A and C kept. The free-run output is linear in B,
        D and each experiment's initial state, so this is one least-squares problem (the
        initial states projected out per experiment), not an iteration: the same care as the
        ARX models' simulation-error refinement, for a fair baseline.
    max_radius : float, default 0.9995
        Largest eigenvalue modulus of A with ``refit="simulation"``.

    Attributes
    ----------
    A_, B_, C_, D_, K_ : ndarrays
        System matrices (n×n, n×r, m×n, m×r, n×m).
    order_ : int
    singular_values_ : ndarray
        Of the weighted oblique projection, for choosing the order.
    n_inputs_, n_outputs_ : int
    signal_range_ : ndarray of shape (2, m + r)
        Smallest and largest training value of each output, then each input: the data
        envelope of [`outside_envelope`][pwa_pipeline.baselines.SubspaceSS.outside_envelope].
    timings_ : dict
        Seconds of the fit (``fit``).

    Examples
    --------
    >>> import numpy as np
    >>> from pwa_pipeline import SubspaceSS
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(2000, 1)); y = np.zeros((2000, 1)); x = 0.0
    >>> for k in range(2000):
    ...     y[k] = x; x = 0.9 * x + u[k, 0]
    >>> model = SubspaceSS(order=1).fit(u, y)
    >>> round(float(model.A_[0, 0]), 6)
    0.9
    """

    _parameter_constraints: dict = {
        "order": [Interval(Integral, 1, None, closed="left"), None],
        "horizon": [Interval(Integral, 1, None, closed="left")],
        "warmup": [Interval(Integral, 1, None, closed="left")],
        "refit": [StrOptions({"none", "simulation"})],
        "max_radius": [Interval(Real, 0, 1, closed="right")],
    }

    def __init__(self, order: int | None = None, horizon: int = 10, warmup: int = 10,
                 refit: str = "none", max_radius: float = 0.9995):
        self.order = order
        self.horizon = horizon
        self.warmup = warmup
        self.refit = refit
        self.max_radius = max_radius

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, u: Signals, y: Signals) -> "SubspaceSS":
        """Identify (A, B, C, D, K) from one or several experiments.

        Raises
        ------
        ValueError
            On bad input, experiments all shorter than 2·horizon + 1, or an order larger than
            horizon·m.
        """
        t0 = time.perf_counter()
        pairs = as_experiments(u, y)
        self.signal_range_ = training_range(pairs)
        # Identify on unit-RMS channels (conditioning of the LQ factor), then map back.
        su = column_rms(np.vstack([p[0] for p in pairs]))
        sy = column_rms(np.vstack([p[1] for p in pairs]))
        pairs = [(ue / su, ye / sy) for ue, ye in pairs]
        k = self.horizon
        r, m = pairs[0][0].shape[1], pairs[0][1].shape[1]
        if self.order is not None and self.order > k * m:
            raise ValueError(
                f"order {self.order} exceeds horizon·m = {k * m}: raise horizon to at least "
                f"{-(-self.order // m)}"
            )
        blocks = [p for p in pairs if p[0].shape[0] >= 2 * k + 2]
        if not blocks:
            raise ValueError(
                f"every experiment is shorter than 2·horizon + 2 = {2 * k + 2} samples"
            )
        hank = []
        for ue, ye in blocks:
            j = ue.shape[0] - 2 * k
            hank.append(np.vstack([
                _block_hankel(ue, k, k, j), _block_hankel(ue, 0, k, j),
                _block_hankel(ye, 0, k, j), _block_hankel(ye, k, k, j),
            ]))
        h = np.hstack(hank)
        # LQ of H through QR of its transpose: only the (rows × rows) factor is kept.
        lower = np.linalg.qr(h.T, mode="r").T
        nu, nw = k * r, k * (r + m)
        l22 = lower[nu : nu + nw, nu : nu + nw]
        l32 = lower[nu + nw :, nu : nu + nw]
        # Oblique projection of future outputs along future inputs onto the past.
        proj = l32 @ np.linalg.pinv(l22) @ h[nu : nu + nw]
        left, sv, right = np.linalg.svd(proj, full_matrices=False)
        self.singular_values_ = sv
        n = self.order if self.order is not None else _order_from_gap(sv, k * m)
        states = np.sqrt(sv[:n])[:, None] * right[:n]
        # Consecutive states within each experiment give (A, B, C, D) by least squares.
        x_now, x_next, u_now, y_now = [], [], [], []
        col = 0
        for ue, ye in blocks:
            j = ue.shape[0] - 2 * k
            xs = states[:, col : col + j]
            x_now.append(xs[:, :-1])
            x_next.append(xs[:, 1:])
            u_now.append(ue[k : k + j - 1].T)
            y_now.append(ye[k : k + j - 1].T)
            col += j
        xu = np.vstack([np.hstack(x_now), np.hstack(u_now)])
        target = np.vstack([np.hstack(x_next), np.hstack(y_now)])
        theta = np.linalg.lstsq(xu.T, target.T, rcond=None)[0].T
        self.A_, self.B_ = theta[:n, :n], theta[:n, n:]
        self.C_, self.D_ = theta[n:, :n], theta[n:, n:]
        res = target - theta @ xu
        cov = res @ res.T / res.shape[1]
        self.K_ = _kalman_gain(self.A_, self.C_, cov[:n, :n], cov[n:, n:], cov[:n, n:])
        if self.refit == "simulation":
            self.A_ = _stabilised(self.A_, self.max_radius)
            with single_threaded_blas():  # small products: threads only wait
                self.B_, self.D_ = _simulation_fit(self.A_, self.C_, pairs)
        self.B_, self.C_ = self.B_ / su, sy[:, None] * self.C_
        self.D_, self.K_ = sy[:, None] * self.D_ / su, self.K_ / sy
        self.order_ = n
        self.n_inputs_, self.n_outputs_ = r, m
        self.n_features_in_ = r
        self.timings_ = {"fit": time.perf_counter() - t0}
        return self

    def resolved_params(self) -> dict:
        """`get_params` with the order chosen at fit filled in."""
        return {**self.get_params(), "order": self.order_}

    @property
    def poles_(self) -> np.ndarray:
        """Eigenvalues of A."""
        return np.linalg.eigvals(self.A_)

    def initial_state(self, u: Float2D, y: Float2D) -> np.ndarray:
        """Least-squares x(0) from a window of data through the Kalman predictor.

        With Ā = A − KC the predictor's output is ŷ(k) = C Āᵏ x0 + (terms of u and y), linear
        in x0; the window's one-step errors are minimised over x0.
        """
        n, w = self.order_, y.shape[0]
        if w * self.n_outputs_ < n:
            raise ValueError(
                f"warm-up too short: {w} sample(s) of {self.n_outputs_} output(s) cannot fix "
                f"{n} states; use at least {-(-n // self.n_outputs_)}"
            )
        abar = self.A_ - self.K_ @ self.C_
        bbar = self.B_ - self.K_ @ self.D_
        obs = np.empty((w, self.n_outputs_, n))
        forced = np.empty((w, self.n_outputs_))
        power, x = np.eye(n), np.zeros(n)
        for k in range(w):
            obs[k] = self.C_ @ power
            forced[k] = self.C_ @ x + self.D_ @ u[k]
            power = abar @ power
            x = abar @ x + bbar @ u[k] + self.K_ @ y[k]
        lhs = obs.reshape(w * self.n_outputs_, n)
        return np.linalg.lstsq(lhs, (y - forced).ravel(), rcond=None)[0]

    def _check(self, u, y, y_name):
        check_is_fitted(self)
        ue, ye = as_signal(u, "u"), as_signal(y, y_name)
        check_width(ue, self.n_inputs_, "u", "input(s)")
        check_width(ye, self.n_outputs_, y_name, "output(s)")
        return ue, ye

    def predict(self, u: Signals, y: Signals, n_init: int | None = None):
        """One-step-ahead prediction by the Kalman predictor, from x(0) fitted on the first
        ``n_init`` samples (default ``warmup``); those rows are returned as given.

        Lists of experiments give lists of predictions.
        """
        if _is_experiment_list(u):
            return [self.predict(a, b, n_init) for a, b in zip(u, y, strict=True)]
        ue, ye = self._check(u, y, "y")
        as_experiments(ue, ye)
        check_n_init(n_init, ye.shape[0])
        w = self.warmup if n_init is None else n_init
        out = ye.copy()
        out[w:] = self._predictor(ue, ye, w)[1][w:]
        return out

    def _predictor(self, u: Float2D, y: Float2D, w: int) -> tuple[Float2D, Float2D]:
        """The Kalman predictor's states x(k) and one-step outputs ŷ(k) of one experiment,
        from x(0) fitted on its first ``w`` samples."""
        x = self.initial_state(u[:w], y[:w])
        states, out = np.empty((len(y), self.order_)), np.empty_like(y)
        for k in range(y.shape[0]):
            states[k] = x
            out[k] = self.C_ @ x + self.D_ @ u[k]
            x = self.A_ @ x + self.B_ @ u[k] + self.K_ @ (y[k] - out[k])
        return states, out

    def to_state_space(self, u: Signals, y: Signals, *, padding: float = PADDING,
                       input_names: list[str] | None = None,
                       output_names: list[str] | None = None) -> PWAStateSpace:
        """The model as a state-space model of one mode, x⁺ = A x + B u, y = C x + D u
        ([`PWAStateSpace`][pwa_pipeline.control.PWAStateSpace], state ``x1 … xn``), for controller
        design beside the ARX models' forms.

        Its envelope, where the model is said to be known, is the range of its states over
        the data ``u``, ``y`` (the training data: the Kalman predictor's states, each
        experiment started from its first ``warmup`` samples) and each input's training
        range, widened by ``padding`` of each span. Its state is not made of past outputs,
        so it is simulated from an initial state (``ss.simulate(u, x0=...)``, e.g.
        [`initial_state`][pwa_pipeline.baselines.SubspaceSS.initial_state] of a warm-up).

        Parameters
        ----------
        u, y : array-like or lists of them
            The training data (the model keeps no state trajectory of its own).
        padding : float, default PADDING
        input_names, output_names : list of str, optional

        Returns
        -------
        PWAStateSpace
        """
        check_is_fitted(self)
        pairs = [(ue, ye) for ue, ye in as_experiments(u, y) if len(ye) > self.warmup]
        if not pairs:
            raise ValueError(f"every experiment is shorter than the warm-up of {self.warmup} "
                             f"samples: no state to bound the envelope with")
        states = np.vstack([self._predictor(ue, ye, self.warmup)[0] for ue, ye in pairs])
        x_lo, x_hi = channel_bounds(np.vstack([states.min(axis=0), states.max(axis=0)]),
                                    padding)
        u_lo, u_hi = (b[self.n_outputs_:] for b in channel_bounds(self.signal_range_, padding))
        n, m, r = self.order_, self.n_outputs_, self.n_inputs_
        return PWAStateSpace(
            self.A_[None], self.B_[None], np.zeros((1, n)), self.C_[None], np.zeros((1, m)),
            [(np.zeros((0, n + r)), np.zeros(0))], np.concatenate([x_lo, u_lo]),
            np.concatenate([x_hi, u_hi]), output_lags=None, input_lags=None,
            D=self.D_[None], input_names=input_names, output_names=output_names,
            padding=padding, source={"model": type(self).__name__, "order": n,
                                     "structures": ["linear state space"] * m})

    def simulate(self, u: Signals, y_init: Signals):
        """Free-run simulation from x(0) fitted on the warm-up window ``y_init``.

        Returns an array of u's length whose first len(y_init) rows are ``y_init``; a run that
        diverges is returned as it is.

        Raises
        ------
        ValueError
            Wrong input width, a warm-up shorter than 1 sample or longer than u, or NaN.
        """
        if _is_experiment_list(u):
            return [self.simulate(a, b) for a, b in zip(u, y_init, strict=True)]
        ue, ye = self._check(u, y_init, "y_init")
        w = ye.shape[0]
        if w < 1 or w > ue.shape[0]:
            raise ValueError(
                f"warm-up too short or too long: y_init has {w} rows, u has {ue.shape[0]}"
            )
        x = self.initial_state(ue[:w], ye)
        out = np.empty((ue.shape[0], self.n_outputs_))
        out[:w] = ye
        with np.errstate(over="ignore", invalid="ignore"):
            for k in range(ue.shape[0]):
                if k >= w:
                    out[k] = self.C_ @ x + self.D_ @ ue[k]
                x = self.A_ @ x + self.B_ @ ue[k]
        return out


    def score(self, u: Signals, y: Signals) -> float:
        """Mean R² (eq. 22, standard form) of the one-step-ahead prediction over outputs,
        the first ``warmup`` samples of each experiment (the initial state's) left out."""
        pairs = as_experiments(u, y)
        yhat = self.predict([p[0] for p in pairs], [p[1] for p in pairs])
        w = self.warmup
        return float(np.mean(r2_score(np.vstack([p[1][w:] for p in pairs]),
                                      np.vstack([p[w:] for p in yhat]))))

    def outside_envelope(self, u: Signals, y: Signals, padding: float = PADDING
                         ) -> np.ndarray | list[np.ndarray]:
        """Whether each sample k follows data outside the training range: the state x(k)
        sums up the past, and the model is known only where the past inputs and outputs
        went, so sample k is flagged when u(k−1) or y(k−1) leaves its channel's training
        range widened by ``padding`` of its span (` channel_bounds`; the ARX models test their regressor φ(k)
        likewise).

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays
        y : array-like of shape (N, m), or a list of such arrays
            Measured outputs, or a simulation's (NaN or inf counts as outside).
        padding : float, default PADDING

        Returns
        -------
        ndarray of bool, shape (N,), or a list of them (one per experiment for a list)
            False on sample 0, which has no past.
        """
        check_is_fitted(self)
        lower, upper = channel_bounds(self.signal_range_, padding)
        many = _is_experiment_list(u)
        flags = []
        for ue, ye in zip(u if many else [u], y if many else [y], strict=True):
            ue = as_signal(ue, "u")
            ye = np.asarray(ye, dtype=float)
            ye = ye[:, None] if ye.ndim == 1 else ye
            check_width(ue, self.n_inputs_, "u", "input(s)")
            check_width(ye, self.n_outputs_, "y", "output(s)")
            flag = np.zeros(len(ye), bool)
            flag[1:] = outside_box(np.hstack([ye, ue])[:-1], lower, upper)
            flags.append(flag)
        return flags if many else flags[0]


def _stabilised(a: Float2D, radius: float) -> Float2D:
    """A with every eigenvalue of modulus above ``radius`` pulled onto it (the
    eigenvectors kept)."""
    lam, vec = np.linalg.eig(a)
    big = np.abs(lam) > radius
    if not big.any():
        return a
    lam[big] *= radius / np.abs(lam[big])
    return np.real(vec @ np.diag(lam) @ np.linalg.inv(vec))


def _simulation_fit(a: Float2D, c: Float2D, pairs: list) -> tuple[Float2D, Float2D]:
    """B and D minimising the free-run error Σ‖y(k) − ŷ(k)‖² over the experiments, with A
    and C fixed and each experiment's initial state free (projected out).

    ŷ(k) = C Aᵏ x0 + Σ_{j<k} C A^{k−j−1} B u(j) + D u(k) is linear in (B, D, x0); the
    sensitivities S(k) = dx(k)/dB follow S(k+1) = A S(k) + I ⊗ u(k)ᵀ. The experiments run
    in lockstep (padded), and only the normal equations are kept, with the initial-state
    directions Γ = [C; CA; …] removed as XᵀX − (QᵀX)ᵀ(QᵀX), Q an orthonormal basis of Γ.
    """
    n, m, r = a.shape[0], c.shape[0], pairs[0][0].shape[1]
    lengths = np.array([len(ue) for ue, _ in pairs])
    e, big = len(pairs), lengths.max()
    u, y = np.zeros((e, big, r)), np.zeros((e, big, m))
    for i, (ue, ye) in enumerate(pairs):
        u[i, :len(ue)], y[i, :len(ye)] = ue, ye
    obs, power = np.empty((big, m, n)), np.eye(n)
    for k in range(big):
        obs[k], power = c @ power, a @ power
    q = np.zeros((e, big, m, n))
    for length in np.unique(lengths):
        basis = np.linalg.qr(obs[:length].reshape(-1, n))[0].reshape(length, m, n)
        q[lengths == length, :length] = basis
    p, diag = n * r + m * r, np.arange(max(n, m))
    xtx, xty = np.zeros((p, p)), np.zeros(p)
    qx, qy = np.zeros((e, n, p)), np.zeros((e, n))
    sens = np.zeros((e, n, n, r))
    for k in range(big):
        live = (lengths > k)[:, None, None]
        rows = np.zeros((e, m, p))
        rows[:, :, :n * r] = c @ sens.reshape(e, n, n * r)
        d_part = np.zeros((e, m, m, r))
        d_part[:, diag[:m], diag[:m], :] = u[:, k, None, :]
        rows[:, :, n * r:] = d_part.reshape(e, m, m * r)
        rows *= live
        flat = rows.reshape(-1, p)
        xtx += flat.T @ flat
        xty += flat.T @ y[:, k].ravel()
        qk = q[:, k].transpose(0, 2, 1)  # stacked matrix products (BLAS), not einsum
        qx += qk @ rows
        qy += (qk @ y[:, k, :, None])[..., 0]
        sens = (a @ sens.reshape(e, n, n * r)).reshape(e, n, n, r)
        sens[:, diag[:n], diag[:n], :] += u[:, k, None, :]
    xtx -= np.einsum("enp,enq->pq", qx, qx)
    xty -= np.einsum("enp,en->p", qx, qy)
    theta = np.linalg.lstsq(xtx, xty, rcond=None)[0]
    return theta[:n * r].reshape(n, r), theta[n * r:].reshape(m, r)


def _order_from_gap(sv: np.ndarray, max_order: int) -> int:
    """The order at the largest drop of log singular value, 1 … max_order."""
    s = np.maximum(sv[: max_order + 1], np.finfo(float).tiny)
    return int(np.argmax(-np.diff(np.log(s)))) + 1


def _kalman_gain(a, c, q, r, s) -> np.ndarray:
    """Steady-state Kalman gain from the process/measurement covariances (zero if none)."""
    n, m = a.shape[0], c.shape[0]
    try:
        p = solve_discrete_are(a.T, c.T, q, r, s=s)
        return (a @ p @ c.T + s) @ np.linalg.inv(c @ p @ c.T + r)
    except (np.linalg.LinAlgError, ValueError):
        return np.zeros((n, m))
