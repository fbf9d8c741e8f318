"""The PWA state-space model a controller designer uses, built from a fitted PWARX model.

A PWARX model (the paper's eq. 1) predicts y(k) = Θ_iᵀ φ(k) where φ(k) ∈ H_i, with φ(k) the
regressor of eq. (2)–(3): per output its lags y_p(k−1) … y_p(k−L), per input its lags
u_q(k−1) … u_q(k−nb), then 1 when the model is affine. Its state-space form keeps those past
values as a non-minimal state, x(k) = φ(k) without the constant (n = m·L + r·nb entries, in
eq. (3)'s order, named ``y1(k-1)``, ``u2(k-2)``…), so that

    x(k+1) = A_i x(k) + B_i u(k) + f_i,    y(k) = C_i x(k) + g_i,
    valid where z(k) = [x(k); u(k)] ∈ P_i = {z : H_i z ≤ h_i},

with y(k) = C_i x(k) + g_i the sub-model's prediction (C_i, g_i the rows of Θ_i over x and
over the constant), A_i the shift of the lags with that prediction entering the newest output
lag, and B_i placing u(k) in the newest input lag. This is the form of MPT3's ``PWASystem``
(each mode an ``LTISystem`` with D = 0 and its domain set over (x, u)). The regions P_i are
the model's regions made explicit inside the **data envelope**, the box of training values
slightly padded (`pwa_pipeline.control.conversion`); outside it the model is an
extrapolation and [`PWAStateSpace.mode_of`][pwa_pipeline.control.PWAStateSpace.mode_of] says so (−1).
"""

from pathlib import Path

import numpy as np

from .._typing import Float2D, Signals
from .._validation import (
    _is_experiment_list,
    as_experiments,
    as_signal,
    check_width,
    warmup_pairs,
)
from ..envelope import PADDING, outside_box
from ..regressors import lagged_matrix, n_initial, regressor_names
from .json_format import read_json, to_document, write_json
from .mpt3 import mpt3_script

#: Distance (in half-widths of the envelope, along a region row's unit normal) within which a
#: point counts as on a region's boundary: such a point lies in several closed regions and
#: takes the lowest-numbered one (the tie rule of `PWAStateSpace.mode_of`).
TIE_TOL = 1e-9

#: What `PWAStateSpace.simulate` does when the trajectory leaves the envelope.
OUTSIDE = ("raise", "nearest")


def _array(value, name: str, ndim: int) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ValueError(f"{name} must be a numeric array: {exc}") from None
    if arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimension(s), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} holds non-finite values")
    return arr


def _check_shape(arr: np.ndarray, expected: tuple, name: str, meaning: str) -> None:
    if arr.shape != expected:
        raise ValueError(f"{name} has shape {arr.shape}; expected {meaning} = {expected}")


class PWAStateSpace:
    """A discrete-time PWA state-space model x⁺ = A_i x + B_i u + f_i,
    y = C_i x + D_i u + g_i, valid where z = [x; u] ∈ P_i = {z : H_i z ≤ h_i} (see the
    module doc).

    Built by [`to_state_space`][pwa_pipeline.control.to_state_space] (``model.to_state_space()``) or
    read by [`from_json`][pwa_pipeline.control.PWAStateSpace.from_json]. An ARX model's state is the
    non-minimal one of eq. (2)–(3): the last L outputs and nb inputs (``output_lags``, ``input_lags``), so
    [`simulate`][pwa_pipeline.control.PWAStateSpace.simulate] from a warm-up of measured outputs gives the
    fitted model's simulation, and D = 0. A state of another kind (the subspace baseline's,
    ``output_lags=None``) has its own names and is simulated from a given initial state (``simulate(u,
    x0=...)``).

    Parameters
    ----------
    A, B, f, C, g : array-like
        Shapes (s, n, n), (s, n, r), (s, n), (s, m, n), (s, m).
    D : array-like of shape (s, m, r), optional
        Feedthrough of the current input to the output; default zero.
    regions : list of (H, h)
        One pair per mode, H of shape (k_i, n + r) and h of shape (k_i,).
    lower, upper : array-like of shape (n + r,)
        The data envelope, lower < upper.
    output_lags, input_lags : int or None
        L and nb: the state holds y(k−1) … y(k−L) of each output, then u(k−1) … u(k−nb) of
        each input, n = m·L + r·nb. None for both: the state is not made of past values.
    state_names : list of str, optional
        The state's entries' names when it is not made of past values (default ``x1…``).
    affine : bool, default False
        φ ends in the constant 1 (eq. 2), for [`regressors`][pwa_pipeline.control.PWAStateSpace.regressors].
    input_names, output_names : list of str, optional
        Default ``u1…`` and ``y1…``.
    padding : float or None, default 0.05
        How far the envelope was widened beyond the training range (a share of each
        channel's span), kept for the record (None: not known).
    mode_regions : array-like of int, shape (s, m), optional
        For each mode, the region of each output's sub-model in the fitted model (the same
        in every column for a model with one partition). Default: mode i is region i.
    dropped_modes : array-like of int, shape (k, m), optional
        The same for the combinations left out as empty inside the envelope.
    source : dict, optional
        What the model was converted from (class, orders, each output's structure, the
        outputs' coupling: `model_source`), for the record.

    Attributes
    ----------
    A, B, f, C, g : ndarrays
    regions : list of (ndarray, ndarray)
    envelope : tuple of ndarrays
        (lower, upper) over z.
    n_modes, n_states, n_inputs, n_outputs : int
    state_names, input_names, output_names : list of str
    mode_regions, dropped_modes : ndarrays of int

    Raises
    ------
    ValueError
        When a matrix, region, the envelope or a list of names does not have the shape the
        others imply (the message names it and the expected shape).
    """

    def __init__(self, A, B, f, C, g, regions, lower, upper, *, output_lags: int | None,
                 input_lags: int | None, affine: bool = False, D=None,
                 input_names: list[str] | None = None, output_names: list[str] | None = None,
                 state_names: list[str] | None = None, padding: float = PADDING,
                 mode_regions=None, dropped_modes=None, source: dict | None = None):
        self.A = _array(A, "A", 3)
        s, n = self.A.shape[0], self.A.shape[1]
        if s == 0:
            raise ValueError("the model has no mode (A has shape "
                             f"{self.A.shape}): every region is empty inside the envelope")
        _check_shape(self.A, (s, n, n), "A", "(modes, states, states)")
        self.B = _array(B, "B", 3)
        r = self.B.shape[2]
        _check_shape(self.B, (s, n, r), "B", "(modes, states, inputs)")
        self.f = _array(f, "f", 2)
        _check_shape(self.f, (s, n), "f", "(modes, states)")
        self.C = _array(C, "C", 3)
        m = self.C.shape[1]
        _check_shape(self.C, (s, m, n), "C", "(modes, outputs, states)")
        self.g = _array(g, "g", 2)
        _check_shape(self.g, (s, m), "g", "(modes, outputs)")
        self.D = np.zeros((s, m, r)) if D is None else _array(D, "D", 3)
        _check_shape(self.D, (s, m, r), "D", "(modes, outputs, inputs)")
        if (output_lags is None) != (input_lags is None):
            raise ValueError("give both output_lags and input_lags (a state of past values) "
                             "or neither (a state of another kind)")
        self.lagged = output_lags is not None
        if self.lagged:
            for name, value in (("output_lags", output_lags), ("input_lags", input_lags)):
                if isinstance(value, bool) or not isinstance(value, int | np.integer) \
                        or value < 0:
                    raise ValueError(f"{name} must be a whole number >= 0, got {value!r}")
            if m * output_lags + r * input_lags != n:
                raise ValueError(
                    f"the state has {n} entries but {m} output(s) × {output_lags} lag(s) + "
                    f"{r} input(s) × {input_lags} lag(s) = "
                    f"{m * output_lags + r * input_lags}")
            if np.any(self.D):
                raise ValueError("a state of past values (output_lags, input_lags) has no "
                                 "feedthrough: D must be zero")
        self.output_lags = None if output_lags is None else int(output_lags)
        self.input_lags = None if input_lags is None else int(input_lags)
        self.affine = bool(affine)
        self.input_names = [f"u{q + 1}" for q in range(r)] if input_names is None \
            else [str(v) for v in input_names]
        self.output_names = [f"y{j + 1}" for j in range(m)] if output_names is None \
            else [str(v) for v in output_names]
        if len(self.input_names) != r:
            raise ValueError(f"input_names has {len(self.input_names)} name(s); B has {r} "
                             f"input column(s)")
        if len(self.output_names) != m:
            raise ValueError(f"output_names has {len(self.output_names)} name(s); C has {m} "
                             f"output row(s)")
        if self.lagged:
            self.state_names = regressor_names(self.output_names, self.input_names,
                                               self.output_lags, self.input_lags, affine=False)
            if state_names is not None and list(state_names) != self.state_names:
                raise ValueError(f"state_names {list(state_names)} do not match the orders "
                                 f"and names, which give {self.state_names}")
        else:
            self.state_names = [f"x{i + 1}" for i in range(n)] if state_names is None \
                else [str(v) for v in state_names]
            if len(self.state_names) != n:
                raise ValueError(f"state_names has {len(self.state_names)} name(s); A has {n} "
                                 f"state(s)")
        if not isinstance(regions, list | tuple) or len(regions) != s:
            raise ValueError(f"regions must be a list of {s} (H, h) pairs, one per mode; got "
                             f"{len(regions) if isinstance(regions, list | tuple) else regions!r}")
        self.regions = []
        for i, pair in enumerate(regions):
            if not isinstance(pair, list | tuple) or len(pair) != 2:
                raise ValueError(f"region {i} must be a pair (H, h)")
            H, h = pair
            if np.size(H) == 0 and np.size(h) == 0:  # a region without rows: all of z
                H, h = np.zeros((0, n + r)), np.zeros(0)
            H, h = _array(H, f"region {i} H", 2), _array(h, f"region {i} h", 1)
            if H.shape[1] != n + r:
                raise ValueError(f"region {i} H has shape {H.shape}; expected (rows, states + "
                                 f"inputs) with states + inputs = {n + r}")
            _check_shape(h, (H.shape[0],), f"region {i} h", "(rows of H,)")
            self.regions.append((H, h))
        lower, upper = _array(lower, "envelope lower", 1), _array(upper, "envelope upper", 1)
        _check_shape(lower, (n + r,), "envelope lower", "(states + inputs,)")
        _check_shape(upper, (n + r,), "envelope upper", "(states + inputs,)")
        if np.any(lower >= upper):
            c = int(np.flatnonzero(lower >= upper)[0])
            raise ValueError(f"the envelope is empty along z[{c}]: lower {lower[c]} >= upper "
                             f"{upper[c]}")
        self.envelope = (lower, upper)
        self.padding = None if padding is None else float(padding)
        self.mode_regions = (np.tile(np.arange(s)[:, None], (1, m)) if mode_regions is None
                             else np.asarray(mode_regions, dtype=int))
        _check_shape(self.mode_regions, (s, m), "mode_regions", "(modes, outputs)")
        self.dropped_modes = (np.empty((0, m), int) if dropped_modes is None
                              or np.size(dropped_modes) == 0
                              else np.asarray(dropped_modes, dtype=int))
        if self.dropped_modes.ndim != 2 or self.dropped_modes.shape[1] != m:
            raise ValueError(f"dropped_modes has shape {self.dropped_modes.shape}; expected "
                             f"(dropped, outputs) with outputs = {m}")
        self.source = dict(source or {})
        self._stack_regions()

    def _stack_regions(self) -> None:
        """All regions' rows in one matrix (a region without rows gets 0·z ≤ 1), for
        [`mode_of`][pwa_pipeline.control.PWAStateSpace.mode_of]."""
        p = self.n_states + self.n_inputs
        rows = [(H, h) if len(h) else (np.zeros((1, p)), np.ones(1)) for H, h in self.regions]
        self._H = np.vstack([H for H, _ in rows])
        self._h = np.concatenate([h for _, h in rows])
        self._starts = np.cumsum([0] + [len(h) for _, h in rows[:-1]])

    # --- sizes and names ----------------------------------------------------------------

    @property
    def n_modes(self) -> int:
        """s, the number of modes (regions non-empty inside the envelope)."""
        return self.A.shape[0]

    @property
    def held(self) -> np.ndarray:
        """Which outputs each mode holds constant (no state or input enters them: y_p =
        g_p), shape (s, m): the modes an output limit adds (`pwa_pipeline.pwa.limits`)."""
        return np.all(self.C == 0, axis=2) & np.all(self.D == 0, axis=2)

    @property
    def n_states(self) -> int:
        """n = m·L + r·nb."""
        return self.A.shape[1]

    @property
    def n_inputs(self) -> int:
        """r."""
        return self.B.shape[2]

    @property
    def n_outputs(self) -> int:
        """m."""
        return self.C.shape[1]

    @property
    def n_initial(self) -> int:
        """Samples before the first state: max(L, nb) (a state of past values only)."""
        self._need_lags("n_initial")
        return n_initial(self.output_lags, self.input_lags)

    def _need_lags(self, what: str) -> None:
        if not self.lagged:
            raise ValueError(f"{what}: this model's state ({', '.join(self.state_names[:3])}"
                             f"{'…' if self.n_states > 3 else ''}) is not made of past outputs "
                             f"and inputs; simulate it from an initial state, "
                             f"simulate(u, x0=...)")

    # --- modes -------------------------------------------------------------------------

    def _z(self, x, u) -> tuple[Float2D, bool]:
        x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        single = x.ndim == 1
        x, u = np.atleast_2d(x), np.atleast_2d(u)
        if x.shape[1] != self.n_states:
            raise ValueError(f"x has {x.shape[1]} entries per row; the state has "
                             f"{self.n_states} ({', '.join(self.state_names)})")
        if u.shape[1] != self.n_inputs:
            raise ValueError(f"u has {u.shape[1]} entries per row; the model has "
                             f"{self.n_inputs} input(s)")
        if x.shape[0] != u.shape[0]:
            raise ValueError(f"x has {x.shape[0]} row(s) and u {u.shape[0]}")
        return np.hstack([x, u]), single

    def in_envelope(self, x, u) -> np.ndarray:
        """Whether each row's z = [x; u] lies in the data envelope (bool, one per row)."""
        z, single = self._z(x, u)
        return self._inside(z)[0] if single else self._inside(z)

    def _inside(self, z: Float2D) -> np.ndarray:
        return ~outside_box(z, *self.envelope, slack=TIE_TOL)

    def _violation(self, z: Float2D) -> Float2D:
        """Largest violation max_k (H_i z − h_i)_k of each region's rows, shape (N, s)."""
        return np.maximum.reduceat(z @ self._H.T - self._h, self._starts, axis=1)

    def mode_of(self, x, u) -> np.ndarray:
        """The mode of each row (x, u): the region P_i that holds z = [x; u].

        Every z in the envelope lies in one region, or on the boundary of several; the tie
        rule is the fitted model's: among the closed regions that hold z (within
        `TIE_TOL` half-widths of the envelope) the lowest-numbered one, as an argmax
        picks the lowest index on ties and a sign test puts 0 with the negative side. (A
        point that rounding leaves in no region takes the least violated one.)

        Parameters
        ----------
        x : array-like of shape (n,) or (N, n)
        u : array-like of shape (r,) or (N, r)

        Returns
        -------
        int or ndarray of int, shape (N,)
            Mode 0 … s−1, or −1 where z is outside the data envelope (or not finite).
        """
        z, single = self._z(x, u)
        mode = self._modes(z)
        return int(mode[0]) if single else mode

    def _modes(self, z: Float2D, nearest: bool = False) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            worst = self._violation(z)
            hit = worst <= TIE_TOL
            mode = np.where(hit.any(axis=1), hit.argmax(axis=1),
                            np.argmin(np.where(np.isnan(worst), np.inf, worst), axis=1))
        if not nearest:
            mode[~self._inside(z)] = -1
        mode[~np.all(np.isfinite(z), axis=1)] = -1
        return mode

    # --- dynamics ----------------------------------------------------------------------

    def step(self, x, u) -> tuple[np.ndarray, np.ndarray]:
        """One step from state x and input u: (x⁺, y) = (A_i x + B_i u + f_i,
        C_i x + D_i u + g_i) with i = [`mode_of`][pwa_pipeline.control.PWAStateSpace.mode_of] (x, u).

        Parameters
        ----------
        x : array-like of shape (n,) or (N, n)
        u : array-like of shape (r,) or (N, r)

        Returns
        -------
        x_next : ndarray of shape (n,) or (N, n)
        y : ndarray of shape (m,) or (N, m)
            The output at the current sample, y(k) = C_i x(k) + D_i u(k) + g_i.

        Raises
        ------
        ValueError
            If a row lies outside the data envelope (its mode is −1).
        """
        z, single = self._z(x, u)
        mode = self._modes(z)
        if np.any(mode < 0):
            bad = np.flatnonzero(mode < 0)
            raise ValueError(f"{bad.size} row(s) (first: {bad[0]}) lie outside the data "
                             f"envelope, where the model has no mode")
        xs, us = z[:, :self.n_states], z[:, self.n_states:]
        x_next = (np.einsum("nij,nj->ni", self.A[mode], xs)
                  + np.einsum("nij,nj->ni", self.B[mode], us) + self.f[mode])
        y = (np.einsum("nij,nj->ni", self.C[mode], xs)
             + np.einsum("nij,nj->ni", self.D[mode], us) + self.g[mode])
        return (x_next[0], y[0]) if single else (x_next, y)

    def _pairs(self, u: Signals, y: Signals) -> list[tuple[Float2D, Float2D]]:
        self._need_lags("states and regressors")
        pairs = as_experiments(u, y)
        for ue, ye in pairs:
            check_width(ue, self.n_inputs, "u", "input(s)")
            check_width(ye, self.n_outputs, "y", "output(s)")
        return pairs

    def states(self, u: Signals, y: Signals) -> Float2D | list[Float2D]:
        """The state x(k) of each sample of measured data, for k = max(L, nb) … N−1.

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays (one per experiment)
        y : array-like of shape (N, m), or a list of such arrays

        Returns
        -------
        ndarray of shape (N − max(L, nb), n), or a list of them
            Row k − max(L, nb) is x(k), aligned with ``u[max(L, nb):]`` (and with
            [`regressors`][pwa_pipeline.control.PWAStateSpace.regressors]).
        """
        pairs = self._pairs(u, y)
        out = [lagged_matrix(ue, ye, self.output_lags, self.input_lags, affine=False)
               for ue, ye in pairs]
        return out if _is_experiment_list(y) else out[0]

    def regressors(self, u: Signals, y: Signals) -> Float2D | list[Float2D]:
        """The fitted model's regressor φ(k) (eq. 2–3) of the same samples as
        [`states`][pwa_pipeline.control.PWAStateSpace.states]: φ(k) = [x(k); 1] for an affine model, x(k)
        otherwise.

        Returns
        -------
        ndarray of shape (N − max(L, nb), n (+1)), or a list of them
        """
        pairs = self._pairs(u, y)
        out = [lagged_matrix(ue, ye, self.output_lags, self.input_lags, self.affine)
               for ue, ye in pairs]
        return out if _is_experiment_list(y) else out[0]

    def simulate(self, u: Signals, y_init: Signals | None = None, outside: str = "raise", *,
                 x0=None) -> Float2D | list[Float2D]:
        """Free-run simulation by the state equations, as the fitted model's ``simulate``.

        The state x(n_init) is built from the warm-up (the last L rows of ``y_init`` and the
        nb inputs before sample n_init), or given (``x0``, at sample 0), then
        x(k+1) = A_i x(k) + B_i u(k) + f_i and y(k) = C_i x(k) + D_i u(k) + g_i with i the
        mode of [x(k); u(k)].

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays
        y_init : array-like of shape (n_init, m) with n_init ≥ max(L, nb), or a list
            Initial outputs (a warm-up window); simulation starts at sample n_init. For a
            state of past values.
        x0 : array-like of shape (n,), or a list of them, optional
            The state at sample 0, in place of ``y_init`` (any model; the only way for a
            state that is not made of past values).
        outside : {"raise", "nearest"}, default "raise"
            When z(k) leaves the data envelope: ``"raise"`` a ValueError naming the sample;
            ``"nearest"`` go on in the region whose rows z violates least (an extrapolation:
            outside the envelope it may differ from the fitted model's own choice).

        Returns
        -------
        ndarray of shape (N, m), or a list of them
            The first n_init rows are ``y_init``. A run that diverges to ±inf or NaN is
            returned as it is (later rows NaN), as the fitted model does.

        Raises
        ------
        ValueError
            If the widths differ from the model's, ``y_init`` has fewer than max(L, nb) rows
            or more rows than u, a value is non-finite, or (``outside="raise"``) the
            trajectory leaves the data envelope.
        """
        if outside not in OUTSIDE:
            raise ValueError(f"outside must be one of {OUTSIDE}, got {outside!r}")
        if (y_init is None) == (x0 is None):
            raise ValueError("give the warm-up outputs y_init or the initial state x0, one "
                             "of them")
        if x0 is None:
            pairs = warmup_pairs(u, y_init, self.n_inputs, self.n_outputs, self.n_initial)
            starts = [(ye.shape[0], self._initial_state(ue, ye, ye.shape[0]))
                      for ue, ye in pairs]
            us = [ue for ue, _ in pairs]
        else:
            us = [as_signal(ue, "u") for ue in (u if _is_experiment_list(u) else [u])]
            states = list(x0) if _is_experiment_list(u) else [x0]
            if len(states) != len(us):
                raise ValueError(f"u has {len(us)} experiment(s) but x0 {len(states)}")
            starts = []
            for ue, x in zip(us, states, strict=True):
                check_width(ue, self.n_inputs, "u", "input(s)")
                x = np.asarray(x, dtype=float)
                if x.shape != (self.n_states,) or not np.all(np.isfinite(x)):
                    raise ValueError(f"x0 must hold {self.n_states} finite value(s) "
                                     f"({', '.join(self.state_names)}), got shape {x.shape}")
                starts.append((0, x))
        out = []
        for i, (ue, (k0, x)) in enumerate(zip(us, starts, strict=True)):
            y = self._free_run(ue, x, k0, outside, i)
            if x0 is None:
                y[:k0] = pairs[i][1]
            out.append(y)
        return out if _is_experiment_list(u) else out[0]

    def _initial_state(self, u: Float2D, y: Float2D, k: int) -> np.ndarray:
        L, nb = self.output_lags, self.input_lags
        return np.concatenate([y[k - L:k][::-1].T.ravel(), u[k - nb:k][::-1].T.ravel()])

    def _free_run(self, u: Float2D, x: np.ndarray, n_init: int, outside: str,
                  experiment: int) -> Float2D:
        """The outputs from sample ``n_init`` on, from the state x there (rows before it
        left for the caller)."""
        N = u.shape[0]
        y = np.empty((N, self.n_outputs))
        if n_init == N:
            return y
        nearest = outside == "nearest"
        with np.errstate(over="ignore", invalid="ignore"):
            for k in range(n_init, N):
                if not np.all(np.isfinite(x)):
                    y[k:] = np.nan
                    break
                z = np.concatenate([x, u[k]])[None, :]
                i = int(self._modes(z, nearest)[0])
                if i < 0:
                    lower, upper = self.envelope
                    c = int(np.argmax(np.maximum(lower - z[0], z[0] - upper)
                                      / (upper - lower)))
                    names = self.state_names + self.input_names
                    raise ValueError(
                        f"the simulation leaves the data envelope at sample {k} "
                        f"(experiment {experiment}): {names[c]} = {z[0, c]:.6g} is outside "
                        f"[{lower[c]:.6g}, {upper[c]:.6g}]; the model is not defined there "
                        f"(outside='nearest' extrapolates)")
                y[k] = self.C[i] @ x + self.D[i] @ u[k] + self.g[i]
                x = self.A[i] @ x + self.B[i] @ u[k] + self.f[i]
        return y

    # --- stability ---------------------------------------------------------------------

    def stability(self, **options):
        """The stability report of the modes' linear parts
        ([`stability_report`][pwa_pipeline.control.stability_report]; ``options`` are its
        keyword arguments)."""
        from .stability import stability_report

        return stability_report(self, **options)

    # --- export ------------------------------------------------------------------------

    def to_dict(self) -> dict:
        """The JSON document of [`to_json`][pwa_pipeline.control.PWAStateSpace.to_json] as Python objects
        (`to_document`)."""
        return to_document(self)

    def to_json(self, path: str | Path | None = None) -> str:
        """The model as a versioned JSON document (`json_format`, whose schema it
        documents), also written to ``path`` when given."""
        return write_json(self, path)

    @classmethod
    def from_json(cls, source: str | Path) -> "PWAStateSpace":
        """Read a model written by [`to_json`][pwa_pipeline.control.PWAStateSpace.to_json] (`read_json`): the
        JSON text or the path of a file holding it.

        Raises
        ------
        ValueError
            If the document is not JSON or not an object, is of another schema or version,
            lacks a field, a field is not of its JSON type or does not have the shape the
            others imply, a region is empty or overlaps another inside the envelope, or the
            regions leave a point of it uncovered (the message names the field or the point).
        """
        return read_json(source, cls)

    def to_mpt3(self, path: str | Path | None = None, Ts: float | None = None) -> str:
        """A MATLAB script that builds the model as an MPT3 ``PWASystem`` named ``pwa``
        (`mpt3_script`, whose parameters these are)."""
        return mpt3_script(self, path, Ts)

    def __repr__(self) -> str:
        return (f"PWAStateSpace(modes={self.n_modes}, states={self.n_states}, "
                f"inputs={self.n_inputs}, outputs={self.n_outputs})")
