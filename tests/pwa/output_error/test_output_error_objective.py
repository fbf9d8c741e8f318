"""The free-run, one-step and weighted costs (pwa.output_error.objective)."""

import numpy as np
import pytest

from pwa_pipeline import PWARX, LinearARX, make_hure_vasak
from pwa_pipeline.pwa.output_error import OutputErrorRefinement
from pwa_pipeline.pwa.output_error.objective import OneStepError, RefinementErrors
from pwa_pipeline.pwa.output_error.simulator import FreeRuns, OutputFreeRuns

from ..._output_error_cases import _output_noise_system


def _weighted_objective(route: str):
    """The errors of a refinement problem, its start, a point away from it and the start
    model's one-step error: the level route (a PWARX with regions, two outputs) or the
    structured one (velocity form, sign regions)."""
    from pwa_pipeline.pwa.scheduling import SignScheduling

    data = make_hure_vasak(n_samples=600, seed=2)
    u, y = [data.u_train[0][:300], data.u_train[0][300:]], [data.y_train[0][:300], data.y_train[0][300:]]
    rng = np.random.default_rng(0)
    if route == "level":
        model = PWARX(na=2, nb=1).fit(data.u_train[0], data.y_train[0])
        runs = FreeRuns(u, y, 2, 1, False, 2)
        x0 = model.thetas_
        errors = RefinementErrors(
            lambda t, s: runs.simulate(t, model.regions_.predict, s), runs.n_scored,
            OneStepError.of_thetas(u, y, 2, 1, False, model.regions_.predict, x0.shape))
    else:
        model = PWARX(na=1, nb=1, affine=True, form="velocity", outputs="decoupled",
                      scheduling=SignScheduling(switch="all")).fit(u, y)
        outputs = dict(enumerate(model.structure_fit_.outputs))
        runs = OutputFreeRuns(u, y, 2, 1, True, 2, outputs, [0, 1])
        x0 = np.concatenate([o.p for o in outputs.values()])
        errors = RefinementErrors(runs.simulate, runs.n_scored,
                                  OneStepError.of_outputs(u, y, 2, 1, True, outputs, [0, 1]))
    # the model's own one-step predictions on the measured regressors, for J1(θ0)
    from pwa_pipeline.regressors import build_regressors
    reg = build_regressors(list(zip(u, y, strict=True)), 2, 1, route != "level")
    predicted = np.vstack([model.predict(ue, ye)[2:] for ue, ye in zip(u, y, strict=True)])
    one_step = np.mean((predicted - reg.target) ** 2)
    return errors, x0, x0 + 0.01 * rng.normal(size=x0.shape), one_step


@pytest.mark.parametrize("route", ["level", "structured"])
def test_the_weighted_objectives_gradient_matches_finite_differences(route):
    errors, x0, x, one_step = _weighted_objective(route)
    assert errors.one_step(x0, False)[0] == pytest.approx(one_step, rel=1e-9)
    objective = errors.weighted(0.5, errors.costs(x0))
    cost, _, jtr = objective(x, True)
    # J_w = J + w·J(θ0)/J1(θ0)·J1, each a mean of squares: its gradient is 2·(the Jᵀr returned)
    ratio = 0.5 * errors.free(x0, False)[0] / errors.one_step(x0, False)[0]
    assert cost == pytest.approx(errors.free(x, False)[0] + ratio * errors.one_step(x, False)[0])
    fd = np.zeros(x.size)
    for i in range(x.size):
        moved = x.ravel().copy()
        moved[i] += 1e-7
        fd[i] = (objective(moved.reshape(x.shape), False)[0] - cost) / 1e-7
    np.testing.assert_allclose(fd, 2 * jtr, atol=1e-4 * np.abs(jtr).max())


def test_the_one_step_error_is_eq_3s_least_squares_residual():
    u, y = _output_noise_system(seed=5)
    ls = LinearARX(1, 1).fit(u, y)
    step = OutputErrorRefinement(max_iter=3, validation_fraction=0).fit(
        ls.theta_[None], [u], [y], 1, 1, False)
    residual = y[1:, 0] - np.column_stack([y[:-1, 0], u[:-1, 0]]) @ ls.theta_[:, 0]
    assert step.one_step_cost_start_ == pytest.approx(np.mean(residual ** 2))
    assert step.one_step_cost_ > step.one_step_cost_start_  # least squares is its minimum
