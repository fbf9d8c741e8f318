"""The costs the output-error refinement minimises: the free-run error J, the one-step error
J₁ of eq. (3) and their weighted sum J_w (`pwa_pipeline.pwa.output_error`)."""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..._typing import Float2D
from ...regressors import build_regressors


class OneStepError:
    """The one-step error J₁ of eq. (3) (`pwa_pipeline.pwa.output_error`) as blocks of
    residuals X_b x[idx_b] − t_b, linear in the parameters x (flattened), the regions taken
    from the measured φ."""

    def __init__(self, blocks: list[tuple[Float2D, np.ndarray, np.ndarray]], size: int):
        self.blocks = blocks
        self.n_scored = sum(len(t) for _, t, _ in blocks)
        self.jtj = np.zeros((size, size))
        for x, _, idx in blocks:
            self.jtj[np.ix_(idx, idx)] += x.T @ x

    @classmethod
    def of_thetas(cls, u: list[Float2D], y: list[Float2D], na: int, nb: int, affine: bool,
                  region_of: Callable | None, shape: tuple[int, int, int]) -> "OneStepError":
        """J₁ of parameter matrices θ of ``shape`` (s, d, m), flattened as in
        `simulate` (region, regressor, output)."""
        s, d, m = shape
        reg = build_regressors(list(zip(u, y, strict=True)), na, nb, affine)
        region = np.zeros(len(reg.phi), int) if region_of is None else region_of(reg.phi)
        return cls([(reg.phi[region == i], reg.target[region == i, j],
                     i * d * m + np.arange(d) * m + j) for i in range(s) for j in range(m)],
                   s * d * m)

    @classmethod
    def of_outputs(cls, u: list[Float2D], y: list[Float2D], lags: int, nb: int, affine: bool,
                   models: list, simulated: list[int]) -> "OneStepError":
        """J₁ of the per-output models ``models[j]``, j in ``simulated``, over their
        concatenated p_j (as `OutputFreeRuns`)."""
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
class RefinementErrors:
    """The free-run error J (``free(x, sensitivities)`` as `simulate`, over
    ``n_free`` scored values) and the one-step error J₁ of one set of experiments."""

    free: Callable
    n_free: int
    one_step: OneStepError

    def costs(self, x: np.ndarray) -> tuple[float, float]:
        """J and J₁ at x, per sample and output."""
        return self.free(x, False)[0], self.one_step(x, False)[0]

    def weighted(self, weight: float, start: tuple[float, float]) -> Callable:
        """J_w (`pwa_pipeline.pwa.output_error`; ``weight`` > 0) as
        ``(x, sensitivities)`` → (cost, JᵀJ, Jᵀr); ``start`` is `costs` at θ₀, for the
        ratio J(θ₀) / J₁(θ₀)."""
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
