"""A sweep of two partitions through the dask executor on a local cluster, and the
leaderboard over what it stored."""

import io
import shutil

import dagster as dg
import numpy as np
import pandas as pd
import pytest

from pwa_pipeline.config import BUNDLED_HPARAMS
from pwa_pipeline.definitions import defs
from pwa_pipeline.methods import METHODS
from pwa_pipeline.orchestration.definitions import partitions_of
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.jobs import LEADERBOARD
from pwa_pipeline.orchestration.partitions import all_keys

from .._results import materialization

KEYS = ["hure_vasak|paper", "hure_vasak|default"]


@pytest.fixture(scope="module")
def dask_sweep(tmp_path_factory, mlflow_template):
    """Two partitions of the simulated data set swept through the dask executor (a
    LocalCluster of one worker thread), on a persistent instance and fresh stores."""
    from dask.distributed import Client, get_task_stream

    from pwa_pipeline.orchestration.dask_sweep import dask_scheduler, sweep_on_dask

    folder = tmp_path_factory.mktemp("dask_sweep")
    shutil.copy(mlflow_template, folder / "mlflow.db")
    uri = f"sqlite:///{folder / 'mlflow.db'}"
    run_config = {"resources": {
        "io_manager": {"config": {"base_dir": str(folder / "storage")}},
        "settings": {"config": {"cache_dir": str(folder / "cache"),
                                "hparams_path": str(BUNDLED_HPARAMS)}},
        "mlflow": {"config": {"tracking_uri": uri}}}}
    io_manager = PartitionedFileIOManager(base_dir=str(folder / "storage"))
    (folder / "home").mkdir()
    with dg.DagsterInstance.local_temp(str(folder / "home")) as instance, \
            dask_scheduler(n_workers=1, processes=False, dashboard=None) as address, \
            Client(address) as client:
        with get_task_stream(client) as stream:  # the tasks the scheduler ran
            runs = [run for _, run in sweep_on_dask(KEYS, instance, address, run_config,
                                                    io_manager=io_manager)]
        tasks = {task["key"] for task in stream.data}
        board = defs.resolve_job_def("refresh_leaderboard").execute_in_process(
            instance=instance, run_config=run_config)
        records = {run.run_id: instance.get_run_by_id(run.run_id) for run in runs}
        yield dict(runs=runs, records=records, address=address, tasks=tasks, board=board,
                   io_manager=io_manager, uri=uri, folder=folder)


def test_a_two_partition_sweep_runs_on_the_dask_executor(dask_sweep):
    from mlflow.tracking import MlflowClient

    runs, records = dask_sweep["runs"], dask_sweep["records"]
    assert [run.success for run in runs] == [True, True]
    for key, run in zip(KEYS, runs, strict=True):
        record = records[run.run_id]
        assert record.job_name == "sweep_dask" and record.tags["dagster/partition"] == key
        assert record.run_config["execution"]["config"]["cluster"] == {
            "existing": {"address": dask_sweep["address"]}}
    # every step was a task on the cluster (dagster-dask names them <job>.<step>)
    assert {f"sweep_dask.{m}_scores" for m in METHODS} | {
        "sweep_dask.pwa_fit", "sweep_dask.comparison"} <= dask_sweep["tasks"]
    # both partitions' assets stored, scores included, in the run's own store
    for key in KEYS:
        model = runs[0].io_manager.load(dg.AssetKey("pwa_model"), key)
        assert model.n_submodels_ >= 1
        for method in METHODS:
            scores = dask_sweep["io_manager"].load(dg.AssetKey(f"{method}_scores"), key)
            assert set(scores["mode"]) == {"one_step", "free_run"}
        comparison = runs[KEYS.index(key)].asset_value("comparison")
        assert list(dict.fromkeys(comparison["method"])) == list(METHODS)
    # and logged: one MLflow run per method and partition, tagged with its Dagster run
    client = MlflowClient(tracking_uri=dask_sweep["uri"])
    exp = client.get_experiment_by_name("pwa-pipeline/hure_vasak")
    logged = client.search_runs([exp.experiment_id], filter_string="tags.method != 'leaderboard'")
    assert sorted((r.data.tags["partition"], r.data.tags["method"]) for r in logged) == sorted(
        (k, m) for k in KEYS for m in METHODS)
    assert {r.data.tags["dagster_run_id"] for r in logged} == {run.run_id for run in runs}


def test_the_leaderboard_ranks_every_stored_partition_and_lists_the_missing(dask_sweep):
    from mlflow.tracking import MlflowClient

    board = dask_sweep["board"]
    assert board.success
    table = board.asset_value(LEADERBOARD)
    assert sorted(zip(table["hparams"], table["method"], strict=True)) == sorted(
        (k.split("|")[1], m) for k in KEYS for m in METHODS)
    # the leaderboard's numbers are the stored scores' output means
    io_manager = dask_sweep["io_manager"]
    for row in table.itertuples():
        scores = io_manager.load(dg.AssetKey(f"{row.method}_scores"), f"hure_vasak|{row.hparams}")
        free = scores[(scores["mode"] == "free_run") & (scores["output"] == "mean")]
        assert row.free_run_nrmse == free["nrmse"].iloc[0]
    assert (np.diff(table["free_run_nrmse"]) >= 0).all() and table["rank"].iloc[0] == 1
    meta = materialization(board, LEADERBOARD).metadata
    others = set(all_keys(partitions_of(defs))) - set(KEYS)
    assert meta["partitions_scored"].value == 2
    assert meta["partitions_missing"].value == len(others)
    assert set(meta["missing"].value.split(", ")) == others
    assert "kuka_robot|paper" in meta["leaderboard"].value
    assert "### hure_vasak" in meta["leaderboard"].value
    assert (dask_sweep["folder"] / "storage" / "leaderboard.parquet").is_file()
    # logged as a run of its own in the data set's experiment, csv + md
    client = MlflowClient(tracking_uri=dask_sweep["uri"])
    exp = client.get_experiment_by_name("pwa-pipeline/hure_vasak")
    [run] = client.search_runs([exp.experiment_id],
                               filter_string="tags.method = 'leaderboard'")
    assert run.info.run_name == "leaderboard" and run.data.tags["latest"] == "true"
    assert {a.path for a in client.list_artifacts(run.info.run_id)} == {
        "leaderboard.csv", "leaderboard.md"}
    import mlflow

    mlflow.set_tracking_uri(dask_sweep["uri"])
    csv = mlflow.artifacts.load_text(f"runs:/{run.info.run_id}/leaderboard.csv")
    logged = pd.read_csv(io.StringIO(csv))
    assert list(logged["method"]) == list(table["method"])
    np.testing.assert_allclose(logged["free_run_nrmse"], table["free_run_nrmse"])
    assert run.data.metrics["best_free_run_nrmse"] == pytest.approx(table["free_run_nrmse"].min())


@pytest.mark.slow
def test_a_scheduler_killed_mid_run_stops_the_command_in_one_line(tmp_path, mlflow_template):
    """The dask scheduler killed (SIGKILL) while ``run --scheduler`` runs its first partition:
    that partition fails with its cause, and the next does not start against the dead
    scheduler; the command ends with one line naming it and what to do, exit 2, and prints
    no stack trace of dask's own."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from benchmarks._ui import free_port

    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    env = {k: v for k, v in os.environ.items()
           if k not in ("DAGSTER_HOME", "MLFLOW_TRACKING_URI", "PWA_DATASETS")}
    env["PWA_PIPELINE_HOME"] = str(tmp_path)
    address = f"tcp://127.0.0.1:{free_port()}"
    dask = [sys.executable, "-m", "dask"]
    started = []
    try:
        started.append(subprocess.Popen(
            [*dask, "scheduler", "--port", address.rsplit(":", 1)[1], "--dashboard-address",
             ":0"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True))
        started.append(subprocess.Popen(
            [*dask, "worker", address, "--nthreads", "1"], env=env, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL, start_new_session=True))
        out = tmp_path / "out.txt"
        with open(out, "w") as sink:
            proc = subprocess.Popen(
                [sys.executable, "-m", "pwa_pipeline", "run", "--scheduler", address,
                 *[a for k in KEYS for a in ("--partition", k)]], env=env, stdout=sink,
                stderr=subprocess.STDOUT, start_new_session=True)
        deadline = time.time() + 180
        while f"=== materialising {KEYS[0]} ===" not in out.read_text():
            assert proc.poll() is None and time.time() < deadline, out.read_text()[-3000:]
            time.sleep(0.2)
        time.sleep(12)  # its steps run on the worker
        os.killpg(started[0].pid, signal.SIGKILL)
        try:
            status = proc.wait(timeout=180)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            raise AssertionError("not ended:\n" + out.read_text()[-6000:])
    finally:
        for process in started:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
    text = out.read_text()
    assert status == 2, text[-3000:]
    assert f"=== materialising {KEYS[1]} ===" not in text
    # dask's client, lock and semaphore printed stack traces of their reconnection attempts
    assert "Traceback" not in text and "distributed." not in text, text[-6000:]
    assert f"  {KEYS[0]}: FAILED after" in text and f"  not run to the end: {KEYS[1]}" in text
    last = text.rstrip().splitlines()[-1]
    assert last.startswith(f"pwa-pipeline run: error: the dask scheduler {address} stopped "
                           f"answering during {KEYS[0]} (")
    assert last.endswith(f"no further partition was started: start the scheduler and its "
                         f"workers again (`dask scheduler`, `dask worker {address}`), then run "
                         f"again")
