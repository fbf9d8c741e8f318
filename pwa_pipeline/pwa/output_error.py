"""Simulation-error (output-error) refinement of ARX-structured models, PWA and linear.

Least squares on eq. (3)'s one-step error fits what a model predicts one sample ahead; a free
run feeds the model its own outputs, and small one-step errors can add up. Refinement starts
from the fitted parameter matrices θ_i and minimises the free-run error over the training
experiments,

    J(θ) = Σ_e Σ_{k ≥ w} ‖ y_e(k) − ŷ_e(k; θ) ‖²,   ŷ_e(k) = θ_{λ(k)}ᵀ φ̂_e(k),

where φ̂ holds the simulated past outputs and λ(k) is the region (step 6) of φ̂_e(k), kept
fixed as a function of φ: the hyperplanes do not move, the regions visited follow the run.

The free run may buy its accuracy with the one-step prediction (on the robot, a joint's
own-increment coefficient moved from 1.0 to −0.9 and the one-step error grew seventy-fold).
With a one-step weight w > 0 the refinement minimises instead

    J_w(θ) = J(θ) + w · J(θ₀) / J₁(θ₀) · J₁(θ),
    J₁(θ) = Σ_e Σ_k ‖ y_e(k) − θ_{λ(k)}ᵀ φ_e(k) ‖²,

J₁ the one-step (equation) error of eq. (3) on the measured regressors φ — the least-squares
objective — with λ(k) the region of the measured φ_e(k), both costs as means per sample and
output. The ratio at the start θ₀ makes w dimensionless: with w = 1, raising the one-step
error by its starting value costs as much as raising the free-run error by its starting value.
Since J₁(θ) = J₁(θ_LS) + (θ − θ_LS)ᵀ XᵀX (θ − θ_LS) / n for the least-squares solution θ_LS
(X the stacked regressors), the term is a regularisation towards least squares in the metric
of the one-step error: directions that barely change the one-step prediction stay free.
w = 0 is the free-run refinement alone; as w grows, the minimiser tends to θ_LS (the start,
when the start is least squares). The iterate is then chosen on J_w of the held-out
experiments (their own ratio at θ₀).

The minimiser is Levenberg–Marquardt on the normal equations. The Jacobian of the free run
is propagated forward in time (sensitivities dŷ(k)/dθ through the output lags of φ̂, the
region treated as locally constant), for all experiments at once, and only JᵀJ (P × P) and
Jᵀr are kept, never J itself (N·m × P: 830 MB for three sub-models on the robot). J₁'s
residuals are linear in θ, so its JᵀJ is computed once.
"""

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator, _fit_context
from sklearn.utils._param_validation import Interval

from .._typing import Float2D
from ._blas import single_threaded_blas
from .regressors import build_regressors


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


class _NormalEquations:
    """JᵀJ and Jᵀr of the free run, from Jacobian rows gathered over 32 time steps for one
    larger product."""

    def __init__(self, p: int):
        self.jtj, self.jtr = np.zeros((p, p)), np.zeros(p)
        self._rows: list[np.ndarray] = []
        self._res: list[np.ndarray] = []

    def add(self, rows: np.ndarray, residuals: np.ndarray, last: bool) -> None:
        """Add the rows dŷ/dθ (n, p) and residuals (n,) of one time step."""
        self._rows.append(rows)
        self._res.append(residuals)
        if len(self._rows) == 32 or last:
            rows_j, res = np.vstack(self._rows), np.concatenate(self._res)
            self.jtj += rows_j.T @ rows_j
            self.jtr += rows_j.T @ res
            self._rows, self._res = [], []


class _Runs:
    """The training experiments padded to one length, simulated in lockstep.

    ``simulated`` (default: every output) are the outputs that run free; the others keep
    their measured values (with decoupled per-output models they do not enter the
    simulated ones).
    """

    def __init__(self, u: list[Float2D], y: list[Float2D], na: int, nb: int, affine: bool,
                 warmup: int, simulated: list[int] | None = None):
        self.na, self.nb, self.affine, self.warmup = na, nb, affine, warmup
        self.lengths = np.array([len(e) for e in y])
        n, e = self.lengths.max(), len(y)
        self.u = np.zeros((e, n, u[0].shape[1]))
        self.y = np.zeros((e, n, y[0].shape[1]))
        for i, (ue, ye) in enumerate(zip(u, y, strict=True)):
            self.u[i, :len(ue)], self.y[i, :len(ye)] = ue, ye
        self.simulated = list(range(self.y.shape[2]) if simulated is None else simulated)
        self.n_scored = int(np.maximum(self.lengths - warmup, 0).sum()) * len(self.simulated)

    def phi(self, ysim: np.ndarray, k: int) -> Float2D:
        """φ̂(k) of every experiment, in eq. (3)'s order, from the simulated outputs."""
        e = ysim.shape[0]
        ylags = ysim[:, k - self.na:k][:, ::-1].transpose(0, 2, 1).reshape(e, -1)
        ulags = self.u[:, k - self.nb:k][:, ::-1].transpose(0, 2, 1).reshape(e, -1)
        parts = [ylags, ulags] + ([np.ones((e, 1))] if self.affine else [])
        return np.concatenate(parts, axis=1)

    def simulate(self, thetas: np.ndarray, region_of: Callable | None,
                 sensitivities: bool) -> tuple[float, np.ndarray | None, np.ndarray | None]:
        """Cost J / (scored samples · outputs), and JᵀJ and Jᵀr when ``sensitivities``, of
        parameter matrices θ (s, d, m) flattened as (region, regressor, output).

        Returns inf (and no normal equations) when the run leaves the finite numbers.
        """
        s, d, m = thetas.shape
        rows, outs = np.arange(self.y.shape[0])[:, None, None], np.arange(m)[None, :, None]

        def step(phi):
            region = np.zeros(len(phi), dtype=int) if region_of is None else region_of(phi)

            def direct(sk):  # dŷ_j(k)/dθ_{λ(k), a, j} = φ_a(k)
                cols = region[:, None, None] * d * m + np.arange(d)[None, None, :] * m + outs
                sk[rows, outs, cols] = phi[:, None, :]

            return thetas[region], direct

        with np.errstate(over="ignore", invalid="ignore"):
            return self._run(step, s * d * m, sensitivities)

    def _run(self, step: Callable, n_params: int, sensitivities: bool):
        """The free run and its sensitivities dŷ(k)/dθ, propagated through the output lags
        of φ̂. ``step(φ̂)`` gives every experiment's parameter matrix at k, (e, d, outputs
        simulated), and a function adding the direct term dŷ(k)/dθ at fixed φ̂ to an
        (e, outputs simulated, n_params) array."""
        e, n = self.y.shape[:2]
        sim, w, na = self.simulated, self.warmup, self.na
        ysim = self.y.copy()
        lag_rows = [[q * na + lag - 1 for q in sim] for lag in range(1, na + 1)]
        sens = np.zeros((na + 1, e, len(sim), n_params))  # ring buffer of dŷ(k)/dθ
        normal, cost = _NormalEquations(n_params), 0.0
        for k in range(w, n):
            active = self.lengths > k
            phi = self.phi(ysim, k)
            theta_k, direct = step(phi)
            yk = np.einsum("ed,edj->ej", phi, theta_k)
            target = self.y[:, k][:, sim]
            ysim[:, k, sim] = np.where(active[:, None], yk, target)
            r = np.where(active[:, None], yk - target, 0.0)
            cost += float(np.sum(r * r))
            if not np.isfinite(cost):
                return np.inf, None, None
            if not sensitivities:
                continue
            sk = np.zeros((e, len(sim), n_params))
            direct(sk)
            # through the output lags of φ̂: φ_{q, lag}(k) = ŷ_q(k − lag)
            for lag in range(1, min(na, k - w) + 1):
                a = theta_k[:, lag_rows[lag - 1], :]                   # (e, q, j)
                sk += np.einsum("eqj,eqp->ejp", a, sens[(k - lag) % (na + 1)])
            sk[~active] = 0.0
            sens[k % (na + 1)] = sk
            normal.add(sk.reshape(-1, n_params), r.ravel(), last=k == n - 1)
        if not sensitivities:
            return cost / self.n_scored, None, None
        return cost / self.n_scored, normal.jtj, normal.jtr


class _OutputRuns(_Runs):
    """The experiments simulated with per-output models
    (:class:`~.structures.OutputModel`): the outputs ``simulated`` run free, the others
    keep their measured values.

    The parameters are the concatenated p_j of the simulated outputs.
    """

    def __init__(self, u, y, lags: int, nb: int, affine: bool, warmup: int,
                 models: list, simulated: list[int]):
        super().__init__(u, y, lags, nb, affine, warmup, simulated)
        self.models = models
        self.g = [models[j].G() for j in self.simulated]
        self.offsets = np.cumsum([0] + [g.shape[2] for g in self.g])

    def simulate(self, p: np.ndarray, sensitivities: bool):
        """As :meth:`_Runs.simulate`, with the concatenated p_j."""
        sim, bounds = self.simulated, list(zip(self.offsets[:-1], self.offsets[1:]))
        thetas = [self.models[j].c + g @ p[a:b]
                  for j, g, (a, b) in zip(sim, self.g, bounds, strict=True)]

        def step(phi):
            regions = [self.models[j].regions(phi) for j in sim]

            def direct(sk):
                for jj, (g, reg, (a, b)) in enumerate(zip(self.g, regions, bounds)):
                    sk[:, jj, a:b] = np.einsum("ed,edp->ep", phi, g[reg])

            return np.stack([t[r] for t, r in zip(thetas, regions, strict=True)], axis=2), direct

        with np.errstate(over="ignore", invalid="ignore"):
            return self._run(step, int(self.offsets[-1]), sensitivities)


class _OneStep:
    """The one-step error J₁ (module doc) as blocks of residuals X_b x[idx_b] − t_b, linear
    in the parameters x (flattened), the regions taken from the measured φ."""

    def __init__(self, blocks: list[tuple[Float2D, np.ndarray, np.ndarray]], size: int):
        self.blocks = blocks
        self.n_scored = sum(len(t) for _, t, _ in blocks)
        self.jtj = np.zeros((size, size))
        for x, _, idx in blocks:
            self.jtj[np.ix_(idx, idx)] += x.T @ x

    @classmethod
    def of_thetas(cls, u: list[Float2D], y: list[Float2D], na: int, nb: int, affine: bool,
                  region_of: Callable | None, shape: tuple[int, int, int]) -> "_OneStep":
        """J₁ of parameter matrices θ of ``shape`` (s, d, m), flattened as in
        :meth:`_Runs.simulate` (region, regressor, output)."""
        s, d, m = shape
        reg = build_regressors(list(zip(u, y, strict=True)), na, nb, affine)
        region = np.zeros(len(reg.phi), int) if region_of is None else region_of(reg.phi)
        return cls([(reg.phi[region == i], reg.target[region == i, j],
                     i * d * m + np.arange(d) * m + j) for i in range(s) for j in range(m)],
                   s * d * m)

    @classmethod
    def of_outputs(cls, u: list[Float2D], y: list[Float2D], lags: int, nb: int, affine: bool,
                   models: list, simulated: list[int]) -> "_OneStep":
        """J₁ of the per-output models ``models[j]``, j in ``simulated``, over their
        concatenated p_j (as :class:`_OutputRuns`)."""
        reg = build_regressors(list(zip(u, y, strict=True)), lags, nb, affine)
        sizes = [models[j].n_params for j in simulated]
        starts = np.cumsum([0] + sizes)
        return cls([(models[j].design(reg.phi), reg.target[:, j] - reg.phi @ models[j].c,
                     a + np.arange(size))
                    for j, a, size in zip(simulated, starts[:-1], sizes, strict=True)],
                   int(starts[-1]))

    def __call__(self, x: np.ndarray, sensitivities: bool):
        """J₁ per sample and output, and JᵀJ and Jᵀr (raw sums) when ``sensitivities``."""
        x = np.ravel(x)
        cost, jtr = 0.0, np.zeros(x.size)
        for xb, t, idx in self.blocks:
            r = xb @ x[idx] - t
            cost += float(r @ r)
            jtr[idx] += xb.T @ r
        if not sensitivities:
            return cost / self.n_scored, None, None
        return cost / self.n_scored, self.jtj, jtr


@dataclass(frozen=True)
class _Errors:
    """The free-run error J (``free(x, sensitivities)`` as :meth:`_Runs.simulate`, over
    ``n_free`` scored values) and the one-step error J₁ of one set of experiments."""

    free: Callable
    n_free: int
    one_step: _OneStep

    def costs(self, x: np.ndarray) -> tuple[float, float]:
        """J and J₁ at x, per sample and output."""
        return self.free(x, False)[0], self.one_step(x, False)[0]

    def weighted(self, weight: float, start: tuple[float, float]) -> Callable:
        """J_w of the module doc (``weight`` > 0) as ``(x, sensitivities)`` → (cost, JᵀJ,
        Jᵀr); ``start`` is :meth:`costs` at θ₀, for the ratio J(θ₀) / J₁(θ₀)."""
        ratio = weight * start[0] / max(start[1], np.finfo(float).tiny)

        def objective(x: np.ndarray, sensitivities: bool):
            cost, jtj, jtr = self.free(x, sensitivities)
            one, one_jtj, one_jtr = self.one_step(x, sensitivities)
            total = cost + ratio * one
            if jtj is None:
                return total, None, None
            k = ratio / self.one_step.n_scored
            return total, jtj / self.n_free + k * one_jtj, jtr / self.n_free + k * one_jtr

        return objective


def _refine(x0: np.ndarray, train: _Errors, held: _Errors | None, weight: float,
            **options) -> OutputErrorResult:
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


def refine_outputs(models: list, simulated: list[int], u: list[Float2D], y: list[Float2D],
                   lags: int, nb: int, affine: bool, warmup: int,
                   validation: tuple[list[Float2D], list[Float2D]] | None = None,
                   max_iter: int = 20, max_seconds: float = 240.0, tol: float = 1e-4,
                   patience: int = 3, one_step_weight: float = 0.0) -> OutputErrorResult:
    """Refine the p_j of the per-output models ``models[j]``, j in ``simulated``, on their
    free-run error, or J_w with ``one_step_weight`` (the module doc, with the models of
    :mod:`~.structures`); the regions stay fixed as functions of φ.

    Returns
    -------
    OutputErrorResult
        ``thetas`` holds the concatenated p_j of the simulated outputs.
    """
    def errors(u: list[Float2D], y: list[Float2D]) -> _Errors:
        runs = _OutputRuns(u, y, lags, nb, affine, warmup, models, simulated)
        return _Errors(runs.simulate, runs.n_scored,
                       _OneStep.of_outputs(u, y, lags, nb, affine, models, simulated))

    start = np.concatenate([models[j].p for j in simulated])
    return _refine(start, errors(u, y), None if validation is None else errors(*validation),
                   one_step_weight, max_iter=max_iter, max_seconds=max_seconds, tol=tol,
                   patience=patience)


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
        Jᵀr None unless ``sensitivities`` (as :meth:`_Runs.simulate`).
    held : callable, optional
        ``held(x)`` → the cost on held-out experiments: the result is the iterate with the
        lowest, and the search stops after ``patience`` accepted steps without a new lowest.
    max_iter, max_seconds, tol, patience
        As :func:`refine_output_error`.

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


def refine_output_error(thetas: np.ndarray, u: list[Float2D], y: list[Float2D], na: int,
                        nb: int, affine: bool, region_of: Callable | None = None,
                        warmup: int | None = None, max_iter: int = 20,
                        max_seconds: float = 240.0, tol: float = 1e-4,
                        validation: tuple[list[Float2D], list[Float2D]] | None = None,
                        patience: int = 3, one_step_weight: float = 0.0) -> OutputErrorResult:
    """Minimise the free-run error over the training experiments, or J_w with a one-step
    weight (see the module doc).

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
        w of J_w (module doc); 0: the free-run error alone.

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

    def errors(u: list[Float2D], y: list[Float2D]) -> _Errors:
        runs = _Runs(u, y, na, nb, affine, warmup)
        return _Errors(lambda t, sens: runs.simulate(t.reshape(thetas.shape), region_of, sens),
                       runs.n_scored,
                       _OneStep.of_thetas(u, y, na, nb, affine, region_of, thetas.shape))

    return _refine(np.asarray(thetas, dtype=float), errors(u, y),
                   None if validation is None else errors(*validation), one_step_weight,
                   max_iter=max_iter, max_seconds=max_seconds, tol=tol, patience=patience)


#: Share of the training experiments held out for validation unless a step is told otherwise.
VALIDATION_FRACTION = 0.1


def held_out(n: int, fraction: float) -> int:
    """How many of ``n`` training experiments (the last ones) are held out for validation:
    ``round(fraction·n)``, at least one and at most n − 1; 0 when ``fraction`` is 0 or
    there is a single experiment."""
    return min(max(1, round(fraction * n)), n - 1) if fraction > 0 and n >= 2 else 0


class OutputErrorRefinement(BaseEstimator):
    """Simulation-error refinement as a step object (see the module doc).

    The optional last step of :class:`~pwa_pipeline.pwa.estimator.PWARX` and of
    :class:`~pwa_pipeline.baselines.linear.LinearARX` (``refinement=``): it takes their
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
        w of the module doc's J_w: the one-step error's weight beside the free-run error,
        each relative to its value at the start. 0 refines the free run alone; a large w
        keeps the one-step fit of the start (least squares). Choose it on held-out training
        experiments (``benchmarks/robot_structure.py --weights`` does so for the robot).

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
            affine: bool, region_of: Callable | None = None) -> "OutputErrorRefinement":
        """Refine ``thetas`` on the experiments ``(u, y)``; arguments as
        :func:`refine_output_error`."""
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
            one_step_weight=self.one_step_weight)
        self.thetas_ = result.thetas
        self.cost_start_, self.cost_ = result.cost_start, result.cost
        self.validation_cost_start_ = result.validation_start
        self.validation_cost_ = result.validation_cost
        self.one_step_cost_start_ = result.one_step_start
        self.one_step_cost_ = result.one_step_cost
        self.n_iter_, self.stop_, self.seconds_ = result.n_iter, result.stop, result.seconds
        return self
