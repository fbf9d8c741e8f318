"""``deploy/compose.yaml`` brought up without Docker: every service but PostgreSQL started
from its own ``command`` and the shared environment (``x-pwa``), with the compose file's
host names, ports and volumes mapped to loopback ports and folders; PostgreSQL is a
throw-away server with the two databases the image's init script makes. Then what a team
does with it: a partition launched from the UI (submitted to the webserver, dequeued and
launched by the daemon) and one from the command line, at once, on the shared scheduler.
"""

import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

import dagster as dg
import pandas as pd
import pytest
import yaml

from benchmarks._cluster import (
    client_instance,
    postgres_missing,
    postgres_server,
    step_events,
    step_span,
    stop_group,
    wait_for_url,
)
from benchmarks._ui import free_port
from pwa_pipeline.datasets import make_hure_vasak
from pwa_pipeline.datasets.user import UserDataset
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.registry import DatasetRegistry

ROOT = Path(__file__).resolve().parents[2]
COMPOSE = ROOT / "deploy" / "compose.yaml"
#: The services the test starts from the compose file, in order (postgres stands apart).
STARTED = ("mlflow", "dask-scheduler", "dask-worker", "dagster-webserver", "dagster-daemon")


def _program(command: str) -> list[str]:
    """A compose ``command`` as arguments, its program the console script installed beside
    this interpreter (the image's PATH)."""
    args = shlex.split(command)
    return [str(Path(sys.executable).parent / args[0]), *args[1:]]


@pytest.fixture(scope="module")
def services(system_package, tmp_path_factory) -> Iterator[dict]:
    """Every service of the compose file, running; yields the environment of a process in
    the compose network (``x-pwa``'s, mapped) and the UI's port."""
    system_package("the compose test needs a PostgreSQL server", postgres_missing())
    compose = yaml.safe_load(COMPOSE.read_text())
    folder = tmp_path_factory.mktemp("compose")
    ports = {name: free_port() for name in ("mlflow", "dask", "dashboard", "web")}
    with ExitStack() as stack:
        postgres = stack.enter_context(postgres_server(("dagster", "mlflow")))
        mapping = [  # the compose network and volumes → loopback and folders
            ("pwa:${PWA_DB_PASSWORD:-pwa}@postgres:5432", postgres.split("//", 1)[1]),
            ("mlflow:5000", f"127.0.0.1:{ports['mlflow']}"),
            ("localhost:5000", f"127.0.0.1:{ports['mlflow']}"),
            ("--port 5000", f"--port {ports['mlflow']}"),
            ("dask-scheduler:8786", f"127.0.0.1:{ports['dask']}"),
            ("--port 8786", f"--port {ports['dask']}"),
            (":8787", f":{ports['dashboard']}"),
            ("-p 3000", f"-p {ports['web']}"),
            ("0.0.0.0", "127.0.0.1"),
            ("/opt/dagster/home", str(folder / "home")),
            ("/artifacts", str(folder / "artifacts")),
            ("file:///store", (folder / "store").as_uri()),
            ("/store", str(folder / "store")),
        ]

        pattern = re.compile("|".join(re.escape(old) for old, _ in mapping))

        def mapped(text: str) -> str:  # one pass: a replacement is never replaced again
            return pattern.sub(lambda match: dict(mapping)[match[0]], text)

        (folder / "home").mkdir()  # the volume of dagster.yaml
        shutil.copy(ROOT / "deploy" / "dagster.yaml", folder / "home" / "dagster.yaml")
        (folder / "store").mkdir()
        env = {**{k: v for k, v in os.environ.items()
                  if not k.startswith(("PWA_", "MLFLOW_", "DAGSTER_"))},
               **{k: mapped(v) for k, v in compose["x-pwa"]["environment"].items()}}
        registry = DatasetRegistry(Path(env["PWA_DATASETS"]))
        for seed, name in enumerate(("m1", "m2")):
            d = make_hure_vasak(n_samples=600, seed=20 + seed)
            pd.DataFrame({"u1": d.u_train[0][:, 0], "u2": d.u_train[0][:, 1], "y1": d.y_train[0][:, 0],
                          "y2": d.y_train[0][:, 1]}).to_csv(folder / f"{name}.csv", index=False)
            registry.add(UserDataset(name=name, path=str(folder / f"{name}.csv"),
                                     u=("u1", "u2"), y=("y1", "y2")))
        processes = []
        for name in STARTED:
            service = compose["services"][name]
            own = service.get("environment", compose["x-pwa"]["environment"])
            replicas = service.get("deploy", {}).get("replicas", 1)
            for _ in range(replicas):
                log = open(folder / f"{name}.log", "ab")  # noqa: SIM115 (closed by the stack)
                stack.callback(log.close)
                process = subprocess.Popen(
                    _program(mapped(service["command"])), cwd=ROOT, stdout=log,
                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                    start_new_session=True, env={**env, **{k: mapped(str(v))
                                                          for k, v in own.items()}})
                stack.callback(stop_group, process)
                processes.append((name, process))
        mlflow = env["MLFLOW_TRACKING_URI"]
        wait_for_url(f"{mlflow}/health", processes[0][1], folder / "mlflow.log")
        web = f"http://127.0.0.1:{ports['web']}"
        wait_for_url(f"{web}/server_info", processes[-2][1], folder / "dagster-webserver.log")
        from dask.distributed import Client

        with Client(env["PWA_DASK_SCHEDULER"], timeout=60) as client:
            client.wait_for_workers(compose["services"]["dask-worker"]["deploy"]["replicas"],
                                    timeout=120)
            workers = set(client.run(os.getpid).values())
        yield {"env": env, "web": ports["web"], "folder": folder, "workers": workers}


def _instance(env: dict[str, str]) -> dg.DagsterInstance:
    """The compose services' Dagster instance, as a process in the network opens it."""
    return client_instance(env["DAGSTER_HOME"], env["PWA_DAGSTER_POSTGRES_URL"])


def _waiting(instance: dg.DagsterInstance, keys: tuple[str, ...]) -> dict[str, bool]:
    """The partition of each ``sweep_dask`` run of ``keys``, and whether that run has said
    that it waits for the scheduler."""
    runs = instance.get_runs(dg.RunsFilter(job_name="sweep_dask",
                                           tags={"dagster/partition": list(keys)}))
    return {run.tags["dagster/partition"]: any(
        "Waiting for the dask scheduler" in e.user_message for e in instance.all_logs(run.run_id))
        for run in runs}


def _launchpad(env: dict[str, str]) -> dict:
    """The run configuration the UI's launchpad shows for ``sweep_dask``: the compose
    scheduler."""
    return {"execution": {"config": {"cluster": {"existing": {
        "address": env["PWA_DASK_SCHEDULER"]}}}}}


def _cli_sweep(env: dict[str, str], *keys: str) -> subprocess.Popen:
    """The compose file's documented command from a shell in a container, over ``keys``
    (its runs do not pass through the run queue)."""
    return subprocess.Popen(
        [sys.executable, "-m", "pwa_pipeline", "run", "--executor", "dask",
         *[a for key in keys for a in ("--partition", key)]], cwd=ROOT, env=env,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _until(condition, timeout: float, what) -> None:
    """Return once ``condition()`` holds; fail with ``what()`` after ``timeout`` s."""
    deadline = time.time() + timeout
    while not condition():
        assert time.time() < deadline, what()
        time.sleep(0.5)


@pytest.mark.slow
@pytest.mark.distributed
@pytest.mark.xdist_group("compose")
@pytest.mark.filterwarnings("ignore::DeprecationWarning:gql.*")
def test_the_compose_services_run_a_ui_run_and_a_command_line_run_in_turn(services):
    from dagster_graphql import DagsterGraphQLClient
    from dask.distributed import Client, Lock, Variable
    from mlflow.tracking import MlflowClient

    from pwa_pipeline.orchestration.jobs import RUN_LOCK

    env, ui_key, cli_key = services["env"], "m1|default", "m2|default"
    with Client(env["PWA_DASK_SCHEDULER"], timeout=10) as client, _instance(env) as instance:
        # the scheduler is busy (this test holds its lock) when both runs arrive
        busy = Lock(RUN_LOCK, scheduler_rpc=client.scheduler, loop=client.loop)
        assert busy.acquire(timeout=5)
        Variable(f"{RUN_LOCK}/holder", client=client).set("the test's client")
        # from the UI, queued for the daemon, which launches it
        run_id = DagsterGraphQLClient("127.0.0.1", port_number=services["web"]) \
            .submit_job_execution("sweep_dask", run_config=_launchpad(env),
                                  tags={"dagster/partition": ui_key})
        keys = (ui_key, cli_key)
        _until(lambda: _waiting(instance, keys) == {ui_key: True}, 120,
               lambda: _waiting(instance, keys))
        sweep = _cli_sweep(env, cli_key)
        _until(lambda: _waiting(instance, keys) == {ui_key: True, cli_key: True}, 120,
               lambda: (_waiting(instance, keys), sweep.poll()))
        Variable(f"{RUN_LOCK}/holder", client=client).delete()
        busy.release()
        out = sweep.communicate(timeout=600)[0]
        assert sweep.returncode == 0, out[-4000:]
        _until(lambda: instance.get_run_by_id(run_id).is_finished, 300,
               lambda: instance.get_run_by_id(run_id).status)
        runs = instance.get_runs(dg.RunsFilter(job_name="sweep_dask",
                                               tags={"dagster/partition": list(keys)}))
        assert {r.tags["dagster/partition"]: r.status for r in runs} == {
            ui_key: dg.DagsterRunStatus.SUCCESS, cli_key: dg.DagsterRunStatus.SUCCESS}
        # every step on a compose worker, the two runs' steps one run after the other, each
        # run saying which run it waited for and when its steps could start
        spans, pids = [], set()
        for run in runs:
            said = [e.user_message for e in instance.all_logs(run.run_id)
                    if e.user_message.startswith(("Waiting for", "The dask scheduler"))]
            assert said == [
                f"Waiting for the dask scheduler {env['PWA_DASK_SCHEDULER']}: the test's "
                f"client holds it. This run's steps start when it ends; terminate this run "
                f"to give up.",
                f"The dask scheduler {env['PWA_DASK_SCHEDULER']} is free: this run's steps "
                f"start."], said
            spans.append(step_span(instance, run.run_id))
            pids |= {e.dagster_event.pid for e in step_events(instance, run.run_id)}
    spans.sort()
    assert spans[0][1] <= spans[1][0], spans
    assert pids == services["workers"]
    # the results in the shared store and the tracking server
    store = PartitionedFileIOManager(base_dir=env["PWA_STORAGE"])
    for key in (ui_key, cli_key):
        comparison = store.load(dg.AssetKey("comparison"), key)
        assert len(comparison) >= 3
    client = MlflowClient(tracking_uri=env["MLFLOW_TRACKING_URI"])
    for dataset in ("m1", "m2"):
        experiment = client.get_experiment_by_name(f"pwa-pipeline/{dataset}")
        assert experiment.artifact_location.startswith("mlflow-artifacts:")
        assert client.search_runs([experiment.experiment_id])


@pytest.mark.distributed
@pytest.mark.xdist_group("compose")
@pytest.mark.filterwarnings("ignore::DeprecationWarning:gql.*")
def test_runs_waiting_for_a_busy_scheduler_stop_when_terminated_or_interrupted(services):
    """Terminated from the UI, a run waiting for the scheduler is cancelled; Ctrl-C stops
    the command line's, which says so and starts no further partition."""
    from dagster_graphql import DagsterGraphQLClient
    from dask.distributed import Client, Lock

    from pwa_pipeline.orchestration.jobs import RUN_LOCK

    env, ui_key, cli_key = services["env"], "m1|output_error", "m2|output_error"
    keys = (ui_key, cli_key)
    ui = DagsterGraphQLClient("127.0.0.1", port_number=services["web"])
    with Client(env["PWA_DASK_SCHEDULER"], timeout=10) as client, _instance(env) as instance:
        busy = Lock(RUN_LOCK, scheduler_rpc=client.scheduler, loop=client.loop)
        assert busy.acquire(timeout=5)
        try:
            run_id = ui.submit_job_execution("sweep_dask", run_config=_launchpad(env),
                                             tags={"dagster/partition": ui_key})
            sweep = _cli_sweep(env, cli_key, "m2|default")
            _until(lambda: _waiting(instance, keys) == {ui_key: True, cli_key: True}, 120,
                   lambda: (_waiting(instance, keys), sweep.poll() is None
                            or sweep.communicate()[0][-3000:]))
            t0 = time.time()
            ui.terminate_run(run_id)
            sweep.send_signal(signal.SIGINT)
            out = sweep.communicate(timeout=60)[0]
            _until(lambda: instance.get_run_by_id(run_id).is_finished, 60,
                   lambda: instance.get_run_by_id(run_id).status)
            stopped = time.time() - t0
            cancelled = instance.all_logs(run_id, of_type=dg.DagsterEventType.RUN_CANCELED)
        finally:
            busy.release()
        runs = {r.tags["dagster/partition"]: r.status for r in instance.get_runs(
            dg.RunsFilter(job_name="sweep_dask", tags={"dagster/partition": list(keys)}))}
    assert runs[ui_key] == dg.DagsterRunStatus.CANCELED
    assert "stopped while waiting for the dask scheduler" in \
        cancelled[0].dagster_event.event_specific_data.error.message
    assert runs[cli_key] == dg.DagsterRunStatus.FAILURE  # no termination was requested
    assert stopped < 20
    assert sweep.returncode == 130, out[-4000:]
    assert f"{cli_key}: INTERRUPTED after" in out
    assert "materialising m2|default" not in out and "not run to the end: m2|default" in out
