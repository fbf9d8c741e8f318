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
