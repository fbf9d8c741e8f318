"""Shared prediction, simulation and scoring of ARX-structured models (PWA and linear)."""

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
from ..envelope import PADDING, outside_box, regressor_bounds
from ..regressors import lagged_matrix, n_initial
from ..scoring.metrics import r2_score
from .structures import output_lags


def training_range(experiments: list[tuple[Float2D, Float2D]]) -> Float2D:
    """Smallest and largest value of each output, then each input, over the experiments.

    Parameters
    ----------
    experiments : list of (u, y)
        As :func:`~pwa_pipeline._validation.as_experiments` returns them.

    Returns
    -------
    ndarray of shape (2, m + r)
        Row 0 the minima, row 1 the maxima: the estimators keep it as ``signal_range_``,
        the data envelope of their state-space form (:mod:`pwa_pipeline.control`).
    """
    joined = np.vstack([np.hstack([y, u]) for u, y in experiments])
    return np.vstack([joined.min(axis=0), joined.max(axis=0)])


class ARXModelBase(BaseEstimator):
    """Base class for models y(k) = f(φ(k)) with φ(k) from eq. (2)–(3).

    Subclasses set ``na``, ``nb``, ``affine``, ``form`` and ``outputs`` as parameters, the fitted
    ``n_inputs_`` and ``n_outputs_`` (and ``signal_range_``, the training range, for the data
    envelope), and implement :meth:`_predict_phi`. φ holds :attr:`output_lags_` output lags:
    na, or na + 1 in the velocity form (:mod:`~.structures`).

    **Data envelope.** A model is known only where its training regressors went.
    :meth:`outside_envelope` says, per sample, whether φ(k) leaves the box of the training
    range padded by :data:`~.envelope.PADDING` (:mod:`~.envelope`); ``predict`` and
    ``simulate`` return the same flags next to their numbers with ``return_outside=True``
    (the numbers are the same either way: outside the envelope the model extrapolates, it
    is not clipped).
    """

    @property
    def structured(self) -> bool:
        """Whether the fit takes the structured route of :mod:`~.structure_fit` (velocity
        form or decoupled outputs)."""
        return self.form != "level" or self.outputs != "joint"

    @property
    def output_lags_(self) -> int:
        """Output lags of φ: na, or na + 1 with ``form="velocity"``."""
        return output_lags(self.na, self.form)

    def _predict_phi(self, phi: Float2D) -> Float2D:
        """y(k) for each row φ(k); shape (n, m)."""
        raise NotImplementedError

    @property
    def n_initial_(self) -> int:
        """Samples needed before the first prediction: max(output lags, nb)."""
        return n_initial(self.output_lags_, self.nb)

    def _experiments(self, u: Signals, y: Signals, y_name: str):
        check_is_fitted(self)
        pairs = as_experiments(u, y, y_name=y_name)
        for ue, ye in pairs:
            check_width(ue, self.n_inputs_, "u", "input(s)")
            check_width(ye, self.n_outputs_, y_name, "output(s)")
        return pairs

    def predict(
        self, u: Signals, y: Signals, n_init: int | None = None, *,
        return_outside: bool = False,
    ) -> Float2D | list[Float2D] | tuple:
        """One-step-ahead prediction ŷ(k) = f(φ(k)) from measured past outputs.

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays (one per experiment)
        y : array-like of shape (N, m), or a list of such arrays
            Measured outputs; only their past values enter φ(k).
        n_init : int, optional
            Rows returned as given (a warm-up window); at least and by default
            max(output lags, nb). From 0 to below each experiment's length.
        return_outside : bool, default False
            Also return, per sample, whether the prediction's regressor φ(k) (the measured
            past outputs and the past inputs) leaves the data envelope
            (:meth:`outside_envelope`); the predictions are the same either way.

        Returns
        -------
        ndarray of shape (N, m), or a list of them
            The first ``n_init`` rows are the given y; the rest are predictions.
        outside : ndarray of bool, shape (N,), or a list of them (``return_outside`` only)
            True where φ(k) leaves the envelope; False on the rows returned as given.

        Raises
        ------
        ValueError
            With ``return_outside=True``, if the model records no training range
            (``signal_range_``).
        """
        pairs = self._experiments(u, y, "y")
        n0 = self.n_initial_
        keep = n0 if n_init is None else max(n_init, n0)
        if return_outside:
            lower, upper = self.envelope()
        out, flags = [], []
        for ue, ye in pairs:
            check_n_init(n_init, ye.shape[0])
            yhat = ye.copy()
            if ye.shape[0] > n0:
                phi = lagged_matrix(ue, ye, self.output_lags_, self.nb, self.affine)
                yhat[n0:] = self._predict_phi(phi)
                yhat[:keep] = ye[:keep]
            out.append(yhat)
            if return_outside:
                flag = self._outside(ue, ye, lower, upper)
                flag[:keep] = False
                flags.append(flag)
        return _returned(out, flags if return_outside else None, _is_experiment_list(y))

    def simulate(self, u: Signals, y_init: Signals, *, return_outside: bool = False
                 ) -> Float2D | list[Float2D] | tuple:
        """Free-run simulation: φ(k) is built from the model's own past outputs.

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays
        y_init : array-like of shape (n_init, m) with n_init ≥ max(output lags, nb), or a
            list
            Initial outputs (a warm-up window); simulation starts at sample n_init.
        return_outside : bool, default False
            Also return, per sample, whether the simulation's regressor φ(k) (its own past
            outputs, the warm-up's where the lags reach into it, and the past inputs) leaves
            the data envelope (:meth:`outside_envelope` of u and the returned outputs); the
            simulation is the same either way.

        Returns
        -------
        ndarray of shape (N, m), or a list of them
            The first n_init rows are ``y_init``. A run that diverges to ±inf or NaN is
            returned as it is (later rows non-finite), not raised.
        outside : ndarray of bool, shape (N,), or a list of them (``return_outside`` only)
            True where φ(k) leaves the envelope or is not finite (a diverged run); False on
            the warm-up rows.

        Raises
        ------
        ValueError
            If the input width differs from the fitted one, ``y_init`` has fewer than
            max(output lags, nb) rows or more rows than u, any value is non-finite, or
            (``return_outside=True``) the model records no training range.
        """
        check_is_fitted(self)
        pairs = warmup_pairs(u, y_init, self.n_inputs_, self.n_outputs_, self.n_initial_)
        if return_outside:
            lower, upper = self.envelope()
        out, flags = [], []
        for ue, ye in pairs:
            out.append(self._free_run(ue, ye))
            if return_outside:
                flag = self._outside(ue, out[-1], lower, upper)
                flag[:ye.shape[0]] = False
                flags.append(flag)
        return _returned(out, flags if return_outside else None, _is_experiment_list(u))

    def envelope(self, padding: float = PADDING) -> tuple[np.ndarray, np.ndarray]:
        """The data envelope over φ(k) without the constant
        (:func:`~.envelope.regressor_bounds`): each entry's channel's training range widened
        by ``padding`` of its span.

        Parameters
        ----------
        padding : float, default :data:`~.envelope.PADDING` (5 %)

        Returns
        -------
        lower, upper : ndarrays of shape (m·L + r·nb,)
            In φ's order (eq. 3; L = :attr:`output_lags_`).

        Raises
        ------
        ValueError
            If the model records no training range (``signal_range_``: e.g. a model joined by
            ``PWARX.assemble`` without one).
        """
        check_is_fitted(self)
        rng = getattr(self, "signal_range_", None)
        if rng is None:
            raise ValueError(
                f"this {type(self).__name__} does not record the range of its training data "
                f"(signal_range_), so it has no data envelope: fit it, or pass the range to "
                f"PWARX.assemble(signal_range=...)")
        return regressor_bounds(rng, self.n_outputs_, self.n_inputs_, self.output_lags_,
                                self.nb, padding)

    def outside_envelope(self, u: Signals, y: Signals, padding: float = PADDING
                         ) -> np.ndarray | list[np.ndarray]:
        """Whether each sample's regressor φ(k), built from ``u`` and ``y``, leaves the data
        envelope (:meth:`envelope`): where the model is used outside its training data.

        Pass measured outputs for the samples of a one-step prediction, or the outputs a
        free run returned (``simulate``'s result, warm-up included) for the samples of that
        run: φ(k) is built from y's rows before k either way.

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays (one per experiment)
        y : array-like of shape (N, m), or a list of such arrays
            May hold NaN or inf (a diverged simulation): a φ(k) with such an entry is
            outside.
        padding : float, default :data:`~.envelope.PADDING` (5 %)

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
        """The flags of :meth:`outside_envelope` of one experiment, shape (N,)."""
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


def _returned(out: list, flags: list | None, many: bool):
    """What ``predict`` and ``simulate`` return: the arrays of each experiment (one array
    for a single one), with their envelope flags when asked (``flags`` not None)."""
    result = out if many else out[0]
    if flags is None:
        return result
    return result, (flags if many else flags[0])
