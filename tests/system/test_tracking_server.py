"""A real MLflow tracking server (``mlflow server`` on a loopback port, artifacts proxied by
the server): a partition's runs, metrics, figures and registered models land there; a server
that stops between the fits and the tracking fails the run with one clear message and keeps
the asset store, and a rerun against the restarted server completes."""

import os
import signal
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import dagster as dg

from benchmarks._ui import free_port
from pwa_pipeline.config import BUNDLED_HPARAMS
from pwa_pipeline.definitions import defs
from pwa_pipeline.methods import METHODS
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.settings import PipelineSettings
from pwa_pipeline.orchestration.tracking import MLflowTracker

PARTITION = "hure_vasak|paper"
ASSETS = [a for a in defs.assets if a.partitions_def is not None]
SCORES = [f"{m}_scores" for m in METHODS]


@contextmanager
def mlflow_server(folder: Path, port: int) -> Iterator[str]:
    """``mlflow server`` with a sqlite backend in ``folder`` and artifacts it serves itself
    (``--serve-artifacts``), one worker; its URL once ``/health`` answers. Ended, process group
    and all, on the way out."""
    env = {**os.environ, "MLFLOW_SERVER_ENABLE_JOB_EXECUTION": "false"}
    env.pop("MLFLOW_TRACKING_URI", None)
    with open(folder / f"server-{port}.log", "ab") as log:
        server = subprocess.Popen(
            [sys.executable, "-m", "mlflow", "server", "--backend-store-uri",
             f"sqlite:///{folder / 'mlflow.db'}", "--serve-artifacts",
             "--artifacts-destination", str(folder / "artifacts"), "--host", "127.0.0.1",
             "--port", str(port), "--workers", "1"],
            env=env, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.time() + 120
        while True:
            try:
                with urllib.request.urlopen(f"{url}/health", timeout=2) as answer:
                    if answer.status == 200:
                        break
            except OSError:
                pass
            assert server.poll() is None and time.time() < deadline, \
                (folder / f"server-{port}.log").read_text()[-3000:]
            time.sleep(0.5)
        yield url
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
            server.wait()


def _resources(folder: Path, url: str) -> dict:
    return {"io_manager": PartitionedFileIOManager(base_dir=str(folder / "storage")),
            "settings": PipelineSettings(cache_dir=str(folder / "cache"),
                                         hparams_path=str(BUNDLED_HPARAMS)),
            "mlflow": MLflowTracker(tracking_uri=url, timeout_seconds=2, request_timeout=5,
                                    request_retries=1)}


def test_a_partition_is_tracked_on_a_real_server(tmp_path, monkeypatch, capsys):
    from mlflow.tracking import MlflowClient

    from pwa_pipeline.orchestration.cli import main

    with mlflow_server(tmp_path, free_port()) as url:
        result = dg.materialize(ASSETS, partition_key=PARTITION,
                                resources=_resources(tmp_path, url))
        assert result.success
        client = MlflowClient(tracking_uri=url)
        experiment = client.get_experiment_by_name("pwa-pipeline/hure_vasak")
        assert experiment.artifact_location.startswith("mlflow-artifacts:")  # proxied
        runs = client.search_runs([experiment.experiment_id])
        assert sorted(r.data.tags["method"] for r in runs) == sorted(METHODS)
        for run in runs:
            assert run.info.status == "FINISHED"
            assert run.data.metrics["per_output/free_run_nrmse_y1"] > 0
            names = {a.path for a in client.list_artifacts(run.info.run_id)}
            assert {"scores.csv", "prediction.png"} <= names, names
        models = {m.name for m in client.search_registered_models()}
        assert models == {f"pwa-pipeline.hure_vasak.{m}" for m in METHODS}
        # doctor reads the same server: nothing left behind
        monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
        assert main(["doctor", "--tracking-uri", url]) == 0
        assert "MLflow runs still RUNNING  : none" in capsys.readouterr().out
    # the artifacts are on the server's side only
    assert list((tmp_path / "artifacts").rglob("prediction.png"))


def test_a_server_stopped_before_tracking_fails_clearly_keeps_the_store_and_a_rerun_completes(
        tmp_path):
    port = free_port()
    with mlflow_server(tmp_path, port) as url:
        resources = _resources(tmp_path, url)
        fits = dg.AssetSelection.all() - dg.AssetSelection.assets(*SCORES, "comparison")
        assert dg.materialize(ASSETS, selection=fits, partition_key=PARTITION,
                              resources=resources).success
    # the server is gone: the scores fail at once, naming it, and nothing stored is lost
    t0 = time.perf_counter()
    failed = dg.materialize(ASSETS, partition_key=PARTITION, resources=resources,
                            selection=SCORES, raise_on_error=False)
    assert not failed.success and time.perf_counter() - t0 < 30
    messages = " ".join(str(e.event_specific_data.error) for e in failed.all_events
                        if e.event_type_value == "STEP_FAILURE")
    assert f"MLflow tracking server {url} cannot be reached" in messages
    assert "already materialised are kept" in messages
    store = resources["io_manager"]
    assert store.load(dg.AssetKey("pwa_model"), PARTITION).n_submodels_ >= 1
    # the same server back on the same store: the rerun completes
    with mlflow_server(tmp_path, port) as url:
        again = dg.materialize(ASSETS, partition_key=PARTITION, resources=resources,
                               selection=SCORES + ["comparison"])
        assert again.success
