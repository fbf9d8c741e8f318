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
slightly padded (:mod:`~pwa_pipeline.control.conversion`); outside it the model is an
extrapolation and :meth:`PWAStateSpace.mode_of` says so (−1).
"""

import json
from pathlib import Path

import numpy as np

from .._typing import Float2D, Signals
from .._validation import _is_experiment_list, as_experiments, check_width, warmup_pairs
from ..envelope import PADDING, outside_box
from ..regressors import lagged_matrix, n_initial, regressor_names

#: Identifies the JSON document of :meth:`PWAStateSpace.to_json`.
SCHEMA = "pwa-pipeline/pwa-state-space"

#: The version of that document this code writes and reads.
SCHEMA_VERSION = 1

#: Distance (in half-widths of the envelope, along a region row's unit normal) within which a
#: point counts as on a region's boundary: such a point lies in several closed regions and
#: takes the lowest-numbered one (the tie rule of :meth:`PWAStateSpace.mode_of`).
TIE_TOL = 1e-9

#: What :meth:`PWAStateSpace.simulate` does when the trajectory leaves the envelope.
OUTSIDE = ("raise", "nearest")


def _array(value, name: str, ndim: int) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
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
    """A discrete-time PWA state-space model x⁺ = A_i x + B_i u + f_i, y = C_i x + g_i, valid
    where z = [x; u] ∈ P_i = {z : H_i z ≤ h_i} (see the module doc).

    Built by :func:`~pwa_pipeline.control.to_state_space` (``model.to_state_space()``) or
    read by :meth:`from_json`. The state is the non-minimal one of eq. (2)–(3): the last L
    outputs and nb inputs, so :meth:`simulate` from a warm-up of measured outputs gives the
    fitted model's simulation.

    Parameters
    ----------
    A, B, f, C, g : array-like
        Shapes (s, n, n), (s, n, r), (s, n), (s, m, n), (s, m).
    regions : list of (H, h)
        One pair per mode, H of shape (k_i, n + r) and h of shape (k_i,).
    lower, upper : array-like of shape (n + r,)
        The data envelope, lower < upper.
    output_lags, input_lags : int
        L and nb: the state holds y(k−1) … y(k−L) of each output, then u(k−1) … u(k−nb) of
        each input, n = m·L + r·nb.
    affine : bool, default False
        φ ends in the constant 1 (eq. 2), for :meth:`regressors`.
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
        What the model was converted from (class, orders, form, route), for the record.

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

    def __init__(self, A, B, f, C, g, regions, lower, upper, *, output_lags: int,
                 input_lags: int, affine: bool = False, input_names: list[str] | None = None,
                 output_names: list[str] | None = None, padding: float = PADDING,
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
        for name, value in (("output_lags", output_lags), ("input_lags", input_lags)):
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
                raise ValueError(f"{name} must be a whole number >= 0, got {value!r}")
        self.output_lags, self.input_lags = int(output_lags), int(input_lags)
        if m * self.output_lags + r * self.input_lags != n:
            raise ValueError(
                f"the state has {n} entries but {m} output(s) × {self.output_lags} lag(s) + "
                f"{r} input(s) × {self.input_lags} lag(s) = "
                f"{m * self.output_lags + r * self.input_lags}")
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
        :meth:`mode_of`."""
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
        """Samples before the first state: max(L, nb)."""
        return n_initial(self.output_lags, self.input_lags)

    @property
    def state_names(self) -> list[str]:
        """Names of the state's entries in order, e.g. ``y1(k-1)``, ``u2(k-2)``."""
        return regressor_names(self.output_names, self.input_names, self.output_lags,
                               self.input_lags, affine=False)

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
        :data:`TIE_TOL` half-widths of the envelope) the lowest-numbered one, as an argmax
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
        """One step from state x and input u: (x⁺, y) = (A_i x + B_i u + f_i, C_i x + g_i)
        with i = :meth:`mode_of` (x, u).

        Parameters
        ----------
        x : array-like of shape (n,) or (N, n)
        u : array-like of shape (r,) or (N, r)

        Returns
        -------
        x_next : ndarray of shape (n,) or (N, n)
        y : ndarray of shape (m,) or (N, m)
            The output at the current sample, y(k) = C_i x(k) + g_i.

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
        y = np.einsum("nij,nj->ni", self.C[mode], xs) + self.g[mode]
        return (x_next[0], y[0]) if single else (x_next, y)

    def _pairs(self, u: Signals, y: Signals) -> list[tuple[Float2D, Float2D]]:
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
            :meth:`regressors`).
        """
        pairs = self._pairs(u, y)
        out = [lagged_matrix(ue, ye, self.output_lags, self.input_lags, affine=False)
               for ue, ye in pairs]
        return out if _is_experiment_list(y) else out[0]

    def regressors(self, u: Signals, y: Signals) -> Float2D | list[Float2D]:
        """The fitted model's regressor φ(k) (eq. 2–3) of the same samples as
        :meth:`states`: φ(k) = [x(k); 1] for an affine model, x(k) otherwise.

        Returns
        -------
        ndarray of shape (N − max(L, nb), n (+1)), or a list of them
        """
        pairs = self._pairs(u, y)
        out = [lagged_matrix(ue, ye, self.output_lags, self.input_lags, self.affine)
               for ue, ye in pairs]
        return out if _is_experiment_list(y) else out[0]

    def simulate(self, u: Signals, y_init: Signals, outside: str = "raise"
                 ) -> Float2D | list[Float2D]:
        """Free-run simulation by the state equations, as the fitted model's ``simulate``.

        The state x(n_init) is built from the warm-up (the last L rows of ``y_init`` and the
        nb inputs before sample n_init), then x(k+1) = A_i x(k) + B_i u(k) + f_i and
        y(k) = C_i x(k) + g_i with i the mode of [x(k); u(k)].

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays
        y_init : array-like of shape (n_init, m) with n_init ≥ max(L, nb), or a list
            Initial outputs (a warm-up window); simulation starts at sample n_init.
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
        pairs = warmup_pairs(u, y_init, self.n_inputs, self.n_outputs, self.n_initial)
        out = [self._free_run(ue, ye, outside, i) for i, (ue, ye) in enumerate(pairs)]
        return out if _is_experiment_list(u) else out[0]

    def _initial_state(self, u: Float2D, y: Float2D, k: int) -> np.ndarray:
        L, nb = self.output_lags, self.input_lags
        return np.concatenate([y[k - L:k][::-1].T.ravel(), u[k - nb:k][::-1].T.ravel()])

    def _free_run(self, u: Float2D, y_init: Float2D, outside: str, experiment: int) -> Float2D:
        n_init, N = y_init.shape[0], u.shape[0]
        y = np.empty((N, self.n_outputs))
        y[:n_init] = y_init
        if n_init == N:
            return y
        x = self._initial_state(u, y_init, n_init)
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
                y[k] = self.C[i] @ x + self.g[i]
                x = self.A[i] @ x + self.B[i] @ u[k] + self.f[i]
        return y

    # --- stability ---------------------------------------------------------------------

    def stability(self, **options):
        """The stability report of the modes' linear parts
        (:func:`~pwa_pipeline.control.stability.stability_report`; ``options`` are its
        keyword arguments)."""
        from .stability import stability_report

        return stability_report(self, **options)

    # --- export ------------------------------------------------------------------------

    def to_dict(self) -> dict:
        """The JSON document of :meth:`to_json` as Python objects."""
        lower, upper = self.envelope
        return {
            "schema": SCHEMA,
            "schema_version": SCHEMA_VERSION,
            "n_modes": self.n_modes, "n_states": self.n_states, "n_inputs": self.n_inputs,
            "n_outputs": self.n_outputs,
            "output_lags": self.output_lags, "input_lags": self.input_lags,
            "affine": self.affine,
            "state_names": self.state_names, "input_names": self.input_names,
            "output_names": self.output_names,
            "A": self.A.tolist(), "B": self.B.tolist(), "f": self.f.tolist(),
            "C": self.C.tolist(), "g": self.g.tolist(),
            "regions": [{"H": H.tolist(), "h": h.tolist()} for H, h in self.regions],
            "envelope": {"lower": lower.tolist(), "upper": upper.tolist(),
                         "padding": self.padding},
            "mode_regions": self.mode_regions.tolist(),
            "dropped_modes": self.dropped_modes.tolist(),
            "source": self.source,
        }

    def to_json(self, path: str | Path | None = None) -> str:
        """The model as a JSON document (schema :data:`SCHEMA`, version
        :data:`SCHEMA_VERSION`).

        The document is an object with

        - ``schema`` (``"pwa-pipeline/pwa-state-space"``) and ``schema_version`` (1);
        - ``n_modes`` s, ``n_states`` n, ``n_inputs`` r, ``n_outputs`` m, ``output_lags`` L,
          ``input_lags`` nb, ``affine``;
        - ``state_names`` (n), ``input_names`` (r), ``output_names`` (m);
        - ``A`` (s × n × n), ``B`` (s × n × r), ``f`` (s × n), ``C`` (s × m × n), ``g``
          (s × m), nested lists in row-major order;
        - ``regions``: s objects ``{"H": k_i × (n + r), "h": k_i}``, P_i = {z : H z ≤ h}
          over z = [x; u];
        - ``envelope``: ``{"lower": n + r, "upper": n + r, "padding": share}``;
        - ``mode_regions`` (s × m) and ``dropped_modes`` (k × m): each mode's, and each
          dropped combination's, region of every output's sub-model in the fitted model;
        - ``source``: what the model was converted from (for the record).

        Numbers are written with 17 significant digits, so a round trip is exact.

        Parameters
        ----------
        path : str or Path, optional
            Also write the document there.

        Returns
        -------
        str
        """
        text = json.dumps(self.to_dict(), indent=1)
        if path is not None:
            Path(path).write_text(text)
        return text

    @classmethod
    def from_json(cls, source: str | Path) -> "PWAStateSpace":
        """Read a model written by :meth:`to_json`.

        Parameters
        ----------
        source : str or Path
            The JSON text, or the path of a file holding it.

        Raises
        ------
        ValueError
            If the document is not JSON, is of another schema or schema version, lacks a
            field, or a field does not have the shape the others imply (the message names
            the field).
        """
        if isinstance(source, Path) or not str(source).lstrip().startswith("{"):
            source = Path(source).read_text()
        try:
            doc = json.loads(source)
        except json.JSONDecodeError as exc:
            raise ValueError(f"not a JSON document: {exc}") from None
        if not isinstance(doc, dict):
            raise ValueError("the JSON document must be an object")
        if doc.get("schema") != SCHEMA:
            raise ValueError(f"not a PWA state-space document: schema is "
                             f"{doc.get('schema')!r}, expected {SCHEMA!r}")
        if doc.get("schema_version") != SCHEMA_VERSION:
            raise ValueError(f"schema version {doc.get('schema_version')!r} is not supported: "
                             f"this version of pwa-pipeline reads version {SCHEMA_VERSION}")
        required = ("A", "B", "f", "C", "g", "regions", "envelope", "output_lags",
                    "input_lags")
        missing = [k for k in required if k not in doc]
        if missing:
            raise ValueError(f"the document lacks field(s) {missing}")
        envelope = doc["envelope"]
        if not isinstance(envelope, dict) or not {"lower", "upper"} <= set(envelope):
            raise ValueError("envelope must be an object with 'lower' and 'upper'")
        regions = doc["regions"]
        if not isinstance(regions, list) or not all(
                isinstance(r, dict) and {"H", "h"} <= set(r) for r in regions):
            raise ValueError("regions must be a list of objects with 'H' and 'h'")
        ss = cls(doc["A"], doc["B"], doc["f"], doc["C"], doc["g"],
                 [(r["H"], r["h"]) for r in regions], envelope["lower"], envelope["upper"],
                 output_lags=doc["output_lags"], input_lags=doc["input_lags"],
                 affine=doc.get("affine", False), input_names=doc.get("input_names"),
                 output_names=doc.get("output_names"),
                 padding=envelope.get("padding"),
                 mode_regions=doc.get("mode_regions"), dropped_modes=doc.get("dropped_modes"),
                 source=doc.get("source"))
        for key, expected in (("n_modes", ss.n_modes), ("n_states", ss.n_states),
                              ("n_inputs", ss.n_inputs), ("n_outputs", ss.n_outputs)):
            if key in doc and doc[key] != expected:
                raise ValueError(f"{key} is {doc[key]!r} but the matrices give {expected}")
        if "state_names" in doc and doc["state_names"] != ss.state_names:
            raise ValueError(f"state_names {doc['state_names']} do not match the orders and "
                             f"names, which give {ss.state_names}")
        return ss

    def to_mpt3(self, path: str | Path | None = None, Ts: float = 1.0) -> str:
        """A MATLAB script that builds the model as an MPT3 ``PWASystem`` named ``pwa``.

        Each mode becomes ``LTISystem('A', A, 'B', B, 'C', C, 'D', D, 'f', f, 'g', g,
        'Ts', Ts)`` (D = 0) with its domain set by ``setDomain('xu', Polyhedron('A', H,
        'b', h))`` over (x, u), and ``pwa = PWASystem([sys1, …, sysS])`` joins them, as
        MPT3's documentation of ``PWASystem`` builds a PWA system. The envelope is stored as
        ``z_min`` and ``z_max``. Numbers are written with 17 significant digits.

        Parameters
        ----------
        path : str or Path, optional
            Also write the script there (e.g. ``model_pwa.m``).
        Ts : float, default 1
            Sampling time (the model counts samples).

        Returns
        -------
        str
        """
        def mat(a: np.ndarray) -> str:
            a = np.atleast_2d(a)
            if a.size == 0:
                return f"zeros({a.shape[0]}, {a.shape[1]})"
            return "[" + "; ".join(" ".join(f"{v:.17g}" for v in row) for row in a) + "]"

        lower, upper = self.envelope
        source = ", ".join(f"{k}={v}" for k, v in self.source.items())
        lines = [
            "% PWA state-space model exported by pwa-pipeline (pwa_pipeline.control)"
            + (f": {source}" if source else ""),
            "%   x(k+1) = A_i x(k) + B_i u(k) + f_i,  y(k) = C_i x(k) + g_i,",
            "%   valid where [x(k); u(k)] lies in {z : H_i z <= h_i}.",
            f"% states x: {', '.join(self.state_names)}",
            f"% inputs u: {', '.join(self.input_names)}",
            f"% outputs y: {', '.join(self.output_names)}",
            f"% {self.n_modes} mode(s); the regions are bounded by the data envelope "
            f"z_min <= [x; u] <= z_max.",
            f"Ts = {Ts:.17g};",
            f"z_min = {mat(lower[:, None])};",
            f"z_max = {mat(upper[:, None])};",
        ]
        D = np.zeros((self.n_outputs, self.n_inputs))
        for i in range(self.n_modes):
            H, h = self.regions[i]
            k = i + 1
            lines += [
                f"% mode {k} (regions of the fitted model: {self.mode_regions[i].tolist()})",
                f"A{k} = {mat(self.A[i])};",
                f"B{k} = {mat(self.B[i])};",
                f"f{k} = {mat(self.f[i][:, None])};",
                f"C{k} = {mat(self.C[i])};",
                f"D{k} = {mat(D)};",
                f"g{k} = {mat(self.g[i][:, None])};",
                f"H{k} = {mat(H) if len(h) else f'zeros(0, {H.shape[1]})'};",
                f"h{k} = {mat(h[:, None]) if len(h) else 'zeros(0, 1)'};",
                f"sys{k} = LTISystem('A', A{k}, 'B', B{k}, 'C', C{k}, 'D', D{k}, "
                f"'f', f{k}, 'g', g{k}, 'Ts', Ts);",
                f"sys{k}.setDomain('xu', Polyhedron('A', H{k}, 'b', h{k}));",
            ]
        lines.append("pwa = PWASystem([" + ", ".join(f"sys{i + 1}" for i in range(self.n_modes))
                     + "]);")
        text = "\n".join(lines) + "\n"
        if path is not None:
            Path(path).write_text(text)
        return text

    def __repr__(self) -> str:
        return (f"PWAStateSpace(modes={self.n_modes}, states={self.n_states}, "
                f"inputs={self.n_inputs}, outputs={self.n_outputs})")
