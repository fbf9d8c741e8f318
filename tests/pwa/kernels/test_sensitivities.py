"""The compiled free run and sensitivities of the output-error refinement equal its numpy
loop."""

import numpy as np
import pytest

from pwa_pipeline.pwa.output_error import OutputFreeRuns
from pwa_pipeline.pwa.output_error.simulator import BLOCK

from .test_free_run import _experiments, _model


@pytest.mark.parametrize("n_vars, form, simulated",
                         [((0, 0), "level", [0, 1]), ((1, 2), "level", [0, 1]),
                          ((2, 0), "velocity", [1]), ((3, 1), "level", [0]),
                          ((-3, -2), "level", [0, 1]), ((1, -2), "level", [0, 1])])
def test_the_compiled_sensitivities_equal_the_numpy_loop(n_vars, form, simulated):
    lags, nb = 3, 2
    experiments = _experiments(0, lengths=(120, 90, BLOCK + 150))  # a run past one block
    u, y = [e[0] for e in experiments], [e[1] for e in experiments]
    rng = np.random.default_rng(1)
    models = {j: _model(j, lags, nb, n_vars[j], rng, scale=0.1, form=form) for j in (0, 1)}
    runs = OutputFreeRuns(u, y, lags, nb, True, 5, models, simulated)
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
