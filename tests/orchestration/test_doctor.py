"""What interrupted runs leave behind, found and repaired."""

import os
import shutil
import time

import dagster as dg
import pytest


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
    never = instance.add_run(dg.DagsterRun(job_name="sweep",
                                           status=dg.DagsterRunStatus.NOT_STARTED))
    client = MlflowClient(tracking_uri=uri)
    mlflow_run = client.create_run(client.create_experiment("pwa-pipeline/d"),
                                   tags={"dagster_run_id": run.run_id})
    tmp = tmp_path / "storage" / "pwa_model" / "d" / ".s.pkl.abc.tmp"
    tmp.parent.mkdir(parents=True)
    tmp.write_text("half")
    os.utime(tmp, (time.time() - 600, time.time() - 600))
    # the run logged no process: taken for left behind once START_GRACE old
    monkeypatch.setattr("pwa_pipeline.orchestration.doctor.START_GRACE", 0.5)
    time.sleep(1.1)  # MLflow and Dagster keep second-resolution start times
    args = ["doctor", "--older-than", "0.01", "--tracking-uri", uri]
    assert main(args) == 1
    report = capsys.readouterr().out
    assert run.run_id in report and mlflow_run.info.run_id in report and str(tmp) in report
    assert never.run_id in report
    assert main(args + ["--repair"]) == 0
    assert instance.get_run_by_id(run.run_id).status == dg.DagsterRunStatus.FAILURE
    assert instance.get_run_by_id(never.run_id).status == dg.DagsterRunStatus.FAILURE
    assert client.get_run(mlflow_run.info.run_id).info.status == "KILLED"
    assert not tmp.exists()
    assert main(args) == 0  # nothing left


@pytest.mark.parametrize("value", ["-5", "nan", "inf"])
def test_doctor_refuses_an_age_that_is_negative_or_not_finite(value, tmp_path, monkeypatch,
                                                              capsys):
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    with pytest.raises(SystemExit) as stop:
        main(["doctor", "--older-than", value, "--tracking-uri",
              f"sqlite:///{tmp_path / 'mlflow.db'}"])
    assert stop.value.code == 2
    assert (f"argument --older-than: must be a finite number of minutes >= 0, got {value!r}"
            in capsys.readouterr().err)
    assert not (tmp_path / "home").exists() and not (tmp_path / "mlflow.db").exists()


def _half_made_store(db):
    """What SIGKILL during MLflow's first schema creation leaves: some tables, no version."""
    import sqlite3

    con = sqlite3.connect(db)
    con.execute("CREATE TABLE entity_associations (association_id VARCHAR(36) PRIMARY KEY)")
    con.execute("CREATE TABLE experiments (experiment_id INTEGER PRIMARY KEY, name TEXT)")
    con.commit()
    con.close()


def test_doctor_moves_a_half_made_mlflow_store_aside(tmp_path, monkeypatch, capsys):
    from mlflow.tracking import MlflowClient

    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    db = tmp_path / "mlflow.db"
    _half_made_store(db)
    uri = f"sqlite:///{db}"
    args = ["doctor", "--tracking-uri", uri]
    assert main(args) == 1
    out = capsys.readouterr().out
    assert "half made" in out and str(db) in out
    assert main(args + ["--repair"]) == 0
    out = capsys.readouterr().out
    aside = [p for p in tmp_path.iterdir() if p.name.startswith("mlflow.db.broken-")]
    assert len(aside) == 1 and str(aside[0]) in out  # kept, never deleted
    assert len([line for line in out.splitlines() if "half-made" in line]) == 1
    MlflowClient(tracking_uri=uri).search_experiments()  # the new store works
    assert main(args) == 0


def test_a_run_refuses_a_half_made_mlflow_store_in_one_line(tmp_path):
    from pwa_pipeline.orchestration.tracking import MLflowTracker

    db = tmp_path / "mlflow.db"
    _half_made_store(db)
    with pytest.raises(dg.Failure, match="doctor --repair"):
        MLflowTracker(tracking_uri=f"sqlite:///{db}").check_reachable()


def test_a_store_killed_while_created_leaves_no_half_made_database(tmp_path):
    import signal
    import subprocess
    import sys

    from pwa_pipeline.orchestration.tracking import MLflowTracker

    db = tmp_path / "mlflow.db"
    uri = f"sqlite:///{db}"
    code = ("import sys, time\n"
            "from pwa_pipeline.orchestration.tracking import MLflowTracker\n"
            "import mlflow.store.db.utils as u\n"
            "upgrade = u._upgrade_db\n"
            "def slow(engine):\n"
            "    print('migrating', flush=True); time.sleep(60)\n"
            "u._upgrade_db = slow\n"
            f"MLflowTracker(tracking_uri={uri!r}).client()\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "migrating"  # tables made, not migrated
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert not db.exists()
    tracker = MLflowTracker(tracking_uri=uri)
    tracker.check_reachable()
    tracker.client().search_experiments()  # the next run creates it whole
    assert db.is_file() and not list(tmp_path.glob(".mlflow.db.*.tmp"))


def test_doctor_ends_the_models_a_killed_logging_left_pending(tmp_path, mlflow_template,
                                                             monkeypatch, capsys):
    import sqlite3

    from mlflow.tracking import MlflowClient

    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))
    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    uri = f"sqlite:///{db}"
    client = MlflowClient(tracking_uri=uri)
    exp = client.create_experiment("pwa-pipeline/d")
    run = client.create_run(exp)
    client.set_terminated(run.info.run_id, "KILLED")
    # what SIGKILL 0.2 s into mlflow.pyfunc.log_model leaves: a logged model PENDING; and a
    # model version a registry left PENDING_REGISTRATION
    pending = client.create_logged_model(exp, name="model", source_run_id=run.info.run_id)
    ready = client.create_logged_model(exp, name="model", source_run_id=run.info.run_id)
    client.finalize_logged_model(ready.model_id, "READY")
    client.create_registered_model("pwa-pipeline.d.pwarx")
    version = client.create_model_version("pwa-pipeline.d.pwarx", "file:///nowhere",
                                          run.info.run_id)
    kept = client.create_model_version("pwa-pipeline.d.pwarx", "file:///nowhere",
                                       run.info.run_id)
    con = sqlite3.connect(db)
    con.execute("UPDATE model_versions SET status = 'PENDING_REGISTRATION' WHERE version = ?",
                (int(version.version),))
    con.commit()
    con.close()
    time.sleep(1.1)
    args = ["doctor", "--older-than", "0.01", "--tracking-uri", uri]
    assert main(args) == 1
    report = capsys.readouterr().out
    assert pending.model_id in report and ready.model_id not in report
    assert "pwa-pipeline.d.pwarx version 1" in report
    assert main(["doctor", "--tracking-uri", uri]) == 0  # younger than an hour: left alone
    capsys.readouterr()
    assert main(args + ["--repair"]) == 0
    out = capsys.readouterr().out
    assert client.get_logged_model(pending.model_id).status == "FAILED"
    assert client.get_logged_model(ready.model_id).status == "READY"
    assert [v.version for v in client.search_model_versions()] == [kept.version]
    assert f"Marked the logged model {pending.model_id} FAILED" in out  # one line each
    assert "Deleted pwa-pipeline.d.pwarx version 1" in out
    assert main(args) == 0
