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
    from pwa_pipeline.orchestration.resources import MLflowTracker, PipelineSettings
    from pwa_pipeline.orchestration.storage import PartitionedFileIOManager

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
