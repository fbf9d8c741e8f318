"""Dagster's supported PostgreSQL storage, as the docs configure it for several processes:
a throw-away PostgreSQL server on a loopback port, a ``dagster.yaml`` with ``storage:
postgres:``, and the command line's runs recorded in the database."""

import glob
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from benchmarks._ui import free_port
from pwa_pipeline.orchestration.instance import DAGSTER_YAML


def _postgres_bin() -> Path | None:
    """The folder of PostgreSQL's server programs (Debian keeps them off the PATH)."""
    found = next(iter(sorted(glob.glob("/usr/lib/postgresql/*/bin/pg_ctl"))), None) \
        or shutil.which("pg_ctl")
    return Path(found).resolve().parent if found else None


def _as_server_user(command: list[str]) -> list[str]:
    """PostgreSQL refuses to run as root: as root, run ``command`` as the user ``postgres``."""
    return ["runuser", "-u", "postgres", "--", *command] if os.geteuid() == 0 else command


@pytest.fixture(scope="module")
def postgres_url(system_package) -> Iterator[str]:
    """A fresh PostgreSQL cluster with a database ``dagster``, on a free loopback port; its
    URL. Stopped and deleted at the end."""
    bin_dir = _postgres_bin()
    missing = None if bin_dir else ("no PostgreSQL server programs (pg_ctl) found; install "
                                    "Debian's postgresql")
    if bin_dir and os.geteuid() == 0 and shutil.which("runuser") is None:
        missing = "running as root without runuser"
    system_package("the PostgreSQL storage test needs a PostgreSQL server", missing)
    folder = Path(tempfile.mkdtemp(prefix="pwa-postgres-"))
    if os.geteuid() == 0:
        shutil.chown(folder, "postgres", "postgres")
    data, port = folder / "data", free_port()
    subprocess.run(_as_server_user([str(bin_dir / "initdb"), "-D", str(data), "-U", "postgres",
                                    "--auth=trust"]), check=True, capture_output=True)
    subprocess.run(_as_server_user([
        str(bin_dir / "pg_ctl"), "-D", str(data), "-l", str(folder / "server.log"), "-w",
        "-o", f"-p {port} -k {folder} -c listen_addresses=127.0.0.1", "start"]),
        check=True, capture_output=True)
    try:
        subprocess.run([str(bin_dir / "createdb"), "-h", "127.0.0.1", "-p", str(port),
                        "-U", "postgres", "dagster"], check=True, capture_output=True)
        yield f"postgresql+psycopg2://postgres@127.0.0.1:{port}/dagster"
    finally:
        subprocess.run(_as_server_user([str(bin_dir / "pg_ctl"), "-D", str(data), "-m", "fast",
                                        "-w", "stop"]), capture_output=True)
        shutil.rmtree(folder, ignore_errors=True)


def test_the_documented_postgres_storage_records_the_command_lines_runs(
        postgres_url, tmp_path, mlflow_template):
    import dagster as dg
    import psycopg2

    home = tmp_path / ".dagster_home"
    home.mkdir()
    # the docs' section added to the file the command line writes; kept as edited. The
    # driver is named: SQLAlchemy 2.1 defaults to psycopg 3, dagster-postgres brings psycopg2
    config = DAGSTER_YAML + f"storage:\n  postgres:\n    postgres_url: \"{postgres_url}\"\n"
    (home / "dagster.yaml").write_text(config)
    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    env = {k: v for k, v in os.environ.items() if k != "MLFLOW_TRACKING_URI"}
    env.update(PWA_PIPELINE_HOME=str(tmp_path), DAGSTER_HOME=str(home),
               PWA_DATASETS=str(tmp_path / "datasets.json"))
    done = subprocess.run([sys.executable, "-m", "pwa_pipeline", "run", "--partition",
                           "hure_vasak|paper"], env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert (home / "dagster.yaml").read_text() == config
    assert not (home / "history").exists()  # no sqlite storage beside the database
    os.environ["DAGSTER_HOME"] = str(home)
    try:
        with dg.DagsterInstance.get() as instance:
            runs = instance.get_runs()
            storage = type(instance.run_storage).__name__
    finally:
        del os.environ["DAGSTER_HOME"]
    assert storage == "PostgresRunStorage"
    assert [r.status for r in runs] == [dg.DagsterRunStatus.SUCCESS] * 2  # partition, board
    assert {r.tags.get("dagster/partition") for r in runs} == {"hure_vasak|paper", None}
    with psycopg2.connect(postgres_url.replace("+psycopg2", "")) as conn, \
            conn.cursor() as cursor:
        cursor.execute("SELECT count(*) FROM runs")
        assert cursor.fetchone() == (2,)
        cursor.execute("SELECT count(*) FROM event_logs WHERE dagster_event_type = "
                       "'ASSET_MATERIALIZATION'")
        assert cursor.fetchone()[0] >= 15  # every asset of the partition, and the board
