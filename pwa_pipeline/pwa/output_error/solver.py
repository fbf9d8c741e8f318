"""Levenberg–Marquardt on the output-error objectives, with the iterate chosen on held-out
experiments (`pwa_pipeline.pwa.output_error`)."""

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..._blas import single_threaded_blas
from ..._typing import Float2D
from .objective import OneStepError, RefinementErrors
from .simulator import FreeRuns, OutputFreeRuns


@dataclass(frozen=True)
class OutputErrorResult:
    """What a refinement did.

    Attributes
    ----------
    thetas : ndarray of shape (s, d, m)
        The refined parameter matrices.
    cost_start, cost : float
        Mean squared free-run error per scored sample and output, before and after.
    n_iter : int
        Levenberg–Marquardt steps taken (accepted or not).
    seconds : float
    stop : str
        Why it stopped.
    validation_start, validation_cost : float
        The same on the validation experiments (NaN without them); ``thetas`` is then the
        iterate with the lowest validation cost (of J_w, with a one-step weight).
    one_step_start, one_step_cost : float
        Mean squared one-step error J₁ per sample and output on the fitting experiments,
        before and after.
    """

    thetas: np.ndarray
    cost_start: float
    cost: float
    n_iter: int
    seconds: float
    stop: str
    validation_start: float = float("nan")
    validation_cost: float = float("nan")
    one_step_start: float = float("nan")
    one_step_cost: float = float("nan")


def levenberg_marquardt(x0: np.ndarray, train: Callable, held: Callable | None = None,
                        max_iter: int = 20, max_seconds: float = 240.0, tol: float = 1e-4,
                        patience: int = 3) -> OutputErrorResult:
    """Levenberg–Marquardt on the normal equations of a free-run cost, with the iterate
    chosen on held-out experiments.

    Parameters
    ----------
    x0 : ndarray
        Starting parameters (any shape; the steps keep it).
    train : callable
        ``train(x, sensitivities)`` → (cost, JᵀJ, Jᵀr) on the fitting experiments, JᵀJ and
        Jᵀr None unless ``sensitivities`` (as `simulate`).
    held : callable, optional
        ``held(x)`` → the cost on held-out experiments: the result is the iterate with the
        lowest, and the search stops after ``patience`` accepted steps without a new lowest.
    max_iter, max_seconds, tol, patience
        As `refine_output_error`.

    Raises
    ------
    ValueError
        If the start's cost is not finite (its free run diverges).
    """
    with single_threaded_blas():  # small products per time step: threads only wait
        return _levenberg_marquardt(x0, train, held, max_iter, max_seconds, tol, patience)


def _levenberg_marquardt(x0, train, held, max_iter, max_seconds, tol, patience):
    t0 = time.perf_counter()
    theta = np.array(x0, dtype=float)
    cost, jtj, jtr = train(theta, True)
    if not np.isfinite(cost):
        raise ValueError("the starting model's free run diverges on the training data; "
                         "output-error refinement needs a start whose free run stays finite")
    start, lam, stop, it = cost, 1.0, f"max_iter = {max_iter} reached", 0
    val_start = np.nan if held is None else held(theta)
    best, best_val, since_best = theta, val_start, 0
    for it in range(1, max_iter + 1):
        scale = np.maximum(np.diag(jtj), 1e-12 * max(np.diag(jtj).max(), 1e-300))
        step = np.linalg.solve(jtj + lam * np.diag(scale), -jtr).reshape(theta.shape)
        trial = theta + step
        trial_cost, trial_jtj, trial_jtr = train(trial, True)
        if trial_cost < cost:
            gain = (cost - trial_cost) / cost
            theta, cost, jtj, jtr = trial, trial_cost, trial_jtj, trial_jtr
            lam = max(lam / 3, 1e-9)
            if held is None:
                best = theta
            else:
                val = held(theta)
                since_best = 0 if val < best_val else since_best + 1
                best, best_val = (theta, val) if val < best_val else (best, best_val)
                if since_best >= patience:
                    stop = f"validation error not lower for {patience} steps"
                    break
            if gain < tol:
                stop = f"relative decrease {gain:.2g} < tol"
                break
        else:
            lam *= 10
            if lam > 1e8:
                stop = "no step lowers the cost"
                break
        if time.perf_counter() - t0 > max_seconds:
            stop = f"max_seconds = {max_seconds:g} passed"
            break
    if best is not theta:
        cost = train(best, False)[0]
    return OutputErrorResult(thetas=best, cost_start=start, cost=cost, n_iter=it,
                             seconds=time.perf_counter() - t0, stop=stop,
                             validation_start=val_start, validation_cost=best_val)


def _refine(x0: np.ndarray, train: RefinementErrors, held: RefinementErrors | None,
            weight: float, **options) -> OutputErrorResult:
    """Levenberg–Marquardt on J_w (on J when ``weight`` is 0), the iterate chosen on J_w of
    ``held``; the result's costs are the free-run and one-step errors apart. The costs at
    θ₀ are simulated once, for the ratios and the result."""
    if weight:
        start = train.costs(x0)
        held_start = None if held is None else held.costs(x0)
        objective = train.weighted(weight, start)
        held_w = None if held is None else held.weighted(weight, held_start)
    else:
        start = (np.nan, train.one_step(x0, False)[0])
        objective, held_w = train.free, None if held is None else held.free
    res = levenberg_marquardt(x0, objective, None if held_w is None else
                              (lambda x: held_w(x, False)[0]), **options)
    parts = {"one_step_start": start[1], "one_step_cost": train.one_step(res.thetas, False)[0]}
    if weight:
        parts |= {"cost_start": start[0], "cost": train.free(res.thetas, False)[0]}
        if held is not None:
            parts |= {"validation_start": held_start[0],
                      "validation_cost": held.free(res.thetas, False)[0]}
    return replace(res, **parts)


def refine_output_error(thetas: np.ndarray, u: list[Float2D], y: list[Float2D], na: int,
                        nb: int, affine: bool, region_of: Callable | None = None,
                        warmup: int | None = None, max_iter: int = 20,
                        max_seconds: float = 240.0, tol: float = 1e-4,
                        validation: tuple[list[Float2D], list[Float2D]] | None = None,
                        patience: int = 3, one_step_weight: float = 0.0,
                        limits: Float2D | None = None) -> OutputErrorResult:
    """Minimise the free-run error over the training experiments, or J_w with a one-step
    weight (`pwa_pipeline.pwa.output_error`).

    Parameters
    ----------
    thetas : ndarray of shape (s, d, m)
        Starting parameter matrices (least squares or clustering).
    u, y : lists of ndarrays
        The training experiments.
    na, nb : int
    affine : bool
    region_of : callable, optional
        φ rows (n, d) → sub-model index (n,); None for a linear model (s = 1).
    warmup : int, optional
        Measured samples that start each run; default max(na, nb).
    max_iter : int
        Levenberg–Marquardt steps at most.
    max_seconds : float
        Stop after the step that passes this time.
    tol : float
        Stop when an accepted step lowers the cost by less than this fraction.
    validation : (u, y) lists of ndarrays, optional
        Experiments held out of the training ones: the result is the iterate with the
        lowest free-run error on them, and the search stops after ``patience`` accepted
        steps without a new lowest.
    patience : int
    one_step_weight : float
        w of J_w (`pwa_pipeline.pwa.output_error`); 0: the free-run error alone.
    limits : ndarray of shape (2, m), optional
        The outputs' limits (`pwa_pipeline.pwa.limits`): the free run is clipped to them.

    Returns
    -------
    OutputErrorResult
        ``thetas`` is the start when no step lowered the (validation) cost.

    Raises
    ------
    ValueError
        If the starting model's free run diverges on the training data (refinement needs a
        start whose free run stays finite).
    """
    warmup = max(na, nb) if warmup is None else warmup

    def errors(u: list[Float2D], y: list[Float2D]) -> RefinementErrors:
        runs = FreeRuns(u, y, na, nb, affine, warmup, limits=limits)
        return RefinementErrors(
            lambda t, sens: runs.simulate(t.reshape(thetas.shape), region_of, sens),
            runs.n_scored, OneStepError.of_thetas(u, y, na, nb, affine, region_of, thetas.shape))

    return _refine(np.asarray(thetas, dtype=float), errors(u, y),
                   None if validation is None else errors(*validation), one_step_weight,
                   max_iter=max_iter, max_seconds=max_seconds, tol=tol, patience=patience)


def refine_outputs(models: list, simulated: list[int], u: list[Float2D], y: list[Float2D],
                   lags: int, nb: int, affine: bool, warmup: int,
                   validation: tuple[list[Float2D], list[Float2D]] | None = None,
                   max_iter: int = 20, max_seconds: float = 240.0, tol: float = 1e-4,
                   patience: int = 3, one_step_weight: float = 0.0,
                   limits: Float2D | None = None) -> OutputErrorResult:
    """Refine the p_j of the per-output models ``models[j]``, j in ``simulated``, on their
    free-run error, or J_w with ``one_step_weight`` (`pwa_pipeline.pwa.output_error`, with the models of
    `pwa_pipeline.pwa.structures`); the regions stay fixed as functions of φ, the free run
    clipped to the outputs' ``limits`` (2, m; `pwa_pipeline.pwa.limits`) when given.

    Returns
    -------
    OutputErrorResult
        ``thetas`` holds the concatenated p_j of the simulated outputs.
    """
    def errors(u: list[Float2D], y: list[Float2D]) -> RefinementErrors:
        runs = OutputFreeRuns(u, y, lags, nb, affine, warmup, models, simulated, limits)
        return RefinementErrors(runs.simulate, runs.n_scored,
                                OneStepError.of_outputs(u, y, lags, nb, affine, models,
                                                        simulated))

    start = np.concatenate([models[j].p for j in simulated])
    return _refine(start, errors(u, y), None if validation is None else errors(*validation),
                   one_step_weight, max_iter=max_iter, max_seconds=max_seconds, tol=tol,
                   patience=patience)
