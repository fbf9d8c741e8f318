"""What every ARX-structured model shares (PWA and linear): one fitted shape, prediction,
simulation, scoring, the data envelope and the state-space form."""

from typing import overload

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from .._typing import Float2D, Signals
from .._validation import (
    _is_experiment_list,
    as_experiments,
    as_signal,
    check_n_init,
    check_width,
    warmup_pairs,
)
from ..control.conversion import to_state_space
from ..control.state_space import PWAStateSpace
from ..envelope import PADDING, outside_box, regressor_bounds
from ..regressors import lagged_matrix, n_initial
from ..scoring.metrics import r2_score
from .groups import modes, predict_groups
from .partitions import RegionMap
from .structures import output_lags


class ARXModelBase(BaseEstimator):
    """Base class for models y(k) = f(φ(k)) with φ(k) from eq. (2)–(3).

    Subclasses take ``na``, ``nb``, ``affine`` and ``form`` as parameters and set at fit
    the one fitted shape every model shares: ``groups_``, a list of
    [`OutputGroup`][pwa_pipeline.pwa.OutputGroup] (outputs that switch together, their region map and
    sub-models), with ``n_inputs_``, ``n_outputs_``, ``structures_`` (each output's structure
    in words), ``signal_range_`` (the training range, for the data envelope) and
    ``timings_`` (seconds per stage of the fit). φ holds `output_lags_` output lags:
    na, or na + 1 in the velocity form (`structures`).

    From the groups every model has, whatever fitted it: `thetas_`, `regions_`
    and `n_submodels_` (the model as eq. 1), `predict`, `simulate`,
    `score` and `to_state_space`.

    **Data envelope.** A model is known only where its training regressors went.
    `outside_envelope` says, per sample, whether φ(k) leaves the box of the training
    range padded by `PADDING` (`pwa_pipeline.envelope`);
    outside it the model extrapolates (its numbers are not clipped).

    **Return types.** ``predict`` and ``simulate`` take one experiment (arrays) or several
    (lists of arrays) and answer in kind: an ndarray of shape (N, m) for one experiment, a
    list of them, one per experiment, for a list.
    """

    @property
    def output_lags_(self) -> int:
        """Output lags of φ: na, or na + 1 with ``form="velocity"``."""
        return output_lags(self.na, self.form)

    @property
    def n_initial_(self) -> int:
        """Samples needed before the first prediction: max(output lags, nb)."""
        return n_initial(self.output_lags_, self.nb)

    @property
    def regions_(self) -> RegionMap:
        """The region map of the model as eq. (1) (`modes`): the group's own
        map for a model of one output group, else the product of the groups' maps (one
        region per combination of the groups' regions). ``regions_.predict(phi)`` gives the
        sub-model of each row of φ."""
        check_is_fitted(self)
        return modes(self.groups_, self.n_outputs_)[0]

    @property
    def thetas_(self) -> np.ndarray:
        """θ_i of eq. (1), shape (s, D, m): each sub-model's parameter matrix over φ (for
        several output groups, one per combination of their regions)."""
        check_is_fitted(self)
        return modes(self.groups_, self.n_outputs_)[1]

    @property
    def steps_(self) -> dict:
        """The fitted steps that found the regions and sub-models, by name (``local_models``,
        ``clustering``, ``submodels``, ``regions``, ``refinement``): those of the first output
        group that ran any (``groups_[g].steps`` has each group's); empty when none ran."""
        check_is_fitted(self)
        return next((g.steps for g in self.groups_ if g.steps), {})

    @property
    def n_submodels_(self) -> int:
        """s, the sub-models of eq. (1): the product of the groups' region counts."""
        check_is_fitted(self)
        return int(np.prod([g.n_regions for g in self.groups_]))

    def _predict_phi(self, phi: Float2D) -> Float2D:
        """y(k) for each row φ(k); shape (n, m)."""
        return predict_groups(self.groups_, phi, self.n_outputs_)

    def _experiments(self, u: Signals, y: Signals, y_name: str):
        check_is_fitted(self)
        pairs = as_experiments(u, y, y_name=y_name)
        for ue, ye in pairs:
            check_width(ue, self.n_inputs_, "u", "input(s)")
            check_width(ye, self.n_outputs_, y_name, "output(s)")
        return pairs

    @overload
    def predict(self, u: Float2D, y: Float2D, n_init: int | None = None) -> Float2D: ...

    @overload
    def predict(self, u: list[Float2D], y: list[Float2D], n_init: int | None = None
                ) -> list[Float2D]: ...

    def predict(self, u: Signals, y: Signals, n_init: int | None = None
                ) -> Float2D | list[Float2D]:
        """One-step-ahead prediction ŷ(k) = f(φ(k)) from measured past outputs.

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays (one per experiment)
        y : array-like of shape (N, m), or a list of such arrays
            Measured outputs; only their past values enter φ(k).
        n_init : int, optional
            Rows returned as given (a warm-up window); at least and by default
            max(output lags, nb). From 0 to below each experiment's length.

        Returns
        -------
        ndarray of shape (N, m) for one experiment; a list of them for a list
            The first ``n_init`` rows are the given y; the rest are predictions.
        """
        pairs = self._experiments(u, y, "y")
        n0 = self.n_initial_
        keep = n0 if n_init is None else max(n_init, n0)
        out = []
        for ue, ye in pairs:
            check_n_init(n_init, ye.shape[0])
            yhat = ye.copy()
            if ye.shape[0] > n0:
                phi = lagged_matrix(ue, ye, self.output_lags_, self.nb, self.affine)
                yhat[n0:] = self._predict_phi(phi)
                yhat[:keep] = ye[:keep]
            out.append(yhat)
        return out if _is_experiment_list(y) else out[0]

    @overload
    def simulate(self, u: Float2D, y_init: Float2D) -> Float2D: ...

    @overload
    def simulate(self, u: list[Float2D], y_init: list[Float2D]) -> list[Float2D]: ...

    def simulate(self, u: Signals, y_init: Signals) -> Float2D | list[Float2D]:
        """Free-run simulation: φ(k) is built from the model's own past outputs.

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays
        y_init : array-like of shape (n_init, m) with n_init ≥ max(output lags, nb), or a
            list
            Initial outputs (a warm-up window); simulation starts at sample n_init.

        Returns
        -------
        ndarray of shape (N, m) for one experiment; a list of them for a list
            The first n_init rows are ``y_init``. A run that diverges to ±inf or NaN is
            returned as it is (later rows non-finite), not raised.

        Raises
        ------
        ValueError
            If the input width differs from the fitted one, ``y_init`` has fewer than
            max(output lags, nb) rows or more rows than u, or any value is non-finite.
        """
        check_is_fitted(self)
        pairs = warmup_pairs(u, y_init, self.n_inputs_, self.n_outputs_, self.n_initial_)
        out = [self._free_run(ue, ye) for ue, ye in pairs]
        return out if _is_experiment_list(u) else out[0]

    def to_state_space(self, u: Signals | None = None, y: Signals | None = None, *,
                       padding: float = PADDING, input_names: list[str] | None = None,
                       output_names: list[str] | None = None) -> PWAStateSpace:
        """The model as a PWA state-space model x⁺ = A_i x + B_i u + f_i, y = C_i x + g_i on
        polyhedral regions of z = [x; u]
        ([`pwa_pipeline.control.to_state_space`][pwa_pipeline.control.to_state_space], whose parameters these
        are): its output groups' regions made explicit inside the data envelope (``signal_range_``, or the
        range of ``u`` and ``y`` when given, widened by ``padding``).
        """
        return to_state_space(self, u, y, padding=padding, input_names=input_names,
                              output_names=output_names)

    def envelope(self, padding: float = PADDING) -> tuple[np.ndarray, np.ndarray]:
        """The data envelope over φ(k) without the constant
        (`regressor_bounds`): each entry's channel's training range widened
        by ``padding`` of its span.

        Parameters
        ----------
        padding : float, default PADDING (5 %)

        Returns
        -------
        lower, upper : ndarrays of shape (m·L + r·nb,)
            In φ's order (eq. 3; L = `output_lags_`).

        Raises
        ------
        ValueError
            If the model records no training range (``signal_range_``).
        """
        check_is_fitted(self)
        rng = getattr(self, "signal_range_", None)
        if rng is None:
            raise ValueError(
                f"this {type(self).__name__} does not record the range of its training data "
                f"(signal_range_), so it has no data envelope: fit it again")
        return regressor_bounds(rng, self.n_outputs_, self.n_inputs_, self.output_lags_,
                                self.nb, padding)

    def outside_envelope(self, u: Signals, y: Signals, padding: float = PADDING
                         ) -> np.ndarray | list[np.ndarray]:
        """Whether each sample's regressor φ(k), built from ``u`` and ``y``, leaves the data
        envelope (`envelope`): where the model is used outside its training data.

        Pass measured outputs for the samples of a one-step prediction, or the outputs a
        free run returned (``simulate``'s result, warm-up included) for the samples of that
        run: φ(k) is built from y's rows before k either way.

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays (one per experiment)
        y : array-like of shape (N, m), or a list of such arrays
            May hold NaN or inf (a diverged simulation): a φ(k) with such an entry is
            outside.
        padding : float, default PADDING (5 %)

        Returns
        -------
        ndarray of bool, shape (N,), or a list of them
            True where φ(k) leaves the envelope; False on the first max(output lags, nb)
            rows, which have no regressor.

        Raises
        ------
        ValueError
            If the model records no training range, or the signals' shapes do not match the
            model's or each other.
        """
        lower, upper = self.envelope(padding)
        u_list = list(u) if _is_experiment_list(u) else [u]
        y_list = list(y) if _is_experiment_list(y) else [y]
        if len(u_list) != len(y_list):
            raise ValueError(f"u has {len(u_list)} experiment(s) but y has {len(y_list)}")
        flags = []
        for i, (ue, ye) in enumerate(zip(u_list, y_list, strict=True)):
            ue = as_signal(ue, "u")
            ye = np.asarray(ye, dtype=float)
            ye = ye[:, None] if ye.ndim == 1 else ye
            if ye.ndim != 2:
                raise ValueError(f"y must be 2-D with shape (n_samples, n_outputs), got "
                                 f"shape {ye.shape}")
            check_width(ue, self.n_inputs_, "u", "input(s)")
            check_width(ye, self.n_outputs_, "y", "output(s)")
            if ue.shape[0] != ye.shape[0]:
                raise ValueError(f"u and y have different lengths: {ue.shape[0]} and "
                                 f"{ye.shape[0]} samples (experiment {i})")
            flags.append(self._outside(ue, ye, lower, upper))
        return flags if _is_experiment_list(y) else flags[0]

    def _outside(self, u: Float2D, y: Float2D, lower: np.ndarray, upper: np.ndarray
                 ) -> np.ndarray:
        """The flags of `outside_envelope` of one experiment, shape (N,)."""
        n0, n = self.n_initial_, y.shape[0]
        flag = np.zeros(n, bool)
        if n > n0:
            flag[n0:] = outside_box(lagged_matrix(u, y, self.output_lags_, self.nb, False),
                                    lower, upper)
        return flag

    def _free_run(self, u: Float2D, y_init: Float2D) -> Float2D:
        na, nb = self.output_lags_, self.nb
        n_init, n = y_init.shape[0], u.shape[0]
        y = np.empty((n, self.n_outputs_))
        y[:n_init] = y_init
        tail = [1.0] if self.affine else []
        with np.errstate(over="ignore", invalid="ignore"):
            for k in range(n_init, n):
                phi = np.concatenate(
                    [y[k - na : k][::-1].T.ravel(), u[k - nb : k][::-1].T.ravel(), tail]
                )
                y[k] = self._predict_phi(phi[None, :])[0]
                if not np.all(np.isfinite(y[k])):
                    y[k + 1 :] = np.nan
                    break
        return y

    def score(self, u: Signals, y: Signals) -> float:
        """Mean R² (eq. 22, standard form) of the one-step-ahead prediction over outputs."""
        pairs = self._experiments(u, y, "y")
        yhat = self.predict([p[0] for p in pairs], [p[1] for p in pairs])
        n0 = self.n_initial_
        y_true = np.vstack([p[1][n0:] for p in pairs])
        y_pred = np.vstack([p[n0:] for p in yhat])
        return float(np.mean(r2_score(y_true, y_pred)))

