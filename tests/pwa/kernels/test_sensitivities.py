"""The compiled free run and sensitivities of the output-error refinement equal its numpy
loop."""

import numpy as np
import pytest

from pwa_pipeline.pwa.output_error import OutputFreeRuns
from pwa_pipeline.pwa.output_error.simulator import BLOCK

from .test_free_run import _experiments, _model, tight_limits


@pytest.mark.parametrize("n_vars, form, simulated, limited",
                         [((0, 0), "level", [0, 1], False), ((1, 2), "level", [0, 1], False),
                          ((2, 0), "velocity", [1], False), ((3, 1), "level", [0], False),
                          ((-3, -2), "level", [0, 1], False), ((1, -2), "level", [0, 1], False),
                          ((0, 0), "level", [0, 1], True), ((1, -2), "level", [0, 1], True)])
def test_the_compiled_sensitivities_equal_the_numpy_loop(n_vars, form, simulated, limited):
    lags, nb = 3, 2
    experiments = _experiments(0, lengths=(120, 90, BLOCK + 150))  # a run past one block
    u, y = [e[0] for e in experiments], [e[1] for e in experiments]
    rng = np.random.default_rng(1)
    models = {j: _model(j, lags, nb, n_vars[j], rng, scale=0.1, form=form) for j in (0, 1)}
    limits = tight_limits(experiments) if limited else None
    runs = OutputFreeRuns(u, y, lags, nb, True, 5, models, simulated, limits)
    p = np.concatenate([models[j].p for j in simulated])
    thetas = [models[j].thetas(p[a:b]) for j, a, b in
              zip(simulated, runs.offsets[:-1], runs.offsets[1:], strict=True)]
    assert runs.kernel is not None  # these regions compile
    cost, jtj, jtr = runs._compiled(thetas, True)
    ref_cost, ref_jtj, ref_jtr = runs._looped(thetas, True)
    assert 0 < ref_cost < 1e3 and np.linalg.matrix_rank(ref_jtj) > 0
    np.testing.assert_allclose(cost, ref_cost, rtol=1e-10)
    np.testing.assert_allclose(jtj, ref_jtj, rtol=1e-8, atol=1e-10 * np.abs(ref_jtj).max())
    np.testing.assert_allclose(jtr, ref_jtr, rtol=1e-8, atol=1e-10 * np.abs(ref_jtr).max())
    assert runs.simulate(p, False)[0] == pytest.approx(ref_cost, rel=1e-10)


def test_a_diverging_refinement_run_is_inf_in_both():
    lags, nb = 3, 2
    experiments = _experiments(2)
    u, y = [e[0] for e in experiments], [e[1] for e in experiments]
    rng = np.random.default_rng(3)
    models = {j: _model(j, lags, nb, 1, rng, scale=50.0) for j in (0, 1)}
    runs = OutputFreeRuns(u, y, lags, nb, True, 5, models, [0, 1])
    thetas = [models[j].thetas() for j in (0, 1)]
    assert runs._compiled(thetas, True) == (np.inf, None, None)
    assert runs._looped(thetas, True) == (np.inf, None, None)


def test_the_sensitivities_under_limits_are_the_gradient_of_the_cost():
    """Jᵀr is half the gradient of the summed squared free-run error, also where outputs sit
    at their limits (their sensitivities 0 there), by central differences."""
    lags, nb = 3, 2
    experiments = _experiments(4)
    u, y = [e[0] for e in experiments], [e[1] for e in experiments]
    rng = np.random.default_rng(5)
    models = {j: _model(j, lags, nb, 0, rng, scale=0.1) for j in (0, 1)}
    runs = OutputFreeRuns(u, y, lags, nb, True, 5, models, [0, 1],
                          tight_limits(experiments))
    p = np.concatenate([models[j].p for j in (0, 1)])
    _, _, jtr = runs.simulate(p, True)
    h = 1e-6
    numeric = np.array([(runs.simulate(p + h * e, False)[0]
                         - runs.simulate(p - h * e, False)[0]) / (2 * h)
                        for e in np.eye(len(p))]) * runs.n_scored / 2
    np.testing.assert_allclose(jtr, numeric, rtol=1e-4, atol=1e-6 * np.abs(numeric).max())
