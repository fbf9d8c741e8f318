"""Simulation-error refinement as a step object (`pwa_pipeline.pwa.output_error`)."""

from collections.abc import Callable
from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator, _fit_context
from sklearn.utils._param_validation import Interval

from ..._typing import Float2D
from .solver import refine_output_error

#: Share of the training experiments held out for validation unless a step is told otherwise.
VALIDATION_FRACTION = 0.1


def held_out(n: int, fraction: float) -> int:
    """How many of ``n`` training experiments (the last ones) are held out for validation:
    ``round(fraction·n)``, at least one and at most n − 1; 0 when ``fraction`` is 0 or
    there is a single experiment."""
    return min(max(1, round(fraction * n)), n - 1) if fraction > 0 and n >= 2 else 0


def numbered(indices: list[int], n: int) -> str:
    """Held-out experiments (``indices``: consecutive, 0-based) as a user counts them, from
    1: ``"4 of 4"``, ``"54–66 of 66"``: what the search's report and the model's page
    say."""
    first, last = indices[0] + 1, indices[-1] + 1
    return f"{first} of {n}" if first == last else f"{first}–{last} of {n}"


class OutputErrorRefinement(BaseEstimator):
    """Simulation-error refinement as a step object (`pwa_pipeline.pwa.output_error`).

    The optional last step of [`PWARX`][pwa_pipeline.PWARX] and of
    [`LinearARX`][pwa_pipeline.baselines.LinearARX] (``refinement=``): it takes their
    fitted θ_i and regions and returns θ_i that minimise the free-run error on the training
    experiments.

    Parameters
    ----------
    max_iter : int, default 20
        Levenberg–Marquardt steps at most.
    max_seconds : float, default 240
        Time bound: stop after the step that passes it.
    tol : float, default 1e-4
        Stop when an accepted step lowers the cost by less than this fraction.
    warmup : int or None, default 10
        Measured samples that start each training run (None: max(na, nb)); as the
        evaluation protocol's warm-up.
    validation_fraction : float, default 0.1
        Share of the training experiments (the last ones, at least one) held out to choose
        the iterate and stop: model selection on training data only, the test data never
        seen. 0, or a single training experiment: no validation, the last iterate is kept.
    patience : int, default 3
        Accepted steps without a lower validation error before stopping.
    one_step_weight : float, default 0
        w of J_w (`pwa_pipeline.pwa.output_error`): the one-step error's weight
        beside the free-run error, each relative to its value at the start. 0 refines the
        free run alone; a large w keeps the one-step fit of the start (least squares).
        Choose it on held-out training experiments (``benchmarks/robot_structure.py
        --weights`` does so for the robot).

    Attributes
    ----------
    thetas_ : ndarray of shape (s, d, m)
    cost_start_, cost_ : float
        Mean squared free-run error per sample and output on the fitting experiments,
        before and after.
    validation_experiments_ : list of int
        Indices (in the training list) of the experiments held out for validation.
    validation_cost_start_, validation_cost_ : float
        The same on them (NaN without validation).
    one_step_cost_start_, one_step_cost_ : float
        Mean squared one-step error per sample and output on the fitting experiments, before
        and after.
    n_iter_ : int
    stop_ : str
    seconds_ : float
    """

    _parameter_constraints: dict = {
        "max_iter": [Interval(Integral, 1, None, closed="left")],
        "max_seconds": [Interval(Real, 0, None, closed="neither")],
        "tol": [Interval(Real, 0, None, closed="left")],
        "warmup": [Interval(Integral, 1, None, closed="left"), None],
        "validation_fraction": [Interval(Real, 0, 1, closed="left")],
        "patience": [Interval(Integral, 1, None, closed="left")],
        "one_step_weight": [Interval(Real, 0, None, closed="left")],
    }

    def __init__(self, max_iter: int = 20, max_seconds: float = 240.0, tol: float = 1e-4,
                 warmup: int | None = 10, validation_fraction: float = VALIDATION_FRACTION,
                 patience: int = 3, one_step_weight: float = 0.0):
        self.max_iter = max_iter
        self.max_seconds = max_seconds
        self.tol = tol
        self.warmup = warmup
        self.validation_fraction = validation_fraction
        self.patience = patience
        self.one_step_weight = one_step_weight

    def run_warmup(self, lags: int, nb: int) -> int:
        """Measured samples that start each run of a model with ``lags`` output lags:
        ``warmup`` (None: none beyond the lags), at least max(lags, nb)."""
        return max(lags, nb) if self.warmup is None else max(self.warmup, lags, nb)

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, thetas: np.ndarray, u: list[Float2D], y: list[Float2D], na: int, nb: int,
            affine: bool, region_of: Callable | None = None,
            limits: Float2D | None = None) -> "OutputErrorRefinement":
        """Refine ``thetas`` on the experiments ``(u, y)``; arguments as
        `refine_output_error` (``limits``: the outputs' limits, `pwa_pipeline.pwa.limits`)."""
        self._validate_params()  # also when an estimator fits it nested (sklearn skips then)
        warmup = self.run_warmup(na, nb)
        n = len(u)
        n_val = held_out(n, self.validation_fraction)
        self.validation_experiments_ = list(range(n - n_val, n))
        fit, held = slice(0, n - n_val), slice(n - n_val, n)
        result = refine_output_error(
            thetas, u[fit], y[fit], na, nb, affine, region_of=region_of, warmup=warmup,
            max_iter=self.max_iter, max_seconds=self.max_seconds, tol=self.tol,
            validation=(u[held], y[held]) if n_val else None, patience=self.patience,
            one_step_weight=self.one_step_weight, limits=limits)
        self.thetas_ = result.thetas
        self.cost_start_, self.cost_ = result.cost_start, result.cost
        self.validation_cost_start_ = result.validation_start
        self.validation_cost_ = result.validation_cost
        self.one_step_cost_start_ = result.one_step_start
        self.one_step_cost_ = result.one_step_cost
        self.n_iter_, self.stop_, self.seconds_ = result.n_iter, result.stop, result.seconds
        return self
