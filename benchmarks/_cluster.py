"""Throw-away shared services on loopback, each started by the command the deployment docs
give: a PostgreSQL server (``initdb``, ``pg_ctl``), an MLflow tracking server (``mlflow
server`` on PostgreSQL, artifacts served by it), a dask scheduler and workers (``dask
scheduler``, ``dask worker``). Each runs in its own process group and is stopped, group and
all, when its context ends. Used by the distributed tests and ``benchmarks/distributed.py``.
"""

import glob
import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from benchmarks._ui import free_port

#: The hyper-parameter sets of the distributed tests and benchmark: the default and a small
#: paper setting for every registered data set.
HPARAMS = """[default."*"]
preset = "default"

[paper."*"]
preset = "paper"
local_models.n_rho = 12
clustering.eps = 0.3
clustering.min_pts = 8
"""


def postgres_bin() -> Path | None:
    """The folder of PostgreSQL's server programs (Debian keeps them off the PATH, in
    ``/usr/lib/postgresql/<version>/bin``)."""
    found = shutil.which("pg_ctl") or next(
        iter(sorted(glob.glob("/usr/lib/postgresql/*/bin/pg_ctl"))), None)
    return Path(found).resolve().parent if found else None


def postgres_missing() -> str | None:
    """Why a throw-away PostgreSQL server cannot be started here, or None if it can."""
    if postgres_bin() is None:
        return "no PostgreSQL server programs (pg_ctl) found; install Debian's postgresql"
    if os.geteuid() == 0 and shutil.which("runuser") is None:
        return "running as root without runuser"
    return None


def as_server_user(command: list[str]) -> list[str]:
    """PostgreSQL refuses to run as root: as root, run ``command`` as the user ``postgres``."""
    return ["runuser", "-u", "postgres", "--", *command] if os.geteuid() == 0 else command


def stop_group(process: subprocess.Popen, timeout: float = 20) -> None:
    """End ``process`` and its process group: SIGTERM, then SIGKILL after ``timeout`` s."""
    for sig, wait in ((signal.SIGTERM, timeout), (signal.SIGKILL, None)):
        try:
            os.killpg(process.pid, sig)
        except ProcessLookupError:
            pass
        try:
            process.wait(timeout=wait)
            return
        except subprocess.TimeoutExpired:
            continue


@contextmanager
def postgres_server(databases: tuple[str, ...] = ("dagster",)) -> Iterator[str]:
    """A fresh PostgreSQL cluster on a free loopback port with ``databases`` created, which
    asks for a password over TCP as a team's server does; yields its URL without a database
    (``postgresql+psycopg2://postgres:<password>@127.0.0.1:<port>``; append ``/<name>``).
    Stopped and deleted at the end."""
    bin_dir = postgres_bin()
    folder = Path(tempfile.mkdtemp(prefix="pwa-postgres-"))
    data, port, password = folder / "data", free_port(), secrets.token_hex(8)
    (folder / "password").write_text(password)
    if os.geteuid() == 0:
        for path in (folder, folder / "password"):
            shutil.chown(path, "postgres", "postgres")
    subprocess.run(as_server_user([str(bin_dir / "initdb"), "-D", str(data), "-U", "postgres",
                                   "--auth-local=trust", "--auth-host=scram-sha-256",
                                   f"--pwfile={folder / 'password'}"]),
                   check=True, capture_output=True)
    subprocess.run(as_server_user([
        str(bin_dir / "pg_ctl"), "-D", str(data), "-l", str(folder / "server.log"), "-w",
        "-o", f"-p {port} -k {folder} -c listen_addresses=127.0.0.1", "start"]),
        check=True, capture_output=True)
    try:
        for name in databases:
            subprocess.run([str(bin_dir / "createdb"), "-h", "127.0.0.1", "-p", str(port),
                            "-U", "postgres", name], check=True, capture_output=True,
                           env={**os.environ, "PGPASSWORD": password})
        yield f"postgresql+psycopg2://postgres:{password}@127.0.0.1:{port}"
    finally:
        subprocess.run(as_server_user([str(bin_dir / "pg_ctl"), "-D", str(data), "-m", "fast",
                                       "-w", "stop"]), capture_output=True)
        shutil.rmtree(folder, ignore_errors=True)


def wait_for_url(url: str, process: subprocess.Popen, log: Path, timeout: float = 120) -> None:
    """Return once ``url`` answers 200; raise with the end of ``log`` if ``process`` ends
    first or ``timeout`` s pass."""
    deadline = time.time() + timeout
    while True:
        try:
            with urllib.request.urlopen(url, timeout=2) as answer:
                if answer.status == 200:
                    return
        except OSError:
            pass
        if process.poll() is not None or time.time() > deadline:
            raise RuntimeError(f"{url} did not come up:\n{log.read_text()[-3000:]}")
        time.sleep(0.3)


@contextmanager
def mlflow_server(backend_uri: str, artifacts: Path, port: int, log: Path) -> Iterator[str]:
    """``mlflow server`` on ``backend_uri`` with the artifacts it serves itself
    (``--serve-artifacts``) in ``artifacts``, one worker, no job execution; yields its URL
    once ``/health`` answers."""
    env = {**os.environ, "MLFLOW_SERVER_ENABLE_JOB_EXECUTION": "false"}
    env.pop("MLFLOW_TRACKING_URI", None)
    with open(log, "ab") as out:
        server = subprocess.Popen(
            [sys.executable, "-m", "mlflow", "server", "--backend-store-uri", backend_uri,
             "--serve-artifacts", "--artifacts-destination", str(artifacts),
             "--host", "127.0.0.1", "--port", str(port), "--workers", "1"],
            env=env, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_for_url(f"{url}/health", server, log)
        yield url
    finally:
        stop_group(server)


@dataclass
class DaskCluster:
    """A dask scheduler and its worker processes (each ``dask worker`` a nanny and the worker
    it restarts), started on their own."""

    address: str
    scheduler: subprocess.Popen
    workers: list[subprocess.Popen] = field(default_factory=list)


@contextmanager
def dask_cluster(n_workers: int, env: dict[str, str], log: Path) -> Iterator[DaskCluster]:
    """``dask scheduler`` on a free loopback port and ``n_workers`` single-threaded
    ``dask worker`` processes with the environment ``env`` (the stores they share); yields
    once every worker has joined."""
    from dask.distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    common = {"stdout": None, "stderr": subprocess.STDOUT, "stdin": subprocess.DEVNULL,
              "start_new_session": True, "env": {**os.environ, **env}}
    with open(log, "ab") as out:
        common["stdout"] = out
        cluster = DaskCluster(address, subprocess.Popen(
            [sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port",
             str(port), "--no-dashboard"], **common))
        try:
            for _ in range(n_workers):
                cluster.workers.append(subprocess.Popen(
                    [sys.executable, "-m", "dask", "worker", address, "--nthreads", "1",
                     "--nworkers", "1", "--no-dashboard", "--host", "127.0.0.1"], **common))
            with Client(address, timeout=60) as client:
                client.wait_for_workers(n_workers, timeout=120)
            yield cluster
        finally:
            for process in [*cluster.workers, cluster.scheduler]:
                stop_group(process)


def client_instance(dagster_home: str, postgres_url: str):
    """The Dagster instance a client of the shared services opens (``$DAGSTER_HOME`` and
    ``$PWA_DAGSTER_POSTGRES_URL`` as given), its home prepared as the command line prepares
    it, whichever comes first; this process's environment is left as it was."""
    from pwa_pipeline.orchestration.instance import POSTGRES_ENV, prepare_instance

    variables = {"DAGSTER_HOME": dagster_home, POSTGRES_ENV: postgres_url}
    os.environ.update(variables)
    try:
        return prepare_instance()
    finally:
        for name in variables:
            del os.environ[name]


def step_events(instance, run_id: str) -> list:
    """A run's step starts and successes (its run may have begun earlier, waiting for the
    scheduler), each with the pid of the process that ran the step."""
    return [e for e in instance.all_logs(run_id) if e.is_dagster_event
            and e.dagster_event.event_type_value in ("STEP_START", "STEP_SUCCESS")]


def step_span(instance, run_id: str) -> tuple[float, float]:
    """When a run's first step began and its last step ended."""
    times = [e.timestamp for e in step_events(instance, run_id)]
    return min(times), max(times)
