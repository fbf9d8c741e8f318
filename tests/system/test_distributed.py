"""The scaled-out deployment on its real components, on loopback: the Dagster instance on
PostgreSQL, an MLflow tracking server on PostgreSQL with the artifacts it serves, the asset
store at an fsspec URL, and a dask scheduler with two worker processes, each started on its
own as the deployment docs start it. Also the clear errors for services that do not answer
and stores that cannot be used.

Partitions are small: three registered data sets of the paper's simulated system (600
samples) × two sets of a hyper-parameter file of the tests' own.
"""

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import dagster as dg
import numpy as np
import pandas as pd
import pytest

from benchmarks._cluster import (
    HPARAMS,
    DaskCluster,
    client_instance,
    dask_cluster,
    mlflow_server,
    postgres_missing,
    postgres_server,
    step_span,
)
from benchmarks._ui import free_port
from pwa_pipeline.datasets import make_hure_vasak
from pwa_pipeline.datasets.user import UserDataset
from pwa_pipeline.methods import METHODS
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.registry import DatasetRegistry
from pwa_pipeline.orchestration.signed_pickles import KEY_FILE, load_object, signing_key
from pwa_pipeline.orchestration.signed_tables import SIGNATURE_SUFFIX, load_table

DATASETS = ("m1", "m2", "m3")
SETS = ("default", "paper")
KEYS = [f"{d}|{s}" for d in DATASETS for s in SETS]
#: The partitions the cluster's sweep runs: every data set and both sets, each once (half of
#: KEYS, to keep the suite within its time; the slow tests run the others).
SWEPT = ["m1|default", "m2|paper", "m3|default"]
#: Dagster run states that mean a run is still going (an orphan once its process is gone).
IN_FLIGHT = {dg.DagsterRunStatus.STARTED, dg.DagsterRunStatus.STARTING,
             dg.DagsterRunStatus.QUEUED, dg.DagsterRunStatus.NOT_STARTED,
             dg.DagsterRunStatus.CANCELING}


@dataclass
class Cluster:
    """The services of one module's tests and how a client reaches them."""

    folder: Path
    dask: DaskCluster
    postgres: str
    mlflow_url: str
    files: dict[str, str]
    reference_run: subprocess.Popen
    mlflow_stack: ExitStack

    def env(self, store: str = "shared") -> dict[str, str]:
        """A client's environment: every store shared, the asset store ``store``."""
        return {**os.environ, **self.files, "PWA_PIPELINE_HOME": str(self.folder),
                "DAGSTER_HOME": str(self.folder / "client-home"),
                "PWA_STORAGE": (self.folder / store).as_uri(),
                "MLFLOW_TRACKING_URI": self.mlflow_url}

    def sweep(self, keys: list[str], store: str = "shared", **popen) -> subprocess.Popen:
        """``python -m pwa_pipeline run --scheduler …`` over ``keys``, started."""
        args = [a for k in keys for a in ("--partition", k)]
        return subprocess.Popen(
            [sys.executable, "-m", "pwa_pipeline", "run", "--scheduler", self.dask.address,
             *args], env=self.env(store), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True, **popen)

    def reference(self) -> PartitionedFileIOManager:
        """The store of the in-process reference run of every key, once it has ended."""
        if self.reference_run.returncode is None:
            out, _ = self.reference_run.communicate(timeout=600)
            assert self.reference_run.returncode == 0, out[-3000:]
        return PartitionedFileIOManager(base_dir=str(self.folder / "reference" / "storage"))

    def store(self, name: str = "shared") -> PartitionedFileIOManager:
        """The asset store ``name`` as the clients reach it (a ``file://`` URL)."""
        return PartitionedFileIOManager(base_dir=(self.folder / name).as_uri())

    def instance(self) -> dg.DagsterInstance:
        """The clients' Dagster instance, on PostgreSQL."""
        return client_instance(str(self.folder / "client-home"),
                               self.files["PWA_DAGSTER_POSTGRES_URL"])

    def start_mlflow(self) -> None:
        """``mlflow server`` at :attr:`mlflow_url` on the database ``mlflow``; stopped by
        closing :attr:`mlflow_stack`."""
        self.mlflow_stack.enter_context(mlflow_server(
            f"{self.postgres}/mlflow", self.folder / "artifacts",
            int(self.mlflow_url.rsplit(":", 1)[1]), self.folder / "mlflow.log"))


def _data_files(folder: Path) -> dict[str, str]:
    """The tests' hyper-parameter file and registry of three small simulated data sets."""
    (folder / "hparams.toml").write_text(HPARAMS)
    registry = DatasetRegistry(folder / "datasets.json")
    for seed, name in enumerate(DATASETS):
        d = make_hure_vasak(n_samples=600, seed=10 + seed)
        pd.DataFrame({"u1": d.u_train[0][:, 0], "u2": d.u_train[0][:, 1], "y1": d.y_train[0][:, 0],
                      "y2": d.y_train[0][:, 1]}
                     ).to_csv(folder / f"{name}.csv", index=False)
        registry.add(UserDataset(name=name, path=str(folder / f"{name}.csv"), u=("u1", "u2"),
                                 y=("y1", "y2")))
    return {"PWA_HPARAMS": str(folder / "hparams.toml"),
            "PWA_DATASETS": str(folder / "datasets.json")}


@pytest.fixture(scope="module")
def cluster(system_package, tmp_path_factory, mlflow_template) -> Iterator[Cluster]:
    """PostgreSQL (databases ``dagster`` and ``mlflow``), ``mlflow server`` on it, ``dask
    scheduler`` and two ``dask worker`` processes; beside them, started first, the
    in-process reference run of every key on a local store and sqlite MLflow. All stopped at
    the end."""
    system_package("the distributed tests need a PostgreSQL server", postgres_missing())
    folder = tmp_path_factory.mktemp("cluster")
    (folder / "client-home").mkdir()  # the clients' DAGSTER_HOME, whichever test runs first
    files = _data_files(folder)
    reference = folder / "reference"
    reference.mkdir()
    shutil.copy(mlflow_template, reference / "mlflow.db")
    env = {k: v for k, v in os.environ.items()
           if k not in ("MLFLOW_TRACKING_URI", "PWA_STORAGE", "PWA_DAGSTER_POSTGRES_URL")}
    in_process = subprocess.Popen(
        [sys.executable, "-m", "pwa_pipeline", "run", *[a for k in KEYS
                                                        for a in ("--partition", k)]],
        env={**env, **files, "PWA_PIPELINE_HOME": str(reference),
             "DAGSTER_HOME": str(reference / "home")},
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        with ExitStack() as stack:
            postgres = stack.enter_context(postgres_server(("dagster", "mlflow")))
            files["PWA_DAGSTER_POSTGRES_URL"] = f"{postgres}/dagster"
            mlflow_stack = stack.enter_context(ExitStack())
            services = Cluster(folder, None, postgres, f"http://127.0.0.1:{free_port()}",
                               files, in_process, mlflow_stack)
            services.start_mlflow()
            # the workers' environment: the data files and the Dagster instance; the stores
            # come with each run's configuration
            services.dask = stack.enter_context(dask_cluster(2, files, folder / "dask.log"))
            yield services
    finally:
        in_process.kill()
        in_process.wait()


def _worker_pids(cluster: Cluster) -> dict[str, int]:
    from dask.distributed import Client

    with Client(cluster.dask.address, timeout=10) as client:
        return client.run(os.getpid)


def _assert_results_equal_the_reference(cluster: Cluster, keys: list[str],
                                        store: str = "shared") -> None:
    """Every method's scores and the PWA model's parameters, to the last digit."""
    shared, reference = cluster.store(store), cluster.reference()
    for key in keys:
        pd.testing.assert_frame_equal(
            shared.load(dg.AssetKey("comparison"), key),
            reference.load(dg.AssetKey("comparison"), key), check_exact=True)
        model = shared.load(dg.AssetKey("pwa_model"), key)
        expected = reference.load(dg.AssetKey("pwa_model"), key)
        assert np.array_equal(model.thetas_, expected.thetas_), key
        assert np.array_equal(model.steps_["submodels"].labels_, expected.steps_["submodels"].labels_), key


def _runs_of(instance: dg.DagsterInstance, keys: list[str]) -> list[dg.DagsterRun]:
    return [r for r in instance.get_runs(dg.RunsFilter(job_name="sweep_dask"))
            if r.tags.get("dagster/partition") in keys]


def _every_stored_file_loads(root: Path) -> int:
    """Load every file of a store that a reader could be served (not the temporary ones);
    returns how many."""
    count = 0
    for path in root.rglob("*"):
        if path.is_dir() or path.name.startswith(".") or path.suffix == SIGNATURE_SUFFIX:
            continue  # a table's signature is checked as the table is loaded
        if path.suffix in (".pkl", ".parquet"):  # signed with the key of its store
            store = next(p for p in path.parents if (p / KEY_FILE).is_file())
            load = load_object if path.suffix == ".pkl" else load_table
            load(path, signing_key(store))
        count += 1
    return count


@pytest.mark.distributed
@pytest.mark.xdist_group("distributed")
def test_a_sweep_across_the_cluster_equals_the_in_process_run(cluster):
    from mlflow.tracking import MlflowClient

    sweep = cluster.sweep(SWEPT)
    out, _ = sweep.communicate(timeout=600)
    assert sweep.returncode == 0, out[-4000:]
    _assert_results_equal_the_reference(cluster, SWEPT)
    # every run in the shared instance, every step on a worker, both workers used
    with cluster.instance() as instance:
        runs = _runs_of(instance, SWEPT)
        assert sorted(r.tags["dagster/partition"] for r in runs) == sorted(SWEPT)
        assert {r.status for r in runs} == {dg.DagsterRunStatus.SUCCESS}
        pids = {e.dagster_event.pid for r in runs for e in instance.all_logs(r.run_id)
                if e.is_dagster_event and e.dagster_event.event_type_value == "STEP_START"}
    assert pids == set(_worker_pids(cluster).values())
    # every method of every partition in the shared MLflow server, artifacts on its side
    client = MlflowClient(tracking_uri=cluster.mlflow_url)
    for dataset in DATASETS:
        experiment = client.get_experiment_by_name(f"pwa-pipeline/{dataset}")
        assert experiment.artifact_location.startswith("mlflow-artifacts:")
        logged = client.search_runs([experiment.experiment_id],
                                    filter_string="tags.method != 'leaderboard'")
        assert sorted((r.data.tags["hparams"], r.data.tags["method"]) for r in logged) == \
            sorted((k.split("|")[1], m) for k in SWEPT if k.startswith(f"{dataset}|")
                   for m in METHODS)
        assert {r.info.status for r in logged} == {"FINISHED"}
    assert list((cluster.folder / "artifacts").rglob("prediction.png"))
    assert _every_stored_file_loads(cluster.folder / "shared") > 6 * 10


@pytest.mark.slow
@pytest.mark.distributed
@pytest.mark.xdist_group("distributed")
def test_two_clients_sweeping_at_once_take_turns_and_both_complete(cluster):
    first, second = ["m1|default"], ["m3|paper"]
    with cluster.instance() as instance:  # earlier tests', when they ran before this one
        earlier = {r.run_id for r in _runs_of(instance, first + second)}
    clients = [cluster.sweep(first), cluster.sweep(second)]
    outputs = [c.communicate(timeout=600)[0] for c in clients]
    for client, out in zip(clients, outputs, strict=True):
        assert client.returncode == 0, out[-4000:]
        assert "FAILED" not in out
    with cluster.instance() as instance:
        latest = [r for r in _runs_of(instance, first + second) if r.run_id not in earlier]
        assert len(latest) == 2
        assert {r.status for r in latest} == {dg.DagsterRunStatus.SUCCESS}
        # the two runs were launched at once but their steps ran one run after the other
        spans = sorted(step_span(instance, r.run_id) for r in latest)
    assert spans[0][1] <= spans[1][0], spans
    _assert_results_equal_the_reference(cluster, first + second)


@pytest.mark.slow
@pytest.mark.distributed
@pytest.mark.xdist_group("distributed")
def test_a_worker_killed_mid_sweep_leaves_a_complete_sweep_and_no_orphan(cluster):
    keys = ["m2|default"]
    before = _worker_pids(cluster)
    sweep = cluster.sweep(keys, store="killed")  # a fresh store: every step computes
    killed, step = None, None
    with cluster.instance() as instance:
        deadline = time.time() + 300
        while killed is None and sweep.poll() is None and time.time() < deadline:
            for run in _runs_of(instance, keys):
                events = [e.dagster_event for e in instance.all_logs(run.run_id)
                          if e.is_dagster_event]
                done = {e.step_key for e in events if e.event_type_value == "STEP_SUCCESS"}
                running = [e for e in events if e.event_type_value == "STEP_START"
                           and e.step_key == "pwa_fit" and e.step_key not in done]
                if running:
                    killed, step = running[0].pid, (run.run_id, "pwa_fit")
                    os.kill(killed, signal.SIGKILL)  # the worker process, mid-step
                    break
            time.sleep(0.05)
        out, _ = sweep.communicate(timeout=600)
        assert killed in before.values(), (killed, before, out[-3000:])
        assert sweep.returncode == 0, out[-4000:]
        runs = _runs_of(instance, keys)
        assert not [r for r in instance.get_runs() if r.status in IN_FLIGHT]
        assert {r.status for r in runs} == {dg.DagsterRunStatus.SUCCESS}
        starts = [e for e in instance.all_logs(step[0]) if e.is_dagster_event
                  and e.dagster_event.event_type_value == "STEP_START"
                  and e.dagster_event.step_key == step[1]]
    # the step began on the killed worker and ran again, to the end, on another
    assert len(starts) == 2 and starts[0].dagster_event.pid == killed \
        and starts[1].dagster_event.pid != killed
    _assert_results_equal_the_reference(cluster, keys, store="killed")
    assert _every_stored_file_loads(cluster.folder / "killed") > 10
    assert killed not in _worker_pids(cluster).values()  # its nanny started a new one


@pytest.mark.slow  # three sweeps; test_tracking_server.py replays the fault in one process
@pytest.mark.distributed
@pytest.mark.xdist_group("distributed")
def test_the_tracking_server_stopped_mid_run_fails_clearly_and_a_rerun_completes(cluster):
    key = "m1|paper"
    comparison = cluster.store().root() / "comparison" / "m1" / "paper.parquet"
    if not comparison.exists():  # stored by the first test, when it ran before this one
        first = cluster.sweep([key])
        out = first.communicate(timeout=600)[0]
        assert first.returncode == 0, out[-4000:]
    kept = comparison.read_bytes()
    sweep = cluster.sweep([key])
    with cluster.instance() as instance:
        deadline = time.time() + 300
        while sweep.poll() is None and time.time() < deadline:
            runs = [r for r in _runs_of(instance, [key])
                    if r.status == dg.DagsterRunStatus.STARTED]
            if runs and any(e.is_dagster_event and e.dagster_event.event_type_value ==
                            "STEP_START" for e in instance.all_logs(runs[0].run_id)):
                break  # its steps have begun; its scores come a second later at the earliest
            time.sleep(0.05)
        cluster.mlflow_stack.close()
        out = sweep.communicate(timeout=600)[0]
        assert sweep.returncode == 1, out[-4000:]
        assert f"{key}: FAILED after" in out
        # the summary says why, in the client's output, although the steps ran on workers
        assert f"pwa_scores: MLflow tracking server {cluster.mlflow_url} cannot be reached" \
            in out.split("Summary")[1]
        assert "already materialised are kept" in out
        assert not [r for r in instance.get_runs() if r.status in IN_FLIGHT]
        failed = _runs_of(instance, [key])[0]
        assert failed.status == dg.DagsterRunStatus.FAILURE
        stored = {e.dagster_event.step_key for e in instance.all_logs(failed.run_id)
                  if e.is_dagster_event and e.dagster_event.event_type_value == "STEP_SUCCESS"}
    # the store is intact: the fits of the failed run stored, nothing else changed, all loads
    assert {"pwa_fit", "control_model", "linear_arx_model", "subspace_model"} <= stored
    assert comparison.read_bytes() == kept
    _assert_results_equal_the_reference(cluster, [key])
    assert _every_stored_file_loads(cluster.folder / "shared") > 10
    # the server back on the same database: the rerun completes
    cluster.start_mlflow()
    again = cluster.sweep([key])
    out = again.communicate(timeout=600)[0]
    assert again.returncode == 0, out[-4000:]
    _assert_results_equal_the_reference(cluster, [key])


def test_the_pipeline_writes_and_reads_its_assets_and_caches_at_an_fsspec_url(monkeypatch):
    from pwa_pipeline.definitions import defs
    from pwa_pipeline.orchestration.settings import PipelineSettings

    from .._results import holding

    monkeypatch.setenv("PWA_STORAGE", "memory://pwa-test-store/assets")
    store = PartitionedFileIOManager()  # the store of $PWA_STORAGE
    assert str(store.root()) == "memory://pwa-test-store/assets"
    names = ("configuration", "raw_benchmark", "regressors", "local_models")
    resources = {"io_manager": store, "settings": PipelineSettings()}
    assert dg.materialize(holding(defs.assets, names), selection=names,
                          partition_key="hure_vasak|paper", resources=resources).success
    regressors = store.load(dg.AssetKey("regressors"), "hure_vasak|paper")
    assert regressors.phi.shape[0] > 1000
    cache = store.root() / "cache"
    assert resources["settings"].cache_root() == cache  # the caches follow the store
    assert sorted(p.name for p in cache.iterdir()) == [".signing-key", "local_models", "models"]
    files = [p.name for p in (store.root() / "regressors" / "hure_vasak").iterdir()]
    assert files == ["paper.pkl"]  # no temporary file left beside it


def test_bad_store_urls_are_refused_naming_them(tmp_path):
    from pwa_pipeline.orchestration.files import check_writable, store_root

    with pytest.raises(ValueError, match=r"storage URL nosuch://bucket/x cannot be used: "
                                         r"Protocol not known: nosuch"):
        store_root("nosuch://bucket/x")
    with pytest.raises(ValueError, match=r"storage URL webdav://u:\*\*\*@host/x cannot be "
                                         r"used") as caught:
        store_root("webdav://u:secret@host/x")  # its package (webdav4) is not installed
    assert "secret" not in str(caught.value)
    (tmp_path / "file").write_text("")
    store = store_root((tmp_path / "file" / "store").as_uri())
    with pytest.raises(ValueError, match=rf"the asset store {store} is not writable "
                                         r"\(NotADirectoryError"):
        check_writable(store, "asset store")


def test_a_scheduler_that_does_not_answer_fails_within_seconds_naming_it(monkeypatch,
                                                                          tmp_path):
    from pwa_pipeline.orchestration import dask_sweep
    from pwa_pipeline.orchestration.cli import main

    address = f"tcp://127.0.0.1:{free_port()}"  # nothing listens there
    monkeypatch.setattr(dask_sweep, "CONNECT_TIMEOUT", 2)
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=f"the dask scheduler {address} does not answer "
                                         f"within 2 s"):
        with dask_sweep.dask_scheduler(address):
            pass
    assert time.perf_counter() - t0 < 15
    with pytest.raises(ValueError, match="'localhost:8786' is not a dask scheduler address"):
        dask_sweep.check_address("localhost:8786")
    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    assert main(["run", "--scheduler", "localhost:8786", "--partition",
                 "hure_vasak|paper"]) == 2
    assert not (tmp_path / "storage" / "comparison").exists()  # nothing was run


def test_workers_that_do_not_see_the_store_are_refused_naming_it(tmp_path):
    from pwa_pipeline.orchestration.dask_sweep import dask_scheduler

    seen, unseen = tmp_path / "seen", tmp_path / "unseen"
    signing_key(seen)  # what the command line creates before its runs
    with dask_scheduler(n_workers=1, processes=False, dashboard=None, stores=[str(seen)]):
        pass
    with pytest.raises(ValueError, match=rf"dask worker .* does not see the store\(s\) "
                                         rf"{unseen} that this process writes"):
        with dask_scheduler(n_workers=1, processes=False, dashboard=None,
                            stores=[str(seen), str(unseen)]):
            pass


def test_the_compose_file_runs_the_services_as_the_docs_and_the_command_line_do():
    import yaml

    from pwa_pipeline.orchestration.instance import POSTGRES_YAML

    deploy = Path(__file__).resolve().parents[2] / "deploy"
    written = (deploy / "dagster.yaml").read_text()
    assert "\n".join(line for line in written.splitlines()
                     if not line.startswith("# ")) + "\n" == POSTGRES_YAML
    services = yaml.safe_load((deploy / "compose.yaml").read_text())["services"]
    assert set(services) == {"postgres", "mlflow", "dagster-webserver", "dagster-daemon",
                             "dask-scheduler", "dask-worker"}
    assert "--serve-artifacts" in services["mlflow"]["command"]
    assert "postgresql+psycopg2://" in services["mlflow"]["command"]
    worker = services["dask-worker"]
    assert worker["command"].startswith("dask worker tcp://dask-scheduler:8786")
    assert worker["deploy"]["replicas"] == 2
    for name in ("dagster-webserver", "dagster-daemon", "dask-worker"):
        env = services[name]["environment"]
        assert env["PWA_DAGSTER_POSTGRES_URL"].startswith("postgresql+psycopg2://")
        assert env["PWA_DAGSTER_POSTGRES_URL"].endswith("@postgres:5432/dagster")
        assert env["PWA_STORAGE"] == "file:///store"
        assert env["MLFLOW_TRACKING_URI"] == "http://mlflow:5000"
        assert "store:/store" in services[name]["volumes"]
