"""The free run and its propagated sensitivities (pwa.output_error.simulator)."""

import numpy as np
import pytest

from pwa_pipeline import PWARX, make_hure_vasak
from pwa_pipeline.pwa.output_error.simulator import FreeRuns


def test_the_propagated_jacobian_matches_finite_differences_with_regions():
    data = make_hure_vasak(n_samples=600, seed=2)
    model = PWARX(na=2, nb=1).fit(data.u_train[0], data.y_train[0])
    runs = FreeRuns([data.u_train[0][:300], data.u_train[0][300:]], [data.y_train[0][:300],
                                                                     data.y_train[0][300:]], 2, 1, False, 2)
    theta = model.thetas_
    cost, _, jtr = runs.simulate(theta, model.regions_.predict, sensitivities=True)
    gradient = 2 * jtr / runs.n_scored
    step, fd = 1e-7, np.zeros(theta.size)
    for i in range(theta.size):
        moved = theta.ravel().copy()
        moved[i] += step
        fd[i] = (runs.simulate(moved.reshape(theta.shape), model.regions_.predict, False)[0]
                 - cost) / step
    # a region switch inside the step would break this; none happens at 1e-7
    np.testing.assert_allclose(fd, gradient, atol=1e-4 * np.abs(gradient).max())


def _free_run_loop(theta, region_of, u, y, warmup):
    """The free run of eq. (1) written out sample by sample (na = 2, nb = 1, two outputs):
    the reference FreeRuns.simulate must match."""
    ysim = y.copy()
    total, count = 0.0, 0
    for k in range(warmup, len(y)):
        phi = np.concatenate([ysim[k - 1::-1][:2].T.ravel(), u[k - 1]])
        yk = phi @ theta[region_of(phi[None])[0]]
        ysim[k] = yk
        total += float(np.sum((yk - y[k]) ** 2))
        count += y.shape[1]
    return total, count


def test_the_free_run_of_experiments_of_unequal_length_is_the_loop_over_each():
    """Experiments of different lengths simulated in lockstep give each one's own free run:
    the cost is the sum over both written-out loops per scored sample and output."""
    data = make_hure_vasak(n_samples=700, seed=3)
    model = PWARX(na=2, nb=1).fit(data.u_train[0], data.y_train[0])
    u, y = [data.u_train[0][:400], data.u_train[0][400:]], [data.y_train[0][:400], data.y_train[0][400:]]
    runs = FreeRuns(u, y, 2, 1, False, 5)
    cost, jtj, jtr = runs.simulate(model.thetas_, model.regions_.predict, False)
    assert jtj is None and jtr is None
    loops = [_free_run_loop(model.thetas_, model.regions_.predict, ue, ye, 5)
             for ue, ye in zip(u, y)]
    assert runs.n_scored == sum(c for _, c in loops) == (395 + 295) * 2
    assert cost == pytest.approx(sum(t for t, _ in loops) / runs.n_scored, rel=1e-12)


def test_a_diverging_free_run_costs_inf_and_gives_no_normal_equations():
    rng = np.random.default_rng(0)
    u, y = rng.normal(size=(3000, 1)), rng.normal(size=(3000, 1))
    runs = FreeRuns([u], [y], 1, 1, False, 1)
    assert runs.simulate(np.array([[[1.5], [0.5]]]), None, True) == (np.inf, None, None)
    cost, jtj, jtr = runs.simulate(np.array([[[0.5], [0.5]]]), None, True)
    assert np.isfinite(cost) and jtj.shape == (2, 2) and jtr.shape == (2,)
