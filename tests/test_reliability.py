"""Faults a hostile user or a busy team meets: names that try to leave the store, planted
or damaged pickles, runs started at once, interrupts, broken or password-protected servers."""

import base64
import contextlib
import json
import multiprocessing
import os
import pickle
import shutil
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import dagster as dg
import numpy as np
import pandas as pd
import pytest

from pwa_pipeline.definitions import defs
from pwa_pipeline.orchestration import caches, files
from pwa_pipeline.orchestration.caches import SignedMemory
from pwa_pipeline.orchestration.credentials import mask_credentials, split_credentials
from pwa_pipeline.orchestration.files import inside, sweep_stale_tmp
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.settings import PipelineSettings
from pwa_pipeline.orchestration.signed_pickles import (
    UnsignedFileError,
    load_object,
    save_object,
    signing_key,
)
from pwa_pipeline.orchestration.tracking import LoggedRun, MLflowTracker

IDENTIFICATION = ["configuration", "raw_benchmark", "regressors", "local_models"]


class _Planted:
    """Unpickling this runs code: it writes ``marker``."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (Path.write_text, (self.marker, "code ran"))


def _assets(names):
    return [a for a in defs.assets if a.key.to_user_string() in names]


def test_paths_cannot_leave_the_store(tmp_path):
    assert inside(tmp_path, "a", "b.pkl") == (tmp_path / "a" / "b.pkl").resolve()
    for bad in (("..", "x.pkl"), ("/etc", "passwd"), ("a", "../../x")):
        with pytest.raises(ValueError, match="would leave the store"):
            inside(tmp_path, *bad)
    io = PartitionedFileIOManager(base_dir=str(tmp_path))
    for key in ("hure_vasak|../../out", "hure_vasak|set?", "../x|paper", "hure_vasak|eps0.1"):
        ctx = dg.build_output_context(asset_key=dg.AssetKey("comparison"), partition_key=key)
        with pytest.raises(ValueError, match="invalid (hyper-parameter set|data set) name"):
            io.handle_output(ctx, pd.DataFrame({"a": [1]}))
    assert [p.name for p in tmp_path.iterdir()] == []


def test_similar_names_never_share_a_file(tmp_path):
    io = PartitionedFileIOManager(base_dir=str(tmp_path))
    for name, value in (("eps0_1", 1), ("eps0_3", 3), ("eps0", 0)):
        ctx = dg.build_output_context(asset_key=dg.AssetKey("x"), partition_key=f"d|{name}")
        io.handle_output(ctx, {"value": value})
    for name, value in (("eps0_1", 1), ("eps0_3", 3), ("eps0", 0)):
        ctx = dg.build_input_context(asset_key=dg.AssetKey("x"), partition_key=f"d|{name}")
        assert io.load_input(ctx) == {"value": value}
    # a table replaces the pickle of the same partition, and only that one
    ctx = dg.build_output_context(asset_key=dg.AssetKey("x"), partition_key="d|eps0")
    io.handle_output(ctx, pd.DataFrame({"a": [1]}))
    assert sorted(p.name for p in (tmp_path / "x" / "d").iterdir()) == [
        "eps0.parquet", "eps0_1.pkl", "eps0_3.pkl"]


def test_a_planted_pickle_is_never_loaded(tmp_path):
    marker = tmp_path / "marker"
    planted = tmp_path / "store" / "x" / "d" / "s.pkl"
    planted.parent.mkdir(parents=True)
    planted.write_bytes(pickle.dumps(_Planted(marker)))
    io = PartitionedFileIOManager(base_dir=str(tmp_path / "store"))
    ctx = dg.build_input_context(asset_key=dg.AssetKey("x"), partition_key="d|s")
    with pytest.raises(UnsignedFileError, match=f"{planted} is not a file this store wrote"):
        io.load_input(ctx)
    assert not marker.exists()
    # signed with another store's key: refused too
    save_object(planted, {"a": 1}, signing_key(tmp_path / "other"))
    with pytest.raises(UnsignedFileError):
        io.load_input(ctx)


def test_create_new_never_replaces_a_file_and_leaves_no_temporary_one(tmp_path):
    path = tmp_path / "f.db"
    assert files.create_new(path, b"first", 0o640)
    assert path.read_bytes() == b"first" and path.stat().st_mode & 0o777 == 0o640
    assert not files.create_new(path, b"second", 0o600)  # another process's file: kept
    assert path.read_bytes() == b"first" and path.stat().st_mode & 0o777 == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.db"]


def test_signed_files_round_trip_and_damage_is_detected(tmp_path):
    key = signing_key(tmp_path)
    assert signing_key(tmp_path) == key and len(key) == 32
    assert (tmp_path / ".signing-key").stat().st_mode & 0o777 == 0o600
    save_object(tmp_path / "a.pkl", {"theta": [1.0, 2.0]}, key)
    assert load_object(tmp_path / "a.pkl", key) == {"theta": [1.0, 2.0]}
    data = (tmp_path / "a.pkl").read_bytes()
    (tmp_path / "a.pkl").write_bytes(data[:-5])  # truncated
    with pytest.raises(UnsignedFileError, match="a.pkl is not a file this store wrote"):
        load_object(tmp_path / "a.pkl", key)


@pytest.fixture()
def settings(tmp_path):
    return PipelineSettings(cache_dir=str(tmp_path / "cache"))


@pytest.mark.parametrize(("asset", "partition", "fitted"), [
    ("local_models", "hure_vasak|paper", "theta_"),
    ("sub_models", "hure_vasak|default", "thetas_")])
def test_bad_cache_entries_are_recomputed_with_a_warning(tmp_path, settings, asset, partition,
                                                         fitted):
    """A planted or truncated entry of the local-model or step-5 cache is never unpickled:
    the run recomputes it, says so, and gives the same result; the next run reads it."""
    resources = {"io_manager": PartitionedFileIOManager(base_dir=str(tmp_path / "store")),
                 "settings": settings}
    instance = dg.DagsterInstance.ephemeral()
    names = IDENTIFICATION + (["clusters", "sub_models"] if asset == "sub_models" else [])
    first = dg.materialize(_assets(names), partition_key=partition, resources=resources,
                           instance=instance)
    [entry] = (tmp_path / "cache" / asset).glob("*.pkl")
    reference = getattr(first.output_for_node(asset), fitted)
    marker = tmp_path / "marker"
    for damage in (lambda: entry.write_bytes(pickle.dumps(_Planted(marker))),
                   lambda: entry.write_bytes(entry.read_bytes()[:100])):
        damage()
        result = dg.materialize(_assets(names), partition_key=partition, resources=resources,
                                instance=instance)
        meta = result.asset_materializations_for_node(asset)[0].metadata
        assert result.success and not meta["from_cache"].value
        logged = [e.user_message for e in instance.all_logs(result.run_id)]
        assert any(f"cache entry {entry} unusable" in m for m in logged)
        assert not marker.exists()
        np.testing.assert_array_equal(getattr(result.output_for_node(asset), fitted), reference)
    again = dg.materialize(_assets(names), partition_key=partition, resources=resources)
    assert again.asset_materializations_for_node(asset)[0].metadata["from_cache"].value
    np.testing.assert_array_equal(getattr(again.output_for_node(asset), fitted), reference)


def test_signed_memory_keys_results_on_the_arguments_and_the_cores_source(tmp_path,
                                                                          monkeypatch):
    """SignedMemory computes a call once per function, arguments and numerical-core source,
    and reads it back signed; a step holding it clones to the same handle."""
    import copy

    from sklearn.base import clone

    from pwa_pipeline.pwa import RefinedSubModels

    calls = []

    def scaled(a, factor=1.0):
        calls.append(factor)
        return np.asarray(a) * factor

    memory = SignedMemory(tmp_path, "m")
    cached = memory.cache(scaled)
    for factor, computed in ((1.0, 1), (1.0, 1), (2.0, 2), (1.0, 2)):
        np.testing.assert_array_equal(cached(np.arange(3.0), factor=factor),
                                      np.arange(3.0) * factor)
        assert len(calls) == computed
    assert (memory.hits, memory.misses) == (2, 2)
    np.testing.assert_array_equal(cached(np.arange(4.0)), np.arange(4.0))  # other data
    monkeypatch.setattr(caches, "core_fingerprint", lambda: "other code")
    cached(np.arange(3.0), factor=1.0)
    assert len(calls) == 4 and len(list((tmp_path / "m").glob("*.pkl"))) == 4
    salted = SignedMemory(tmp_path, "m", salt="other figures").cache(scaled)
    salted(np.arange(3.0), factor=1.0)  # the same call, another salt: computed again
    assert len(calls) == 5 and len(list((tmp_path / "m").glob("*.pkl"))) == 5
    assert copy.deepcopy(memory) is memory
    assert clone(RefinedSubModels(memory=memory)).memory is memory


def test_stale_temporary_files_are_swept_fresh_ones_kept(tmp_path):
    old, new = tmp_path / ".a.pkl.x1.tmp", tmp_path / ".a.pkl.x2.tmp"
    for p in (old, new):
        p.write_text("half")
    os.utime(old, (time.time() - 7200, time.time() - 7200))
    (tmp_path / "b.pkl").write_text("kept")
    assert sweep_stale_tmp(tmp_path) == [old]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".a.pkl.x2.tmp", "b.pkl"]


def _log_one(args):
    uri, i = args
    tracker = MLflowTracker(tracking_uri=uri)
    return tracker.log_run(dataset="d", hparams=f"s{i}", method="pwa", params={}, metrics={"m": i},
                           tags={}, artifacts={}).run_id


@contextlib.contextmanager
def _fork_pool(processes: int):
    """A fork pool ended by close + join: ``Pool.__exit__`` terminates its workers by SIGTERM,
    which pytest-xdist's workers ignore, and a worker blocked on the task queue's lock (held by
    the terminating pool) then never ends."""
    pool = multiprocessing.get_context("fork").Pool(processes)
    try:
        yield pool
    finally:
        pool.close()
        pool.join()


@pytest.mark.parametrize("fresh", [True, False])
def test_runs_started_at_once_all_log(tmp_path, fresh, mlflow_template):
    from mlflow.tracking import MlflowClient

    db = tmp_path / "mlflow.db"
    if not fresh:
        shutil.copy(mlflow_template, db)
    uri = f"sqlite:///{db}"
    with _fork_pool(3) as pool:  # separate processes, no re-import
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
                             metrics={"nrmse": float("inf")}, tags={"partition": "d|s"},
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
    assert run.data.metrics == {"nrmse": 1e300}
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
    t0 = time.perf_counter()
    with pytest.raises(Exception) as info:
        tracker.log_run(dataset="d", hparams="s", method="pwa", params={}, metrics={},
                        tags={}, artifacts={})
    assert time.perf_counter() - t0 < 30
    assert "s3cret" not in str(info.value)


def _prepare(home):
    os.environ["DAGSTER_HOME"] = home
    from pwa_pipeline.orchestration.instance import prepare_instance

    prepare_instance().get_runs(limit=1)
    return "ok"


def test_instances_created_at_once_share_one_schema(tmp_path):
    import sqlite3

    for trial in range(2):  # without the lock 2 of 3 such trials broke the home
        home = tmp_path / f"home{trial}"
        with _fork_pool(4) as pool:
            assert pool.map(_prepare, [str(home)] * 4) == ["ok"] * 4
        db = sqlite3.connect(home / "history" / "runs.db")
        assert db.execute("select count(*) from alembic_version").fetchone() == (1,)
        assert "nux:\n  enabled: false" in (home / "dagster.yaml").read_text()


def test_doctor_finds_and_repairs_what_a_killed_run_left(tmp_path, mlflow_template, monkeypatch,
                                                         capsys):
    from mlflow.tracking import MlflowClient

    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    uri = f"sqlite:///{db}"
    # what SIGKILL leaves: a STARTED Dagster run, a RUNNING MLflow run, a temporary file
    from pwa_pipeline.orchestration.instance import prepare_instance

    instance = prepare_instance()
    run = instance.add_run(dg.DagsterRun(job_name="sweep", status=dg.DagsterRunStatus.STARTED))
    client = MlflowClient(tracking_uri=uri)
    mlflow_run = client.create_run(client.create_experiment("pwa-pipeline/d"))
    tmp = tmp_path / "storage" / "pwa_model" / "d" / ".s.pkl.abc.tmp"
    tmp.parent.mkdir(parents=True)
    tmp.write_text("half")
    os.utime(tmp, (time.time() - 600, time.time() - 600))
    time.sleep(1.1)  # MLflow and Dagster keep second-resolution start times
    args = ["doctor", "--older-than", "0.01", "--tracking-uri", uri]
    assert main(args) == 1
    report = capsys.readouterr().out
    assert run.run_id in report and mlflow_run.info.run_id in report and str(tmp) in report
    assert main(args + ["--repair"]) == 0
    assert instance.get_run_by_id(run.run_id).status == dg.DagsterRunStatus.FAILURE
    assert client.get_run(mlflow_run.info.run_id).info.status == "KILLED"
    assert not tmp.exists()
    assert main(args) == 0  # nothing left


def test_tables_for_unknown_data_sets_are_refused(tmp_path):
    from pwa_pipeline.orchestration.definitions import build_definitions

    path = tmp_path / "hp.toml"
    path.write_text("[a.hure_vasak]\n[a.kuka_robto]\n")
    with pytest.raises(ValueError, match=r"unknown data set\(s\) \['kuka_robto'\]"):
        build_definitions(path)


def test_re_runs_mark_the_latest_run(tmp_path, mlflow_template):
    from mlflow.tracking import MlflowClient

    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    uri = f"sqlite:///{db}"
    ids = [_log_one((uri, 0)) for _ in range(3)] + [_log_one((uri, 1))]
    client = MlflowClient(tracking_uri=uri)
    tags = {i: client.get_run(i).data.tags["latest"] for i in ids}
    assert [tags[i] for i in ids] == ["false", "false", "true", "true"]  # s0 thrice, s1 once
