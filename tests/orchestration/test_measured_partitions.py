"""The measured benchmarks as partitions: offered with the bundled sets, skipped with the
variable to set where their files are not, and scored in their own convention in MLflow."""


import dagster as dg
import numpy as np
import pandas as pd
import pytest

from pwa_pipeline.config import BUNDLED_HPARAMS
from pwa_pipeline.orchestration.definitions import build_definitions, partitions_of
from pwa_pipeline.orchestration.partitions import all_keys, runnable_keys

from ._resources import run_resources


@pytest.fixture()
def tanks_folder(tmp_path):
    """A stand-in for the tanks' official file: a first-order tank, 1024 + 1024 samples."""
    rng = np.random.default_rng(0)
    columns = {}
    for part in ("Est", "Val"):
        u = np.repeat(rng.uniform(1, 6, 64), 16)
        y = np.full(1024, 5.0)
        for k in range(1, 1024):
            y[k] = 0.9 * y[k - 1] + 0.12 * u[k - 1] + 0.3
        columns[f"u{part}"], columns[f"y{part}"] = u, y + 0.01 * rng.standard_normal(1024)
    folder = tmp_path / "tanks"
    folder.mkdir()
    pd.DataFrame({**columns, "Ts": [4.0] + [np.nan] * 1023}).to_csv(
        folder / "dataBenchmark.csv", index=False)
    return folder


def test_the_tanks_are_partitions_scored_in_their_own_convention(
        tmp_path, tanks_folder, monkeypatch, mlflow_template):
    monkeypatch.setenv("PWA_TANKS_DATA", str(tanks_folder))
    monkeypatch.setenv("PWA_EMPS_DATA", str(tmp_path / "nowhere"))
    defs = build_definitions(BUNDLED_HPARAMS, tmp_path / "datasets.json")
    partitions, settings = partitions_of(defs), defs.resources["settings"]
    offered = all_keys(partitions)
    assert {"cascaded_tanks|default", "cascaded_tanks|auto",
            "cascaded_tanks|output_error", "emps|default", "emps|auto",
            "emps|output_error"} <= set(offered)
    keys, skipped = runnable_keys(partitions, settings)
    assert "cascaded_tanks|default" in keys and not any(k.startswith("emps|") for k in keys)
    assert skipped["emps"].startswith("no emps data: ") and "set PWA_EMPS_DATA" in skipped["emps"]
    resources = run_resources(tmp_path, mlflow_template, settings)
    result = dg.materialize(list(defs.assets), partition_key="cascaded_tanks|default",
                            resources=resources)
    assert result.success
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri=resources["mlflow"].tracking_uri)
    (experiment,) = [e for e in client.search_experiments() if "cascaded_tanks" in e.name]
    runs = {run.data.tags.get("method"): run
            for run in client.search_runs([experiment.experiment_id])}
    assert {"pwa", "linear_arx", "subspace"} <= set(runs)
    for run in (runs[m] for m in ("pwa", "linear_arx", "subspace")):
        # a first-order tank with 1 % noise: every model follows it to within noise
        assert 0 < run.data.metrics["benchmark/rmse_V_from_5"] < 0.1, run.data.tags
        assert run.data.params["warmup"] == "5"
        # the headline metrics stay few (as the browser tests require of every run)
        assert len([k for k in run.data.metrics if "/" not in k]) <= 8, run.data.metrics
