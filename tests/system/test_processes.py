"""Runs as separate processes, ended the hard way: Ctrl-C to ``pwa-pipeline run`` while a
robot partition fits, and SIGKILL found and repaired by ``pwa-pipeline doctor``. Each waits
for a real run to reach the PWA fit, so they take a minute or more."""

import os
import shutil
import signal
import subprocess
import sys
import time

import dagster as dg
import pytest


def test_an_interrupt_ends_the_run_in_flight_and_starts_no_other(tmp_path, mlflow_template,
                                                                  robot):
    """Ctrl-C (SIGINT to the command's process group, as a terminal sends it) while a robot
    partition with local sets of 250 rows runs: it ends as an interrupted run, the next
    never starts, exit status 130, no run is left STARTED, and the output says so in one
    line per event, without a traceback. An interrupt can wait for
    the step in flight to end, and one that a library dropped is sent again 5 s later, so the
    command is given 150 s to end."""
    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    (tmp_path / "hparams.toml").write_text(
        '[longer.kuka_robot]\npreset = "default"\nna = 2\nnb = 2\n'
        'local_models.n_rho = 250\n\n'
        '[quick.hure_vasak]\npreset = "default"\nna = 1\nnb = 1\n')
    env = {k: v for k, v in os.environ.items()
           if k not in ("DAGSTER_HOME", "MLFLOW_TRACKING_URI", "PWA_DATASETS")}
    env["PWA_PIPELINE_HOME"] = str(tmp_path)
    env["PWA_HPARAMS"] = str(tmp_path / "hparams.toml")
    keys = ["kuka_robot|longer", "hure_vasak|quick"]
    out = tmp_path / "out.txt"
    with open(out, "w") as sink:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pwa_pipeline", "run",
             *[a for k in keys for a in ("--partition", k)]], env=env, stdout=sink,
            stderr=subprocess.STDOUT, start_new_session=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 120
    while "pwa_fit" not in out.read_text():  # the run is fitting the PWA chain
        assert proc.poll() is None and time.time() < deadline, out.read_text()[-3000:]
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGINT)
    try:
        status = proc.wait(timeout=150)
    except subprocess.TimeoutExpired:  # what each process was doing goes into the failure
        os.killpg(proc.pid, signal.SIGKILL)
        raise AssertionError("not ended 150 s after Ctrl-C:\n" + out.read_text()[-6000:])
    assert status == 130
    text = out.read_text()
    # one line per event, no stack trace: not Dagster's, nor its log-mirroring helpers'
    assert "Traceback" not in text and "Stack Trace" not in text, text
    assert "\n    pwa_fit: interrupted (Ctrl-C or SIGTERM)\n" in text
    summary = text.split("\nSummary\n")[1]
    assert f"  {keys[0]}: INTERRUPTED after" in summary
    assert f"  not run to the end: {keys[1]}" in summary
    assert f"=== materialising {keys[1]} ===" not in text
    os.environ["DAGSTER_HOME"] = str(tmp_path / ".dagster_home")
    try:
        with dg.DagsterInstance.get() as instance:
            statuses = [r.status for r in instance.get_runs()]
    finally:
        del os.environ["DAGSTER_HOME"]
    assert statuses == [dg.DagsterRunStatus.FAILURE]


@pytest.mark.slow
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
