"""``run``: partitions one after the other in this process, on shared stores; a failure or
an interrupt keeps what was computed (Ctrl-C to a real run: tests/system/test_processes.py)."""

import base64
import os
import shutil
import subprocess
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import dagster as dg
import pandas as pd
import pytest

from pwa_pipeline.datasets import make_hure_vasak
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.paths import default_storage_dir


def test_partitions_run_one_after_the_other_and_a_failure_keeps_the_others(
        tmp_path, mlflow_template, monkeypatch, capsys):
    from mlflow.tracking import MlflowClient

    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    d = make_hure_vasak(n_samples=1200, seed=7)
    frame = pd.DataFrame({"u1": d.u_train[0][:, 0], "u2": d.u_train[0][:, 1], "y1": d.y_train[0][:, 0],
                          "y2": d.y_train[0][:, 1]})
    for name in ("plant", "mill", "gone"):
        frame.to_csv(tmp_path / f"{name}.csv", index=False)
        assert main(["add-dataset", name, str(tmp_path / f"{name}.csv"), "--u", "u1", "u2",
                     "--y", "y1", "y2"]) == 0
    # the file is there (so the run starts) but its columns are not: its run fails, and the
    # others' results must stay
    (tmp_path / "gone.csv").write_text("a,b\n1,2\n")
    capsys.readouterr()
    keys = ["plant|default", "mill|default", "gone|default"]
    args = ["run"] + [a for k in keys for a in ("--partition", k)]
    assert main(args) == 1
    out, err = capsys.readouterr()
    assert "gone|default: FAILED after" in out
    assert ("\n    raw_benchmark: ValueError: gone.csv has no column(s) ['u1', 'u2', 'y1', "
            "'y2']; it has ['a', 'b']\n") in out
    # the failure's cause in one line, not Dagster's wrapper and its stack traces
    assert "Error occurred while executing op" not in out + err
    assert "Stack Trace" not in out + err and "Traceback" not in out + err
    assert "\n  3 partition(s) run, 2 succeeded, 1 failed; " in out.split("Summary")[1]
    for key in keys[:2]:
        assert f"{key}: mean over the outputs" in out
        assert f"  {key}: " in out.split("Summary")[1]  # its summary line
    instance = dg.DagsterInstance.get()
    runs = {r.tags["dagster/partition"]: r for r in instance.get_runs()
            if "dagster/partition" in r.tags}
    assert {runs[k].job_name for k in keys} == {"sweep"}  # listed among the sweep job's runs
    assert [r.job_name for r in instance.get_runs() if "dagster/partition" not in r.tags] == [
        "refresh_leaderboard"]
    assert {k: runs[k].status for k in keys} == {
        "plant|default": dg.DagsterRunStatus.SUCCESS,
        "mill|default": dg.DagsterRunStatus.SUCCESS,
        "gone|default": dg.DagsterRunStatus.FAILURE}
    pids = {e.dagster_event.pid for k in keys for e in instance.all_logs(runs[k].run_id)
            if e.is_dagster_event and e.dagster_event.pid is not None}
    assert pids == {os.getpid()}  # every step of every run in this process
    client = MlflowClient(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    for dataset in ("plant", "mill"):
        exp = client.get_experiment_by_name(f"pwa-pipeline/{dataset}")
        logged = client.search_runs([exp.experiment_id],
                                    filter_string="tags.method != 'leaderboard'")
        assert sorted(r.data.tags["method"] for r in logged) == [
            "linear_arx", "pwa", "subspace"]
    assert client.get_experiment_by_name("pwa-pipeline/gone") is None
    store = PartitionedFileIOManager(base_dir=str(default_storage_dir()))
    for key in keys[:2]:
        model = store.load(dg.AssetKey("pwa_model"), key)
        assert f"  {key}: {model.n_submodels_} PWA sub-model(s)" in out


def test_a_store_that_cannot_be_written_stops_the_command_before_any_run(tmp_path,
                                                                          monkeypatch, capsys):
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    monkeypatch.delenv("DAGSTER_HOME", raising=False)
    (tmp_path / "storage").write_text("not a folder")
    assert main(["run", "--partition", "hure_vasak|paper"]) == 2
    err = capsys.readouterr().err
    assert f"error: the asset store {tmp_path / 'storage'} cannot be a folder: " in err
    assert not (tmp_path / ".dagster_home").exists()  # nothing started


def test_a_store_that_lives_only_in_memory_is_refused_before_any_run(tmp_path, monkeypatch,
                                                                    capsys):
    """``PWA_STORAGE=memory://…`` would run (exit 0) and lose every asset and export when the
    process ends: refused at the start, in one line saying why (exit 2)."""
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    monkeypatch.delenv("DAGSTER_HOME", raising=False)
    monkeypatch.setenv("PWA_STORAGE", "memory://pwa-lost/assets")
    assert main(["run", "--partition", "hure_vasak|paper"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pwa-pipeline run: error: the asset store memory://pwa-lost/assets "
                          "is kept only in this process's memory")
    assert "lost when the process ends" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / ".dagster_home").exists()  # nothing started


def _undo_mlflow_environment(monkeypatch) -> None:
    """Unset MLflow's URI and credential variables for the test, and have what the command
    sets in them (`credentials_to_environment`) undone after it."""
    for name in ("MLFLOW_TRACKING_URI", "MLFLOW_TRACKING_USERNAME", "MLFLOW_TRACKING_PASSWORD"):
        monkeypatch.setenv(name, "")  # recorded, so that the test's end restores it
        monkeypatch.delenv(name)


def test_a_tracking_server_that_does_not_answer_stops_the_command_in_one_line(
        tmp_path, monkeypatch, capsys):
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    monkeypatch.delenv("DAGSTER_HOME", raising=False)
    _undo_mlflow_environment(monkeypatch)
    assert main(["run", "--partition", "hure_vasak|paper", "--tracking-uri",
                 "http://ana:s3cret@127.0.0.1:9"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pwa-pipeline run: error: MLflow tracking server "
                          "http://127.0.0.1:9 cannot be reached")
    assert "s3cret" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "storage").exists()  # no run started


def _run_cli(args: list[str], tmp_path: Path, **env: str) -> subprocess.CompletedProcess:
    """``python -m pwa_pipeline`` in a fresh process on stores under ``tmp_path``."""
    root = Path(__file__).resolve().parents[2]
    environ = {**os.environ, "PWA_PIPELINE_HOME": str(tmp_path),
               "DAGSTER_HOME": str(tmp_path / "home"),
               "PWA_DATASETS": str(tmp_path / "datasets.json"),
               "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]),
               **env}
    environ.pop("MLFLOW_TRACKING_URI", None)
    return subprocess.run([sys.executable, "-m", "pwa_pipeline", *args], cwd=tmp_path,
                          env=environ, capture_output=True, text=True, timeout=300)


def _one_line_error(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 2, result.stdout + result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    return lines[0]


def test_a_partition_without_its_data_stops_the_command_in_one_line(tmp_path):
    """The README's own example without the robot's data: one line naming the partition, the
    path looked at and the variable to set, exit 2, before any run."""
    missing = tmp_path / "no-kuka"
    error = _one_line_error(_run_cli(["run", "--partition", "kuka_robot|paper"], tmp_path,
                                     PWA_KUKA_DATA=str(missing)))
    assert error == (f"pwa-pipeline run: error: kuka_robot|paper cannot run: no KUKA data at "
                     f"{missing} (set PWA_KUKA_DATA)")
    assert not (tmp_path / "storage").exists() and not (tmp_path / "home").exists()


def test_a_registered_data_set_whose_file_was_deleted_stops_the_command_in_one_line(tmp_path):
    d = make_hure_vasak(n_samples=300, seed=7)
    table = tmp_path / "plant.csv"
    pd.DataFrame({"u1": d.u_train[0][:, 0], "u2": d.u_train[0][:, 1], "y1": d.y_train[0][:, 0],
                  "y2": d.y_train[0][:, 1]}).to_csv(table, index=False)
    added = _run_cli(["add-dataset", "plant", str(table), "--u", "u1", "u2", "--y", "y1", "y2"],
                     tmp_path)
    assert added.returncode == 0, added.stderr
    table.unlink()
    error = _one_line_error(_run_cli(["run", "--partition", "plant|default", "--partition",
                                      "hure_vasak|paper", "--partition", "plant|auto"],
                                     tmp_path))
    assert error == (f"pwa-pipeline run: error: plant|default, plant|auto cannot run: its file "
                     f"{table} is missing (registered in {tmp_path / 'datasets.json'})")
    assert not (tmp_path / "storage").exists() and not (tmp_path / "home").exists()


@pytest.mark.parametrize("value", ["0", "-3", "two"])
def test_a_local_cluster_without_workers_is_refused_by_the_parser(value, tmp_path,
                                                                  monkeypatch, capsys):
    """``--workers 0`` started a LocalCluster of no workers, waited 30 s, then said to start
    a worker: refused at once by the argument parser (exit 2)."""
    import time

    from pwa_pipeline.orchestration import dask_sweep
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    monkeypatch.delenv("PWA_DASK_SCHEDULER", raising=False)
    monkeypatch.setattr(dask_sweep, "WORKER_TIMEOUT", 3)  # a reproduction that fails fast
    t0 = time.perf_counter()
    with pytest.raises(SystemExit) as stop:
        main(["run", "--executor", "dask", "--workers", value, "--partition",
              "hure_vasak|paper"])
    assert stop.value.code == 2 and time.perf_counter() - t0 < 2
    assert (f"argument --workers: must be a whole number of worker processes >= 1, got "
            f"{value!r}" in capsys.readouterr().err)
    assert not (tmp_path / "home").exists()  # nothing started


class _HealthOnly(BaseHTTPRequestHandler):
    """A tracking server whose /health answers 200 to ana:s3cret; its API answers 503."""

    def do_GET(self):  # noqa: N802
        expected = "Basic " + base64.b64encode(b"ana:s3cret").decode()
        ok = self.path == "/health" and self.headers.get("Authorization") == expected
        self.send_response(200 if ok else 503)
        self.end_headers()
        self.wfile.write(b"OK")

    do_POST = do_GET  # noqa: N815

    def log_message(self, *args):
        pass


def test_a_password_in_the_tracking_uri_is_never_stored_in_a_run(tmp_path, monkeypatch,
                                                                 capsys):
    """``run --tracking-uri http://ana:s3cret@host``: the runs it launches (and the
    leaderboard's) hold the URI masked, never the password, in their run configuration,
    tags and job snapshot (all shown in the Dagster UI); the password reaches MLflow
    through its own environment variables."""
    from pwa_pipeline.orchestration.cli import main

    server = ThreadingHTTPServer(("127.0.0.1", 0), _HealthOnly)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    uri = f"http://ana:s3cret@127.0.0.1:{server.server_address[1]}"
    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    _undo_mlflow_environment(monkeypatch)
    d = make_hure_vasak(n_samples=300, seed=7)
    pd.DataFrame({"u1": d.u_train[0][:, 0], "u2": d.u_train[0][:, 1],
                  "y1": d.y_train[0][:, 0], "y2": d.y_train[0][:, 1]}).to_csv(
        tmp_path / "plant.csv", index=False)
    assert main(["add-dataset", "plant", str(tmp_path / "plant.csv"), "--u", "u1", "u2",
                 "--y", "y1", "y2"]) == 0
    (tmp_path / "plant.csv").write_text("a,b\n1,2\n")  # the run starts, then fails at once
    try:
        # the probe passed (with the credentials from the environment) and the run started
        assert main(["run", "--partition", "plant|default", "--tracking-uri", uri]) == 1
    finally:
        server.shutdown()
    out = capsys.readouterr()
    assert "s3cret" not in out.out + out.err
    instance = dg.DagsterInstance.get()
    runs = instance.get_runs()
    assert {r.job_name for r in runs} >= {"sweep"}
    for run in runs:
        stored = [dg.serialize_value(run.run_config), dg.serialize_value(run.tags),
                  dg.serialize_value(instance.get_job_snapshot(run.job_snapshot_id))]
        assert not [s for s in stored if "s3cret" in s], run.job_name


def test_the_libraries_bookkeeping_lines_are_silenced_and_their_warnings_kept(
        tmp_path, monkeypatch, capsys):
    """MLflow's "Creating initial MLflow database tables" (INFO) is not the run's news: the
    command shows that logger's warnings only."""
    import logging

    import mlflow  # noqa: F401  (configures MLflow's handler, as a run does)

    from pwa_pipeline.orchestration.cli import BOOKKEEPING_LOGGERS, main

    for name in BOOKKEEPING_LOGGERS:
        monkeypatch.setattr(logging.getLogger(name), "level", logging.getLogger(name).level)
    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    assert main(["list-datasets"]) == 0
    capsys.readouterr()
    root = logging.getLogger()  # as an application showing every INFO line configures it
    shown = logging.StreamHandler(sys.stderr)
    monkeypatch.setattr(root, "level", logging.INFO)
    root.addHandler(shown)
    try:
        tables = logging.getLogger("mlflow.store.db.utils")
        tables.info("Creating initial MLflow database tables...")
        tables.warning("a warning users should see")
    finally:
        root.removeHandler(shown)
    err = capsys.readouterr().err
    assert "a warning users should see" in err
    assert "Creating initial" not in err


@pytest.mark.parametrize("command", ["doctor", "add-dataset"])
def test_a_home_that_cannot_be_written_stops_doctor_and_add_dataset_in_one_line(
        command, tmp_path, monkeypatch, capsys):
    """A home under a file (as a read-only one, whoever runs it: root writes anywhere else):
    one line naming the folder and what to do, exit 2, instead of a traceback."""
    from pwa_pipeline.orchestration.cli import main

    (tmp_path / "file").write_text("")
    home = tmp_path / "file" / "home"
    monkeypatch.setenv("PWA_PIPELINE_HOME", str(home))
    monkeypatch.delenv("DAGSTER_HOME", raising=False)
    monkeypatch.delenv("PWA_DATASETS", raising=False)
    d = make_hure_vasak(n_samples=300, seed=7)
    pd.DataFrame({"u1": d.u_train[0][:, 0], "y1": d.y_train[0][:, 0]}).to_csv(
        tmp_path / "plant.csv", index=False)
    args = {"doctor": ["doctor"],
            "add-dataset": ["add-dataset", "plant", str(tmp_path / "plant.csv"), "--u", "u1",
                            "--y", "y1"]}[command]
    assert main(args) == 2
    err = capsys.readouterr().err
    folder = home / (".dagster_home" if command == "doctor" else "storage")
    assert err == (f"pwa-pipeline {command}: error: {folder}: Not a directory; make it "
                   f"writable, or set $PWA_PIPELINE_HOME (or $DAGSTER_HOME, $PWA_STORAGE, "
                   f"$PWA_DATASETS) to a folder this user can write\n")


def test_doctor_on_a_tracking_server_that_refuses_says_so_in_one_line(tmp_path, monkeypatch,
                                                                      capsys):
    """`doctor --tracking-uri` naming a port nothing listens on: one line naming the server
    (password masked), exit 2, instead of MLflow's retries and a 100-line traceback."""
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    _undo_mlflow_environment(monkeypatch)
    assert main(["doctor", "--tracking-uri", "http://ana:s3cret@127.0.0.1:9"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pwa-pipeline doctor: error: MLflow tracking server "
                          "http://ana:***@127.0.0.1:9 cannot be reached (")
    assert "s3cret" not in err and len(err.strip().splitlines()) == 1


def test_the_dagster_storage_failing_mid_run_stops_the_command_in_one_line(
        tmp_path, monkeypatch, capsys):
    """The Dagster instance's sqlite storage failing inside a run (a full disk: `disk I/O
    error`, raised out of the run as a 40-frame traceback): the summary of what was done,
    then one line naming the storage, the cause and what to do, exit 2."""
    import sqlite3

    from sqlalchemy.exc import OperationalError

    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    monkeypatch.delenv("PWA_DATASETS", raising=False)
    _undo_mlflow_environment(monkeypatch)

    def full_disk(*args, **kwargs):
        raise OperationalError('PRAGMA main.table_xinfo("runs")', {},
                               sqlite3.OperationalError("disk I/O error"))

    monkeypatch.setattr(dg.JobDefinition, "execute_in_process", full_disk)
    keys = ["hure_vasak|paper", "hure_vasak|default"]
    assert main(["run", *[a for k in keys for a in ("--partition", k)]]) == 2
    printed = capsys.readouterr()
    assert printed.out.rstrip().endswith(f"not run to the end: {', '.join(keys)}")
    assert printed.err == (
        f"pwa-pipeline run: error: the Dagster instance's storage in {tmp_path / 'home'} "
        f"failed during the run: disk I/O error; free space on that disk, then run again "
        f"(results already stored are kept)\n")


def test_a_dask_scheduler_gone_stops_the_next_partitions_in_one_line(monkeypatch):
    """After a partition's run failed on a scheduler that no longer answers, no further
    partition starts against it: one line naming the scheduler and what to do."""
    from pwa_pipeline.orchestration import dask_sweep
    from pwa_pipeline.orchestration.partition_runs import ServiceLost

    monkeypatch.setattr(dask_sweep, "CONNECT_TIMEOUT", 0.5)
    with pytest.raises(ServiceLost) as lost:
        dask_sweep.check_scheduler("tcp://127.0.0.1:9", "plant|default")
    message = str(lost.value)
    assert message.startswith("the dask scheduler tcp://127.0.0.1:9 stopped answering during "
                              "plant|default (")
    assert message.endswith("no further partition was started: start the scheduler and its "
                            "workers again (`dask scheduler`, `dask worker tcp://127.0.0.1:9`),"
                            " then run again")


def test_a_failure_is_told_by_its_root_cause_in_one_line():
    """Dagster wraps what a step raised (`Error occurred while executing op "X":`) and
    names it by its module path: the cause the code raised is what is said, a Dagster
    Failure by its description."""
    from pwa_pipeline.orchestration.partition_runs import root_cause

    @dg.asset
    def reads_a_file():
        try:
            raise KeyError("u1")
        except KeyError as exc:
            raise ValueError("plant.csv has no column 'u1'\nsecond line") from exc

    @dg.asset
    def writes_a_file():
        raise dg.Failure(description="cannot write /store/x.pkl: No space left on device")

    failures = dg.materialize([reads_a_file, writes_a_file],
                              raise_on_error=False).get_step_failure_events()
    errors = [e.event_specific_data.error for e in sorted(failures, key=lambda e: e.step_key)]
    assert errors[0].message.startswith(
        "dagster._core.errors.DagsterExecutionStepExecutionError: Error occurred")
    assert errors[1].message.startswith("dagster._core.definitions.events.Failure: ")
    assert [root_cause(e) for e in errors] == [
        "ValueError: plant.csv has no column 'u1'",
        "cannot write /store/x.pkl: No space left on device"]
