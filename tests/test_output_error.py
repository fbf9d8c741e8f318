"""Simulation-error refinement: its Jacobian against finite differences, consistency under
output noise where least squares is biased, and its place in the estimators."""

import numpy as np
import pytest

from pwa_pipeline import PWARX, LinearARX, make_hure_vasak
from pwa_pipeline.pwa.output_error import OutputErrorRefinement, _Runs, refine_output_error


def _output_noise_system(seed: int, n: int = 3000, sigma: float = 0.5):
    """y(k) = 0.9 y(k−1) + 0.5 u(k−1), measured with white noise: an output-error system."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 1))
    y = np.zeros((n, 1))
    for k in range(1, n):
        y[k] = 0.9 * y[k - 1] + 0.5 * u[k - 1]
    return u, y + sigma * rng.normal(size=y.shape)


def test_the_propagated_jacobian_matches_finite_differences_with_regions():
    data = make_hure_vasak(n_samples=600, seed=2)
    model = PWARX(na=2, nb=1).fit(data.u, data.y)
    runs = _Runs([data.u[:300], data.u[300:]], [data.y[:300], data.y[300:]], 2, 1, False, 2)
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


def test_refinement_removes_the_least_squares_bias_under_output_noise():
    u, y = _output_noise_system(seed=5)
    ls = LinearARX(1, 1).fit(u, y)
    oe = LinearARX(1, 1, refinement=OutputErrorRefinement(max_iter=50)).fit(u, y)
    truth = np.array([0.9, 0.5])
    assert abs(ls.theta_[0, 0] - 0.9) > 0.1  # equation error is biased here
    np.testing.assert_allclose(oe.theta_.ravel(), truth, atol=0.02)
    assert oe.refinement_.cost_ < oe.refinement_.cost_start_


def test_pwarx_refinement_keeps_regions_and_lowers_the_training_free_run_error():
    data = make_hure_vasak(n_samples=1500, seed=4)
    plain = PWARX(na=1, nb=1).fit(data.u, data.y)
    refined = PWARX(na=1, nb=1, refinement=OutputErrorRefinement(max_iter=5)).fit(
        data.u, data.y)
    np.testing.assert_array_equal(refined.base_thetas(), plain.thetas_)  # step 6's θ_i
    np.testing.assert_array_equal(refined.regions_.coef_, plain.regions_.coef_)
    assert refined.refinement_.cost_ < refined.refinement_.cost_start_
    assert np.abs(refined.thetas_ - plain.thetas_).max() > 0
    assert refined.resolved_params()["refinement__max_iter"] == 5
    assert "refinement" in refined.timings_


def test_a_diverging_start_is_refused_with_its_reason():
    u, y = _output_noise_system(seed=1, n=2000)  # 1.5^2000 overflows
    with pytest.raises(ValueError, match="starting model's free run diverges"):
        refine_output_error(np.array([[[1.5], [0.5]]]), [u], [y], 1, 1, False)


def test_the_pipeline_refines_pwa_and_linear_arx_when_the_set_asks(tmp_path, mlflow_template):
    import shutil

    import dagster as dg

    from pwa_pipeline.orchestration.definitions import build_definitions
    from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
    from pwa_pipeline.orchestration.settings import PipelineSettings
    from pwa_pipeline.orchestration.tracking import MLflowTracker

    path = tmp_path / "oe.toml"
    path.write_text('[oe.hure_vasak]\npreset = "default"\nna = 1\nnb = 1\n'
                    'refinement.max_iter = 3\n')
    defs = build_definitions(path, tmp_path / "datasets.json")
    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    resources = {"io_manager": PartitionedFileIOManager(base_dir=str(tmp_path / "storage")),
                 "settings": PipelineSettings(cache_dir=str(tmp_path / "cache")).with_files(
                     path, tmp_path / "datasets.json"),
                 "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{db}")}
    result = dg.materialize([a for a in defs.assets if a.partitions_def is not None],
                            partition_key="hure_vasak|oe", resources=resources)
    step = result.output_for_node("output_error_refinement")
    model = result.output_for_node("pwa_model")
    # the start (step 6's θ_i, refitted with the regions) may already be the best iterate on
    # the held-out experiments: the refinement then keeps it
    assert step.n_iter_ == 3 and step.cost_ <= step.cost_start_
    np.testing.assert_array_equal(model.thetas_, step.thetas_)
    assert np.abs(model.thetas_ - result.output_for_node("sub_models").thetas_).max() > 0
    linear = result.output_for_node("linear_arx_model")
    assert linear.refinement_.n_iter_ >= 1
    meta = result.asset_materializations_for_node("output_error_refinement")[0].metadata
    assert meta["refined"].value is True and meta["iterations"].value == 3


def test_validation_experiments_choose_the_iterate_and_are_not_fitted():
    u, y = _output_noise_system(seed=9, n=2500)
    us, ys = np.array_split(u, 5), np.array_split(y, 5)
    step = OutputErrorRefinement(max_iter=30, validation_fraction=0.2, warmup=1)
    ls = LinearARX(1, 1).fit(us[:4], ys[:4])
    step.fit(ls.theta_[None], us, ys, 1, 1, False)
    assert step.validation_experiments_ == [4]
    held = _Runs([us[4]], [ys[4]], 1, 1, False, 1)
    assert held.simulate(step.thetas_, None, False)[0] == pytest.approx(step.validation_cost_)
    assert step.validation_cost_ < step.validation_cost_start_
    fitted = _Runs(us[:4], ys[:4], 1, 1, False, 1)  # the cost is over the other four only
    assert fitted.simulate(step.thetas_, None, False)[0] == pytest.approx(step.cost_)


def _weighted_objective(route: str):
    """The errors of a refinement problem, its start, a point away from it and the start
    model's one-step error: the level route (a PWARX with regions, two outputs) or the
    structured one (velocity form, sign regions)."""
    from pwa_pipeline.pwa.output_error import _Errors, _OneStep, _OutputRuns
    from pwa_pipeline.pwa.scheduling import SignScheduling

    data = make_hure_vasak(n_samples=600, seed=2)
    u, y = [data.u[:300], data.u[300:]], [data.y[:300], data.y[300:]]
    rng = np.random.default_rng(0)
    if route == "level":
        model = PWARX(na=2, nb=1).fit(data.u, data.y)
        runs = _Runs(u, y, 2, 1, False, 2)
        x0 = model.thetas_
        errors = _Errors(lambda t, s: runs.simulate(t, model.regions_.predict, s),
                         runs.n_scored,
                         _OneStep.of_thetas(u, y, 2, 1, False, model.regions_.predict, x0.shape))
    else:
        model = PWARX(na=1, nb=1, affine=True, form="velocity", outputs="decoupled",
                      scheduling=SignScheduling(switch="all")).fit(u, y)
        outputs = dict(enumerate(model.structure_.outputs))
        runs = _OutputRuns(u, y, 2, 1, True, 2, outputs, [0, 1])
        x0 = np.concatenate([o.p for o in outputs.values()])
        errors = _Errors(runs.simulate, runs.n_scored,
                         _OneStep.of_outputs(u, y, 2, 1, True, outputs, [0, 1]))
    # the model's own one-step predictions on the measured regressors, for J1(θ0)
    from pwa_pipeline.pwa.regressors import build_regressors
    reg = build_regressors(list(zip(u, y, strict=True)), 2, 1, route != "level")
    if route == "level":
        predicted = np.einsum("nd,ndm->nm", reg.phi, x0[model.regions_.predict(reg.phi)])
    else:
        predicted = model.structure_.predict_phi(reg.phi)
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


def test_the_one_step_weight_trades_free_run_error_for_one_step_error():
    """Under output noise least squares (the minimum of the one-step error) is biased and the
    free-run refinement is not: 0 is the free-run refinement itself, a large weight keeps the
    least-squares parameters, and weights between trade one error for the other."""
    from pwa_pipeline.pwa.output_error import levenberg_marquardt

    u, y = _output_noise_system(seed=5)
    ls = LinearARX(1, 1).fit(u, y).theta_[None]
    fits = {w: OutputErrorRefinement(max_iter=50, validation_fraction=0, one_step_weight=w)
            .fit(ls, [u], [y], 1, 1, False) for w in (0.0, 0.05, 1e6)}
    runs = _Runs([u], [y], 1, 1, False, 10)
    plain = levenberg_marquardt(ls, lambda t, s: runs.simulate(t, None, s), max_iter=50)
    np.testing.assert_array_equal(fits[0.0].thetas_, plain.thetas)
    np.testing.assert_allclose(fits[0.0].thetas_.ravel(), [0.9, 0.5], atol=0.02)
    np.testing.assert_allclose(fits[1e6].thetas_, ls, atol=1e-4)
    assert abs(ls[0, 0, 0] - 0.9) > 0.1
    mid = fits[0.05]
    assert fits[0.0].cost_ < mid.cost_ < fits[1e6].cost_
    assert fits[1e6].one_step_cost_ < mid.one_step_cost_ < fits[0.0].one_step_cost_


def test_the_structured_route_passes_the_one_step_weight():
    """Velocity form under output noise: a large weight keeps each output's least squares on
    the fitting experiments (the first four; the fifth is held out)."""
    from pwa_pipeline.pwa.scheduling import SignScheduling

    rng = np.random.default_rng(4)
    us = [rng.normal(size=(400, 1)) for _ in range(5)]
    ys = []
    for ue in us:
        clean = np.zeros(400)
        for k in range(2, 400):
            clean[k] = clean[k - 1] + 0.7 * (clean[k - 1] - clean[k - 2]) + 0.5 * ue[k - 1, 0]
        ys.append((clean + 0.5 * rng.normal(size=400))[:, None])
    kw = {"na": 1, "nb": 1, "affine": True, "form": "velocity", "outputs": "decoupled"}

    def refined(w):
        step = OutputErrorRefinement(max_iter=30, one_step_weight=w, validation_fraction=0.2)
        model = PWARX(**kw, scheduling=SignScheduling(switch="offset"), refinement=step)
        return model.fit(us, ys).structure_fit_

    far, kept = refined(0.0), refined(1e6)
    offset_ls = PWARX(**kw, scheduling=SignScheduling(switch="offset")).fit(us[:4], ys[:4])
    np.testing.assert_allclose(kept.model.outputs[0].p, offset_ls.structure_.outputs[0].p,
                               atol=1e-4)
    assert np.abs(far.model.outputs[0].p - offset_ls.structure_.outputs[0].p).max() > 0.05
    assert kept.refinement[0]["one_step"] == pytest.approx(kept.refinement[0]["one_step_start"],
                                                           rel=1e-6)
    assert far.refinement[0]["one_step"] > far.refinement[0]["one_step_start"]


def test_a_negative_one_step_weight_is_refused():
    from sklearn.utils._param_validation import InvalidParameterError

    u, y = _output_noise_system(seed=1, n=200)
    step = OutputErrorRefinement(one_step_weight=-1.0)
    for kw in ({}, {"form": "velocity", "outputs": "decoupled"}):
        with pytest.raises(InvalidParameterError, match="'one_step_weight' parameter"):
            LinearARX(1, 1, refinement=step, **kw).fit(u, y)


def test_the_warm_up_covers_the_lags_and_none_means_the_lags_alone():
    assert OutputErrorRefinement(warmup=None).run_warmup(2, 3) == 3
    assert OutputErrorRefinement(warmup=10).run_warmup(2, 3) == 10
    assert OutputErrorRefinement(warmup=1).run_warmup(3, 2) == 3
