"""Levenberg–Marquardt on the output-error costs (pwa.output_error.solver)."""

import numpy as np
import pytest

from pwa_pipeline import LinearARX
from pwa_pipeline.pwa.output_error import OutputErrorRefinement
from pwa_pipeline.pwa.output_error.simulator import FreeRuns
from pwa_pipeline.pwa.output_error.solver import levenberg_marquardt, refine_output_error

from ..._output_error_cases import _output_noise_system


def test_a_diverging_start_is_refused_with_its_reason():
    u, y = _output_noise_system(seed=1, n=2000)  # 1.5^2000 overflows
    with pytest.raises(ValueError, match="starting model's free run diverges"):
        refine_output_error(np.array([[[1.5], [0.5]]]), [u], [y], 1, 1, False)


def test_the_one_step_weight_trades_free_run_error_for_one_step_error():
    """Under output noise least squares (the minimum of the one-step error) is biased and the
    free-run refinement is not: 0 is the free-run refinement itself, a large weight keeps the
    least-squares parameters, and weights between trade one error for the other."""
    u, y = _output_noise_system(seed=5)
    ls = LinearARX(1, 1).fit(u, y).theta_[None]
    fits = {w: OutputErrorRefinement(max_iter=50, validation_fraction=0, one_step_weight=w)
            .fit(ls, [u], [y], 1, 1, False) for w in (0.0, 0.05, 1e6)}
    runs = FreeRuns([u], [y], 1, 1, False, 10)
    plain = levenberg_marquardt(ls, lambda t, s: runs.simulate(t, None, s), max_iter=50)
    np.testing.assert_array_equal(fits[0.0].thetas_, plain.thetas)
    np.testing.assert_allclose(fits[0.0].thetas_.ravel(), [0.9, 0.5], atol=0.02)
    np.testing.assert_allclose(fits[1e6].thetas_, ls, atol=1e-4)
    assert abs(ls[0, 0, 0] - 0.9) > 0.1
    mid = fits[0.05]
    assert fits[0.0].cost_ < mid.cost_ < fits[1e6].cost_
    assert fits[1e6].one_step_cost_ < mid.one_step_cost_ < fits[0.0].one_step_cost_


def _linear_problem(seed: int = 0):
    """A least-squares cost ‖A x − b‖² / n as (cost, JᵀJ, Jᵀr): its minimiser is lstsq's."""
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(200, 3)), rng.normal(size=200)

    def cost(x, sensitivities):
        r = a @ x.ravel() - b
        return (float(r @ r) / len(b), a.T @ a if sensitivities else None,
                a.T @ r if sensitivities else None)

    return cost, np.linalg.lstsq(a, b, rcond=None)[0]


def test_levenberg_marquardt_reaches_the_least_squares_minimum_and_keeps_the_shape():
    cost, best = _linear_problem()
    x0 = np.zeros((3, 1))
    res = levenberg_marquardt(x0, cost, max_iter=50, tol=1e-12)
    assert res.thetas.shape == x0.shape
    np.testing.assert_allclose(res.thetas.ravel(), best, rtol=1e-6)
    assert res.cost < res.cost_start and res.cost == pytest.approx(cost(best, False)[0])
    assert np.isnan(res.validation_start) and np.isnan(res.validation_cost)


def test_the_held_out_cost_chooses_the_iterate_and_stops_the_search():
    """A held-out cost lowest at the start: the start is kept, and the search stops after
    ``patience`` accepted steps without a new lowest."""
    cost, _ = _linear_problem()
    x0 = np.zeros((3, 1))
    res = levenberg_marquardt(x0, cost, held=lambda x: float(np.sum(x ** 2)), max_iter=50,
                              patience=2)
    np.testing.assert_array_equal(res.thetas, x0)
    assert res.validation_cost == res.validation_start == 0.0
    assert res.n_iter == 2 and "validation error not lower for 2 steps" in res.stop
    assert res.cost == res.cost_start
