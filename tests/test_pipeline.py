"""The Dagster layer: definitions, materialisation, MLflow tracking, schedule, storage."""

import shutil

import dagster as dg
import pandas as pd
import pytest

from pwa_pipeline.definitions import defs
from pwa_pipeline.pipeline.assets import ASSETS
from pwa_pipeline.pipeline.partitions import all_keys, split_key
from pwa_pipeline.pipeline.resources import MLflowTracker, PipelineConfig
from pwa_pipeline.pipeline.schedules import sweep_schedule
from pwa_pipeline.pipeline.storage import PartitionedFileIOManager, atomic_write


@pytest.fixture(scope="session")
def mlflow_template(tmp_path_factory):
    """An MLflow sqlite store migrated once (it takes seconds), copied by each test."""
    from mlflow.tracking import MlflowClient

    path = tmp_path_factory.mktemp("mlflow") / "template.db"
    MlflowClient(tracking_uri=f"sqlite:///{path}").search_experiments()
    return path


@pytest.fixture()
def resources(tmp_path, mlflow_template):
    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    return {
        "io_manager": PartitionedFileIOManager(base_dir=str(tmp_path / "storage")),
        "config": PipelineConfig(cache_dir=str(tmp_path / "cache")),
        "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{db}"),
    }


def _runs(resources, dataset):
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri=resources["mlflow"].tracking_uri)
    exp = client.get_experiment_by_name(f"pwa-pipeline/{dataset}")
    return client, client.search_runs([exp.experiment_id])


def test_definitions_load():
    repo = defs.get_repository_def()
    keys = {k.to_user_string() for k in repo.asset_graph.get_all_asset_keys()}
    assert {"raw_benchmark", "regressors", "local_models", "clusters", "sub_models",
            "svm_regions", "validation_metrics", "subspace_baseline", "comparison"} <= keys
    assert repo.get_job("sweep") is not None
    assert repo.get_schedule_def("sweep_schedule").default_status == dg.DefaultScheduleStatus.STOPPED


def test_schedule_requests_every_partition_once():
    ctx = dg.build_schedule_context(scheduled_execution_time=pd.Timestamp("2026-11-21T02:00"))
    requests = list(sweep_schedule(ctx))
    assert sorted(r.partition_key for r in requests) == sorted(all_keys())
    assert len({r.run_key for r in requests}) == len(requests) == len(all_keys())
    assert "hure_vasak|paper" in all_keys() and "kuka_robot|default" in all_keys()


def test_partition_keys_parse_and_reject_typos():
    assert split_key("kuka_robot|paper") == ("kuka_robot", "paper")
    with pytest.raises(ValueError, match="unknown partition 'kuka|paper'"):
        split_key("kuka|paper")


def test_materialise_hure_vasak_paper(resources, tmp_path):
    result = dg.materialize(ASSETS, partition_key="hure_vasak|paper", resources=resources)
    assert result.success
    subs = result.output_for_node("sub_models")
    assert subs.thetas.shape == (2, 4, 2)  # the paper's setting finds 2 of the 4 modes
    table = result.output_for_node("comparison")
    assert set(table["method"]) == {"pwa", "linear_arx", "subspace"}
    assert len(table) == 3 * 2 * 3  # methods × modes × (2 outputs + mean)
    checks = {e.check_name: e.passed for e in result.get_asset_check_evaluations()}
    assert checks["finite_parameters"] and checks["at_least_one_sub_model"]
    assert checks["noise_share_below_limit"]
    # files written and read back
    stored = pd.read_parquet(tmp_path / "storage" / "comparison" / "hure_vasak" / "paper.parquet")
    pd.testing.assert_frame_equal(stored, table)
    assert (tmp_path / "storage" / "sub_models" / "hure_vasak" / "paper.pkl").is_file()
    # MLflow: one run per method with params, metrics, tags and artifacts
    client, runs = _runs(resources, "hure_vasak")
    assert sorted(r.data.tags["method"] for r in runs) == ["linear_arx", "pwa", "subspace"]
    pwa = next(r for r in runs if r.data.tags["method"] == "pwa")
    assert pwa.data.params["n_rho"] == "18" and pwa.data.params["eps"] == "0.1"
    assert pwa.data.tags["partition"] == "hure_vasak|paper"
    assert pwa.data.tags["dagster_run_id"] == result.run_id
    assert pwa.data.metrics["n_submodels"] == 2
    free = table[(table.method == "pwa") & (table["mode"] == "free_run") & (table.output == "mean")]
    assert pwa.data.metrics["free_run_nrmse_mean"] == pytest.approx(free["nrmse"].iloc[0])
    assert {a.path for a in client.list_artifacts(pwa.info.run_id)} == {
        "parameter_matrices.json", "scores.csv", "prediction.png"}
    meta = result.asset_materializations_for_node("validation_metrics")[0].metadata
    assert meta["mlflow_run_id"].value == pwa.info.run_id


def test_local_models_are_reused_when_only_eps_changes(resources):
    first = dg.materialize(ASSETS[:3], partition_key="hure_vasak|paper", resources=resources)
    again = dg.materialize(ASSETS[:3], partition_key="hure_vasak|paper", resources=resources)
    meta = [r.asset_materializations_for_node("local_models")[0].metadata for r in (first, again)]
    assert not meta[0]["from_cache"].value and meta[1]["from_cache"].value
    assert meta[0]["cache_key"].value == meta[1]["cache_key"].value


def test_unreachable_tracking_server_fails_clearly_and_keeps_assets(resources, tmp_path):
    resources["mlflow"] = MLflowTracker(tracking_uri="http://127.0.0.1:9", timeout_seconds=1)
    result = dg.materialize(ASSETS, partition_key="hure_vasak|default", resources=resources,
                            raise_on_error=False)
    assert not result.success
    failures = [e for e in result.all_events if e.event_type_value == "STEP_FAILURE"]
    messages = " ".join(str(e.event_specific_data.error) for e in failures)
    assert "MLflow tracking server http://127.0.0.1:9 cannot be reached" in messages
    assert "already materialised are kept" in messages
    # the identification steps before tracking are materialised and stay on disk
    done = {e.asset_key.to_user_string() for e in result.get_asset_materialization_events()}
    assert {"regressors", "local_models", "clusters", "sub_models", "svm_regions"} <= done
    assert (tmp_path / "storage" / "svm_regions" / "hure_vasak" / "default.pkl").is_file()


def test_atomic_write_keeps_the_old_file_when_a_write_fails(tmp_path):
    path = tmp_path / "a.parquet"
    atomic_write(path, lambda p: p.write_text("old"))

    def broken(p):
        p.write_text("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        atomic_write(path, broken)
    assert path.read_text() == "old"
    assert [f.name for f in tmp_path.iterdir()] == ["a.parquet"]


def test_materialise_kuka_robot(resources, robot):
    result = dg.materialize(ASSETS, partition_key="kuka_robot|default", resources=resources)
    assert result.success
    data = result.output_for_node("raw_benchmark")
    assert data.n_train == 39988 and len(data.u_test) == 6
    table = result.output_for_node("comparison")
    one_step = table[(table["mode"] == "one_step") & (table.output == "mean")]
    assert (one_step["nrmse"] < 0.05).all()  # one-step prediction of 10 Hz positions is easy
    _, runs = _runs(resources, "kuka_robot")
    assert len(runs) == 3
