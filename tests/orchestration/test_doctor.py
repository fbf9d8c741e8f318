"""What interrupted runs leave behind, found and repaired."""

import os
import shutil
import time

import dagster as dg


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



def test_doctor_finds_a_killed_run_at_once_and_leaves_a_live_one(tmp_path, mlflow_template,
                                                                  robot):
    """SIGKILL of ``run`` in the middle of a long partition (the robot's structure, refined on
    the free run for up to a minute): with the default age, doctor lists its Dagster run
    (its process is gone) and the MLflow runs it opened; a run still going is not listed."""
    import signal
    import subprocess
    import sys

    from mlflow.tracking import MlflowClient

    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    env = {k: v for k, v in os.environ.items() if k not in ("DAGSTER_HOME", "MLFLOW_TRACKING_URI")}
    env.update(PWA_PIPELINE_HOME=str(tmp_path), PWA_DATASETS=str(tmp_path / "datasets.json"))
    cli = [sys.executable, "-m", "pwa_pipeline"]
    out = tmp_path / "out.txt"
    with open(out, "w") as sink:
        proc = subprocess.Popen([*cli, "run", "--partition", "kuka_robot|robot"], env=env,
                                stdout=sink, stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.time() + 120
    while "pwa_fit" not in out.read_text():  # the run is fitting the PWA chain
        assert proc.poll() is None and time.time() < deadline, out.read_text()[-2000:]
        time.sleep(0.2)
    doctor = [*cli, "doctor", "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}"]
    env["DAGSTER_HOME"] = str(tmp_path / ".dagster_home")
    live = subprocess.run(doctor, env=env, capture_output=True, text=True)
    assert live.returncode == 0, live.stdout  # a live run is not left behind
    assert proc.poll() is None, out.read_text()[-2000:]  # (still going when doctor looked)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    found = subprocess.run(doctor, env=env, capture_output=True, text=True)
    assert found.returncode == 1, found.stdout
    os.environ["DAGSTER_HOME"] = env["DAGSTER_HOME"]
    try:
        with dg.DagsterInstance.get() as instance:
            [run] = [r for r in instance.get_runs() if r.tags.get("dagster/partition")]
    finally:
        del os.environ["DAGSTER_HOME"]
    assert run.run_id in found.stdout
    repaired = subprocess.run([*doctor, "--repair"], env=env, capture_output=True, text=True)
    assert repaired.returncode == 0
    os.environ["DAGSTER_HOME"] = env["DAGSTER_HOME"]
    try:
        with dg.DagsterInstance.get() as instance:
            assert instance.get_run_by_id(run.run_id).status == dg.DagsterRunStatus.FAILURE
    finally:
        del os.environ["DAGSTER_HOME"]
    client = MlflowClient(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    running = [r for e in client.search_experiments()
               for r in client.search_runs([e.experiment_id], "attributes.status = 'RUNNING'")]
    assert running == []
    assert subprocess.run(doctor, env=env, capture_output=True).returncode == 0
