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
from pwa_pipeline.orchestration import storage
from pwa_pipeline.orchestration.resources import (
    LoggedRun,
    MLflowTracker,
    PipelineSettings,
    mask_credentials,
    split_credentials,
)
from pwa_pipeline.orchestration.storage import (
    PartitionedFileIOManager,
    SignedMemory,
    UnsignedFileError,
    inside,
    load_object,
    save_object,
    signing_key,
    sweep_stale_tmp,
)

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
    assert storage.create_new(path, b"first", 0o640)
    assert path.read_bytes() == b"first" and path.stat().st_mode & 0o777 == 0o640
    assert not storage.create_new(path, b"second", 0o600)  # another process's file: kept
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


def test_a_file_this_process_signed_is_loaded_from_memory_until_it_changes(tmp_path,
                                                                           monkeypatch):
    """The payload a process wrote or verified is unpickled again without reading the file;
    a file replaced (another process's write), touched or planted since is read and
    verified anew."""
    key = signing_key(tmp_path)
    path = tmp_path / "a.pkl"
    save_object(path, {"theta": 1.0}, key)
    reads = []
    read_bytes = Path.read_bytes
    monkeypatch.setattr(Path, "read_bytes", lambda p: reads.append(p.name) or read_bytes(p))
    first, second = load_object(path, key), load_object(path, key)
    assert first == second == {"theta": 1.0} and first is not second and reads == []
    save_object(tmp_path / "b.pkl", {"theta": 2.0}, key)
    os.replace(tmp_path / "b.pkl", path)  # what another process's atomic write does
    assert load_object(path, key) == {"theta": 2.0} and reads == ["a.pkl"]
    assert load_object(path, key) == {"theta": 2.0} and reads == ["a.pkl"]  # verified: kept
    os.utime(path, ns=(0, 0))
    assert load_object(path, key) == {"theta": 2.0} and reads == ["a.pkl", "a.pkl"]
    marker = tmp_path / "marker"
    planted = tmp_path / "c.pkl"
    planted.write_bytes(pickle.dumps(_Planted(marker)))
    os.replace(planted, path)
    with pytest.raises(UnsignedFileError, match="a.pkl is not a file this store wrote"):
        load_object(path, key)
    assert not marker.exists()
    # another store's key never gets this store's payload from memory
    save_object(path, {"theta": 3.0}, key)
    with pytest.raises(UnsignedFileError):
        load_object(path, signing_key(tmp_path / "other"))


def test_the_memory_of_verified_files_keeps_the_recently_used_within_its_bound(tmp_path):
    """At most ``max_bytes`` of payloads, the least recently used dropped first; a payload
    over a quarter of the bound is never kept."""
    memory = storage._VerifiedPayloads(max_bytes=400)
    files = {}
    for name in "abcdef":
        files[name] = tmp_path / name
        files[name].write_bytes(b"x")
    key = b"k"

    def put(name, size):
        memory.put(files[name], key, name.encode() * size, memory.identity(files[name]),
                   name.encode())

    for name in "abcd":
        put(name, 100)
    assert [memory.get(files[n], key) is not None for n in "abcd"] == [True] * 4
    assert memory.get(files["a"], key) == b"a" * 100  # a: the most recently used now
    put("e", 100)  # over the bound: b, the least recently used, is dropped
    assert [memory.get(files[n], key) is not None for n in "abcde"] == [
        True, False, True, True, True]
    put("f", 101)  # over a quarter of the bound: not kept, nothing dropped
    assert memory.get(files["f"], key) is None
    assert sum(memory.get(files[n], key) is not None for n in "acde") == 4


def test_the_same_payload_is_linked_to_the_file_that_holds_it_and_behaves_as_a_copy(
        tmp_path, monkeypatch):
    """A pickle with the same bytes and key as a kept file (the sets of a sweep store the
    same regressors) becomes a hard link to that file: one inode, no write, both names
    loaded from memory. Replacing either name leaves the other as it was; another key, a
    different payload, a source replaced since it was kept, or a file system that refuses
    links get a file of their own."""
    key = signing_key(tmp_path)
    theta = np.arange(5000.0)
    a, b, c, d = (tmp_path / "s" / f"{n}.pkl" for n in "abcd")
    save_object(a, {"theta": theta}, key)
    writes = []  # the names written to (the temporary file is .<name>.pkl.<random>.tmp)
    write_bytes = Path.write_bytes
    monkeypatch.setattr(Path, "write_bytes",
                        lambda p, data: writes.append(p.name.split(".")[1])
                        or write_bytes(p, data))
    save_object(b, {"theta": theta.copy()}, key)
    assert writes == [] and a.stat().st_ino == b.stat().st_ino and b.stat().st_nlink == 2
    assert not [p for p in a.parent.iterdir() if p.suffix == ".tmp"]
    reads = []
    read_bytes = Path.read_bytes
    monkeypatch.setattr(Path, "read_bytes", lambda p: reads.append(p.name) or read_bytes(p))
    for name in (a, b):
        np.testing.assert_array_equal(load_object(name, key)["theta"], theta)
    assert reads == []  # both kept with the identity the link gave the file
    save_object(a, {"theta": theta + 1}, key)  # a different payload: written
    assert writes == ["a"] and b.stat().st_nlink == 1
    np.testing.assert_array_equal(load_object(b, key)["theta"], theta)
    np.testing.assert_array_equal(load_object(a, key)["theta"], theta + 1)
    other = signing_key(tmp_path / "other")
    save_object(tmp_path / "other" / "b.pkl", {"theta": theta}, other)  # another store's key
    assert writes[-1] == "b" and b.stat().st_nlink == 1
    # a kept source replaced since by another process (its signature is the store's): never
    # linked to, as the identity it was kept with is gone
    save_object(c, {"theta": theta * 2}, key)
    stale = storage._VERIFIED.signed_as(storage.hmac.new(
        key, pickle.dumps({"theta": theta * 2}, protocol=5), "sha256").digest())
    assert stale is not None and stale[0] == c
    os.replace(b, c)
    assert not storage._link_same(d, key, *stale, b"")
    assert not d.exists() and not [p for p in c.parent.iterdir() if p.suffix == ".tmp"]
    save_object(d, {"theta": theta * 2}, key)
    assert writes[-1] == "d" and d.stat().st_nlink == 1
    monkeypatch.setattr(os, "link", lambda *_: (_ for _ in ()).throw(OSError(31, "links")))
    save_object(tmp_path / "s" / "e.pkl", {"theta": theta * 2}, key)
    assert writes[-1] == "e"
    np.testing.assert_array_equal(load_object(tmp_path / "s" / "e.pkl", key)["theta"], theta * 2)


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
    monkeypatch.setattr(storage, "core_fingerprint", lambda: "other code")
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


def _log_model_once_at(args):
    """Log a run of one fitted linear ARX model once ``barrier`` lets every process go."""
    uri, hparams, barrier = args
    from pwa_pipeline import LinearARX, make_hure_vasak
    from pwa_pipeline.orchestration.mlflow_models import (
        ModelToLog,
        Simulator,
        example_table,
        table_dataset,
    )

    data = make_hure_vasak(n_samples=300, snr_db=30, seed=0)
    model = LinearARX(na=1, nb=1).fit(data.u, data.y)
    table = example_table(data.u, data.y, data.u_names, data.y_names, 5)
    tracker = MLflowTracker(tracking_uri=uri)
    tracker.client()  # the store ready before the race
    barrier.wait()
    return tracker.log_run(dataset="d", hparams=hparams, method="linear_arx", params={},
                           metrics={}, tags={}, artifacts={},
                           model=ModelToLog(Simulator(model, data.u_names, data.y_names),
                                            table, table_dataset(table))).run_id


def test_runs_scoring_one_model_at_once_log_it_once(tmp_path, mlflow_template):
    """Three processes score the same model at the same moment (as ``run --jobs 2`` does with
    a baseline two partitions share): on the sqlite store one run logs and registers it, the
    others link it."""
    from mlflow.tracking import MlflowClient

    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    barrier = multiprocessing.get_context("fork").Manager().Barrier(3)
    with _fork_pool(3) as pool:
        ids = pool.map(_log_model_once_at, [(uri, f"s{i}", barrier) for i in range(3)])
    client = MlflowClient(tracking_uri=uri)
    tags = [client.get_run(i).data.tags for i in ids]
    logged = {t["model_run_id"] for t in tags}
    assert len(logged) == 1 and logged <= set(ids)
    assert len({t["model_id"] for t in tags}) == 1
    versions = client.search_model_versions("name = 'pwa-pipeline.d.linear_arx'")
    assert [v.run_id for v in versions] == list(logged)


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
