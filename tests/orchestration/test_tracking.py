"""The MLflow resource: runs logged whole, ended on failure, credentials never shown."""

import base64
import json
import shutil
import sqlite3
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import dagster as dg
import pandas as pd
import pytest

from pwa_pipeline.orchestration.credentials import mask_credentials, split_credentials
from pwa_pipeline.orchestration.tracking import LoggedRun, MLflowTracker

from .._fork_pool import fork_pool


def _log_one(args):
    uri, i = args
    tracker = MLflowTracker(tracking_uri=uri)
    return tracker.log_run(dataset="d", hparams=f"s{i}", method="pwa", params={}, metrics={"m": i},
                           tags={}, artifacts={}).run_id


@pytest.mark.parametrize("fresh", [True, False])
def test_runs_started_at_once_all_log(tmp_path, fresh, mlflow_template):
    from mlflow.tracking import MlflowClient

    db = tmp_path / "mlflow.db"
    if not fresh:
        shutil.copy(mlflow_template, db)
    uri = f"sqlite:///{db}"
    with fork_pool(3) as pool:  # separate processes, no re-import
        ids = pool.map(_log_one, [(uri, i) for i in range(3)])
    client = MlflowClient(tracking_uri=uri)
    exps = [e for e in client.search_experiments() if e.name == "pwa-pipeline/d"]
    assert len(exps) == 1
    runs = client.search_runs([exps[0].experiment_id])
    assert sorted(r.info.run_id for r in runs) == sorted(ids)
    assert {r.info.status for r in runs} == {"FINISHED"}


class _Exploding:
    """A value whose JSON serialisation (``float(self)``) raises ``error``."""

    def __init__(self, error):
        self.error = error

    def __float__(self):
        raise self.error


@pytest.mark.parametrize(("error", "status"), [(KeyboardInterrupt(), "KILLED"),
                                               (RuntimeError("disk full"), "FAILED")])
def test_interrupted_logging_ends_the_run(tmp_path, mlflow_template, error, status):
    from mlflow.tracking import MlflowClient

    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    tracker = MLflowTracker(tracking_uri=f"sqlite:///{db}")
    with pytest.raises(type(error)):
        tracker.log_run(dataset="d", hparams="s", method="pwa", params={"n_rho": 61},
                        metrics={"nrmse": 0.25}, tags={"partition": "d|s"},
                        artifacts={"f.json": {"x": _Exploding(error)}})
    client = MlflowClient(tracking_uri=f"sqlite:///{db}")
    exp = client.get_experiment_by_name("pwa-pipeline/d")
    [run] = client.search_runs([exp.experiment_id])
    assert run.info.status == status
    # the scores computed before the failure are kept
    assert run.data.metrics == {"nrmse": 0.25}
    assert run.data.params == {"method": "pwa", "n_rho": "61"}
    assert run.data.tags["partition"] == "d|s" and "latest" not in run.data.tags


def test_a_metric_that_is_not_a_number_fails_the_run(tmp_path, mlflow_template):
    from mlflow.tracking import MlflowClient

    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    tracker = MLflowTracker(tracking_uri=f"sqlite:///{db}")
    with pytest.raises(ValueError, match="could not convert"):
        tracker.log_run(dataset="d", hparams="s", method="pwa", params={},
                        metrics={"nrmse": "high"}, tags={}, artifacts={})
    client = MlflowClient(tracking_uri=f"sqlite:///{db}")
    [run] = client.search_runs([client.get_experiment_by_name("pwa-pipeline/d").experiment_id])
    assert run.info.status == "FAILED"


def test_a_finished_run_is_filled_in_one_batch(tmp_path, mlflow_template, monkeypatch):
    import mlflow
    from mlflow.tracking import MlflowClient

    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    batches, stored = [], []
    real = MlflowClient.log_batch
    monkeypatch.setattr(MlflowClient, "log_batch",
                        lambda self, run_id, **kw: batches.append(kw) or real(self, run_id, **kw))
    for name in ("log_artifact", "log_artifacts", "log_text"):  # artifacts: one call for all
        monkeypatch.setattr(MlflowClient, name, lambda self, *a, real=getattr(
            MlflowClient, name), name=name, **kw: stored.append(name) or real(self, *a, **kw))
    tracker = MLflowTracker(tracking_uri=f"sqlite:///{db}")
    artifacts = {"f.json": {"x": 1.5}, "t.csv": pd.DataFrame({"a": [1, 2]}),
                 "n.md": "# n", "p.png": b"\x89PNG\x00"}
    run_id = tracker.log_run(dataset="d", hparams="s", method="pwa", params={"n_rho": 61},
                             metrics={"nrmse": float("inf"), "r2": 0.5},
                             tags={"partition": "d|s"},
                             artifacts=artifacts).run_id
    assert len(batches) == 1 and stored == ["log_artifacts"]
    folder = Path(mlflow.artifacts.download_artifacts(run_id=run_id,
                                                      tracking_uri=f"sqlite:///{db}"))
    assert json.loads((folder / "f.json").read_text()) == {"x": 1.5}
    assert pd.read_csv(folder / "t.csv").equals(artifacts["t.csv"])
    assert (folder / "n.md").read_text() == "# n"
    assert (folder / "p.png").read_bytes() == b"\x89PNG\x00"
    run = MlflowClient(tracking_uri=f"sqlite:///{db}").get_run(run_id)
    assert run.info.status == "FINISHED"
    assert run.data.metrics == {"r2": 0.5}  # a value not finite is left out
    assert run.data.params == {"method": "pwa", "n_rho": "61"}
    assert {k: run.data.tags[k] for k in ("partition", "latest", "method")} == \
        {"partition": "d|s", "latest": "true", "method": "pwa"}


@pytest.mark.parametrize("error", [KeyboardInterrupt(), RuntimeError("disk full")])
def test_a_run_that_cannot_be_marked_ended_keeps_its_own_error(tmp_path, mlflow_template,
                                                               monkeypatch, caplog, error):
    """When marking the broken run fails too (an interrupt inside a sqlite write can leave
    the store locked: `database is locked`), the interrupt or error itself propagates, so
    that Dagster ends the step as interrupted rather than failed on the store; the run is
    left RUNNING for ``doctor --repair``, and a warning says so."""
    from mlflow.exceptions import MlflowException
    from mlflow.tracking import MlflowClient

    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    tracker = MLflowTracker(tracking_uri=f"sqlite:///{db}")

    def locked(self, run_id, status=None, end_time=None):
        if status != "FINISHED":
            raise MlflowException("(sqlite3.OperationalError) database is locked")

    monkeypatch.setattr(MlflowClient, "set_terminated", locked)
    with pytest.raises(type(error)) as raised:
        tracker.log_run(dataset="d", hparams="s", method="pwa", params={}, metrics={},
                        tags={}, artifacts={"f.json": {"x": _Exploding(error)}})
    assert raised.value is error
    monkeypatch.undo()
    client = MlflowClient(tracking_uri=f"sqlite:///{db}")
    [run] = client.search_runs([client.get_experiment_by_name("pwa-pipeline/d").experiment_id])
    assert run.info.status == "RUNNING"
    assert f"MLflow run {run.info.run_id} could not be marked" in caplog.text
    assert "database is locked" in caplog.text and "doctor --repair" in caplog.text


@pytest.mark.parametrize("error", [
    OSError(28, "No space left on device"),
    sqlite3.OperationalError("database or disk is full")])
def test_a_full_disk_fails_the_run_naming_the_store(tmp_path, mlflow_template, error):
    """A full disk under the MLflow store (an OSError naming no file, or sqlite's `database or
    disk is full`): the step fails saying which store and what to do; the run is FAILED."""
    from mlflow.tracking import MlflowClient

    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    tracker = MLflowTracker(tracking_uri=f"sqlite:///{db}")
    with pytest.raises(dg.Failure) as raised:
        tracker.log_run(dataset="d", hparams="s", method="pwa", params={}, metrics={},
                        tags={}, artifacts={"f.json": {"x": _Exploding(error)}})
    assert raised.value.description == (
        f"MLflow store sqlite:///{db} could not be written: {str(error).split('] ')[-1]}; "
        f"free space on its disk, then materialise the partition again (its assets already "
        f"stored are kept)")
    assert raised.value.__cause__ is error
    client = MlflowClient(tracking_uri=f"sqlite:///{db}")
    [run] = client.search_runs([client.get_experiment_by_name("pwa-pipeline/d").experiment_id])
    assert run.info.status == "FAILED"


class _Server(BaseHTTPRequestHandler):
    """/health answers 200 (with the right credentials); the API answers 503."""

    def do_GET(self):  # noqa: N802
        expected = "Basic " + base64.b64encode(b"ana:s3cret").decode()
        ok = self.path == "/health" and self.headers.get("Authorization") == expected
        self.send_response(200 if ok else (401 if self.path == "/health" else 503))
        self.end_headers()
        self.wfile.write(b"OK")

    do_POST = do_GET  # noqa: N815

    def log_message(self, *args):
        pass


@pytest.fixture()
def broken_server():
    server = ThreadingHTTPServer(("127.0.0.1", 0), _Server)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server.server_address[1]
    server.shutdown()


def test_credentials_are_used_for_the_probe_and_never_shown(broken_server):
    uri = f"http://ana:s3cret@127.0.0.1:{broken_server}"
    assert mask_credentials(uri) == f"http://ana:***@127.0.0.1:{broken_server}"
    url, token = split_credentials(uri)
    assert url == f"http://127.0.0.1:{broken_server}"
    assert base64.b64decode(token) == b"ana:s3cret"
    MLflowTracker(tracking_uri=uri).check_reachable()  # live: the probe sends the password
    # a run's link is made without the store (whose API fails here) and without the password
    assert MLflowTracker(tracking_uri=uri).run_url(LoggedRun("r1", "7")) == (
        f"http://127.0.0.1:{broken_server}/#/experiments/7/runs/r1?workflowType=machine_learning")
    wrong = uri.replace("s3cret", "guess")
    with pytest.raises(dg.Failure) as info:
        MLflowTracker(tracking_uri=wrong).check_reachable()
    assert "cannot be reached" in info.value.description
    assert "guess" not in info.value.description and "ana:***@" in info.value.description


def test_a_server_whose_api_fails_fails_the_run_within_30_seconds(broken_server):
    tracker = MLflowTracker(tracking_uri=f"http://ana:s3cret@127.0.0.1:{broken_server}",
                            request_timeout=3, request_retries=1)
    from mlflow.exceptions import MlflowException

    t0 = time.perf_counter()
    with pytest.raises(MlflowException, match=rf"API request to http://127.0.0.1:{broken_server}"
                                              r"/api/2.0/mlflow/.* failed .*503") as info:
        tracker.log_run(dataset="d", hparams="s", method="pwa", params={}, metrics={},
                        tags={}, artifacts={})
    assert time.perf_counter() - t0 < 30
    assert "s3cret" not in str(info.value) and "ana" not in str(info.value)


def test_re_runs_mark_the_latest_run(tmp_path, mlflow_template):
    from mlflow.tracking import MlflowClient

    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    uri = f"sqlite:///{db}"
    ids = [_log_one((uri, 0)) for _ in range(3)] + [_log_one((uri, 1))]
    client = MlflowClient(tracking_uri=uri)
    tags = {i: client.get_run(i).data.tags["latest"] for i in ids}
    assert [tags[i] for i in ids] == ["false", "false", "true", "true"]  # s0 thrice, s1 once

