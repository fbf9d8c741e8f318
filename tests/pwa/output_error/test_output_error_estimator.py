"""The output-error refinement step and its place in the estimators and the pipeline
(pwa.output_error.estimator)."""

import numpy as np
import pytest

from pwa_pipeline import PWARX, LinearARX, make_hure_vasak
from pwa_pipeline.pwa.output_error import OutputErrorRefinement
from pwa_pipeline.pwa.output_error.simulator import FreeRuns

from ..._output_error_cases import _output_noise_system
from ..._results import materialization


def test_refinement_removes_the_least_squares_bias_under_output_noise():
    u, y = _output_noise_system(seed=5)
    ls = LinearARX(1, 1).fit(u, y)
    oe = LinearARX(1, 1, refinement=OutputErrorRefinement(max_iter=50)).fit(u, y)
    truth = np.array([0.9, 0.5])
    assert abs(ls.theta_[0, 0] - 0.9) > 0.1  # equation error is biased here
    np.testing.assert_allclose(oe.theta_.ravel(), truth, atol=0.02)
    assert oe.steps_["refinement"].cost_ < oe.steps_["refinement"].cost_start_


def test_pwarx_refinement_keeps_regions_and_lowers_the_training_free_run_error():
    data = make_hure_vasak(n_samples=1500, seed=4)
    plain = PWARX(na=1, nb=1).fit(data.u_train[0], data.y_train[0])
    refined = PWARX(na=1, nb=1, refinement=OutputErrorRefinement(max_iter=5)).fit(
        data.u_train[0], data.y_train[0])
    np.testing.assert_array_equal(refined.steps_["regions"].thetas_, plain.thetas_)  # step 6's
    np.testing.assert_array_equal(refined.regions_.coef_, plain.regions_.coef_)
    assert refined.steps_["refinement"].cost_ < refined.steps_["refinement"].cost_start_
    assert np.abs(refined.thetas_ - plain.thetas_).max() > 0
    assert refined.resolved_params()["refinement__max_iter"] == 5
    assert "refinement" in refined.timings_


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
    step = result.asset_value("output_error_refinement")
    model = result.asset_value("pwa_model")
    # the start (step 6's θ_i, refitted with the regions) may already be the best iterate on
    # the held-out experiments: the refinement then keeps it
    assert step.n_iter_ == 3 and step.cost_ <= step.cost_start_
    np.testing.assert_array_equal(model.thetas_, step.thetas_)
    assert np.abs(model.thetas_ - result.asset_value("sub_models").thetas_).max() > 0
    linear = result.asset_value("linear_arx_model")
    assert linear.steps_["refinement"].n_iter_ >= 1
    meta = materialization(result, "output_error_refinement").metadata
    assert meta["fitted"].value is True and meta["iterations"].value == 3


def test_validation_experiments_choose_the_iterate_and_are_not_fitted():
    u, y = _output_noise_system(seed=9, n=2500)
    us, ys = np.array_split(u, 5), np.array_split(y, 5)
    step = OutputErrorRefinement(max_iter=30, validation_fraction=0.2, warmup=1)
    ls = LinearARX(1, 1).fit(us[:4], ys[:4])
    step.fit(ls.theta_[None], us, ys, 1, 1, False)
    assert step.validation_experiments_ == [4]
    held = FreeRuns([us[4]], [ys[4]], 1, 1, False, 1)
    assert held.simulate(step.thetas_, None, False)[0] == pytest.approx(step.validation_cost_)
    assert step.validation_cost_ < step.validation_cost_start_
    fitted = FreeRuns(us[:4], ys[:4], 1, 1, False, 1)  # the cost is over the other four only
    assert fitted.simulate(step.thetas_, None, False)[0] == pytest.approx(step.cost_)


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
    least_squares = offset_ls.structure_fit_.outputs[0].p
    np.testing.assert_allclose(kept.outputs[0].p, least_squares, atol=1e-4)
    assert np.abs(far.outputs[0].p - least_squares).max() > 0.05
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
