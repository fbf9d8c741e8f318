"""Linear ARX baseline with the same regressors as the PWARX model."""

import time
from numbers import Integral

import numpy as np
from sklearn.base import BaseEstimator, _fit_context, clone
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions

from .._typing import Signals
from .._validation import as_experiments
from ..envelope import training_range
from ..pwa.arx import ARXModelBase
from ..pwa.groups import OutputGroup
from ..pwa.partitions import SingleRegion
from ..pwa.structure_fit import fit_structure
from ..pwa.structures import COUPLINGS, FORMS
from ..regressors import build_regressors


class LinearARX(ARXModelBase):
    """Linear MIMO ARX model y(k) = θᵀφ(k), fitted by least squares (one sub-model).

    Parameters
    ----------
    na, nb : int
        Orders of eq. (3).
    affine : bool, default False
    form : {"level", "velocity"}, default "level"
        ``"velocity"``: each output's increment Δy(k) from na lagged increments, the level
        y(k−1) and the inputs, integrated (`pwa_pipeline.pwa.structures`).
    outputs : {"joint", "decoupled"}, default "joint"
        ``"decoupled"``: one MISO model per output, on its own lags and every input.
    refinement : estimator, optional
        An `OutputErrorRefinement`: θ refined from the
        least-squares fit to minimise the free-run error on the training experiments. None:
        least squares only.

    Attributes
    ----------
    theta_ : ndarray of shape (d, m)
        Over the level regressor φ (eq. 3; na + 1 output lags in the velocity form), so a
        velocity-form or decoupled model predicts as any ARX model.
    groups_ : list of OutputGroup
        The fitted shape every ARX model shares (`pwa_pipeline.pwa.groups`): one
        group of every output with one region, ``theta_`` as its sub-model (its ``steps``
        hold the fitted refinement, where one ran on the level, joint route). So
        ``thetas_`` is ``theta_[None]``, ``n_submodels_`` 1.
    structures_ : list of str
        Each output's structure in words (form, orders, linear).
    structure_fit_ : StructureFit (velocity form or decoupled outputs)
        The validation experiments and the refinement of each output group
        (`StructureFit`).
    timings_ : dict
        Seconds of the fit (``fit``).
    n_inputs_, n_outputs_ : int
    signal_range_ : ndarray of shape (2, m + r)
        Smallest and largest training value of each output, then each input: the data
        envelope of `outside_envelope` and of
        `to_state_space`.

    Examples
    --------
    >>> import numpy as np
    >>> from pwa_pipeline import LinearARX
    >>> u = np.random.default_rng(0).normal(size=(200, 1))
    >>> y = np.zeros((200, 1))
    >>> for k in range(1, 200):
    ...     y[k] = 0.5 * y[k - 1] + 2.0 * u[k - 1]
    >>> np.round(LinearARX(1, 1).fit(u, y).theta_.ravel(), 6)
    array([0.5, 2. ])
    """

    _parameter_constraints: dict = {
        "na": [Interval(Integral, 0, None, closed="left")],
        "nb": [Interval(Integral, 0, None, closed="left")],
        "affine": ["boolean"],
        "form": [StrOptions(set(FORMS))],
        "outputs": [StrOptions(set(COUPLINGS))],
        "refinement": [HasMethods(["fit"]), None],
    }

    def __init__(self, na: int = 1, nb: int = 1, affine: bool = False, form: str = "level",
                 outputs: str = "joint", refinement: BaseEstimator | None = None):
        self.na = na
        self.nb = nb
        self.affine = affine
        self.form = form
        self.outputs = outputs
        self.refinement = refinement

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, u: Signals, y: Signals) -> "LinearARX":
        """Least-squares fit on one or several experiments (regressors never span two)."""
        t0 = time.perf_counter()
        pairs = as_experiments(u, y)
        self.signal_range_ = training_range(pairs)
        self.n_inputs_ = pairs[0][0].shape[1]
        self.n_outputs_ = pairs[0][1].shape[1]
        self.n_features_in_ = self.n_inputs_
        steps = {}
        if self.form != "level" or self.outputs != "joint":
            self.structure_fit_ = fit_structure(pairs, self.na, self.nb, self.affine, self.form,
                                                self.outputs, refinement=self.refinement)
            self.theta_ = np.column_stack([o.thetas()[0] for o in self.structure_fit_.outputs])
        else:
            reg = build_regressors(pairs, self.na, self.nb, self.affine)
            if reg.phi.shape[0] < reg.phi.shape[1]:
                raise ValueError(
                    f"too few samples: {reg.phi.shape[0]} regressor rows for "
                    f"{reg.phi.shape[1]} parameters per output"
                )
            self.theta_ = np.linalg.lstsq(reg.phi, reg.target, rcond=None)[0]
            if self.refinement is not None:
                steps["refinement"] = clone(self.refinement).fit(
                    self.theta_[None], [p[0] for p in pairs], [p[1] for p in pairs], self.na,
                    self.nb, self.affine)
                self.theta_ = steps["refinement"].thetas_[0]
        self.groups_ = [OutputGroup(tuple(range(self.n_outputs_)),
                                    SingleRegion(self.theta_.shape[0]), self.theta_[None],
                                    steps)]
        self.structures_ = [f"{self.form} ({self.na}, {self.nb}), linear"] * self.n_outputs_
        self.timings_ = {"fit": time.perf_counter() - t0}
        return self

    def resolved_params(self) -> dict:
        """The parameters as ``get_params(deep=True)`` names them (nothing is chosen at
        fit), the refinement step by its class name."""
        params = self.get_params(deep=True)
        if self.refinement is not None:
            params["refinement"] = type(self.refinement).__name__
        return params
