"""Dagster's supported PostgreSQL storage, as the docs configure it for several processes:
a throw-away PostgreSQL server on a loopback port, a ``dagster.yaml`` with ``storage:
postgres:`` (written by hand, or generated from ``$PWA_DAGSTER_POSTGRES_URL``), the command
line's runs recorded in the database, and bad URLs refused with a clear message."""

import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from benchmarks._cluster import postgres_missing, postgres_server
from benchmarks._ui import free_port
from pwa_pipeline.orchestration.instance import (
    DAGSTER_YAML,
    POSTGRES_ENV,
    POSTGRES_YAML,
    check_postgres_url,
    prepare_instance,
)


@pytest.fixture(scope="module")
def postgres_url(system_package) -> Iterator[str]:
    """A fresh PostgreSQL cluster with a database ``dagster``, on a free loopback port; its
    URL. Stopped and deleted at the end."""
    system_package("the PostgreSQL storage test needs a PostgreSQL server", postgres_missing())
    with postgres_server(("dagster",)) as server:
        yield f"{server}/dagster"


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


def test_the_generated_instance_follows_the_url_variable(postgres_url, tmp_path, monkeypatch):
    import psycopg2

    home = tmp_path / "home"
    monkeypatch.setenv("DAGSTER_HOME", str(home))
    monkeypatch.delenv(POSTGRES_ENV, raising=False)
    prepare_instance().dispose()
    assert (home / "dagster.yaml").read_text() == DAGSTER_YAML
    monkeypatch.setenv(POSTGRES_ENV, postgres_url)
    instance = prepare_instance()
    try:
        # the file names the variable, never the URL: no password on disk
        assert (home / "dagster.yaml").read_text() == POSTGRES_YAML
        assert postgres_url not in POSTGRES_YAML
        assert type(instance.run_storage).__name__ == "PostgresRunStorage"
        assert type(instance.event_log_storage).__name__ == "PostgresEventLogStorage"
    finally:
        instance.dispose()
    with psycopg2.connect(postgres_url.replace("+psycopg2", "")) as conn, \
            conn.cursor() as cursor:
        cursor.execute("SELECT count(*) FROM information_schema.tables WHERE table_name = "
                       "'runs'")
        assert cursor.fetchone() == (1,)
    monkeypatch.delenv(POSTGRES_ENV)
    prepare_instance().dispose()  # generated, so it follows the variable back
    assert (home / "dagster.yaml").read_text() == DAGSTER_YAML


@pytest.mark.parametrize("url, problem", [
    ("mysql://u:secret@127.0.0.1/dagster", "is not a PostgreSQL URL"),
    ("postgresql+psycopg2://u:secret@127.0.0.1:5432", "names no database"),
    ("postgresql+psycopg2://u:secret@127.0.0.1:5432/", "names no database"),
    ("postgresql+nodriver://u:secret@127.0.0.1:5432/dagster", "its driver cannot be loaded"),
])
def test_a_bad_postgres_url_is_refused_naming_the_problem_and_masking_the_password(url,
                                                                                   problem):
    with pytest.raises(ValueError, match=problem) as caught:
        check_postgres_url(url)
    assert "secret" not in str(caught.value) and "u:***@127.0.0.1" in str(caught.value)
    check_postgres_url("postgresql+psycopg2://u:secret@127.0.0.1:5432/dagster")


def _refused(url: str, tmp_path, monkeypatch) -> str:
    """The message with which the command line refuses the PostgreSQL URL ``url``: within
    30 s, before the Dagster home is made, in one line with exit status 2."""
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    monkeypatch.setenv(POSTGRES_ENV, url)
    t0 = time.perf_counter()
    with pytest.raises(ValueError) as caught:
        prepare_instance()
    assert time.perf_counter() - t0 < 30
    assert not (tmp_path / "home").exists()
    assert main(["doctor"]) == 2
    return str(caught.value)


def test_a_database_that_does_not_answer_fails_within_seconds_naming_it(tmp_path,
                                                                        monkeypatch):
    """Refused at once, with the server's reason, rather than after Dagster's retries."""
    port = free_port()  # nothing listens there
    message = _refused(f"postgresql+psycopg2://dagster:secret@127.0.0.1:{port}/db", tmp_path,
                       monkeypatch)
    assert message.startswith(f"Dagster's PostgreSQL storage (postgresql+psycopg2://dagster:***@"
                              f"127.0.0.1:{port}/db) cannot be used: connection to server at "
                              f"\"127.0.0.1\", port {port} failed: Connection refused. ")
    assert "secret" not in message and "nothing was run" in message


def test_wrong_credentials_fail_within_seconds_naming_the_server_and_masking_them(
        postgres_url, tmp_path, monkeypatch):
    """The server asks for a password: a wrong one is refused with the server's reason and
    the URL, its password masked."""
    user, rest = postgres_url.split("//", 1)[1].split("@", 1)
    message = _refused(postgres_url.replace(user, "postgres:guess3d"), tmp_path, monkeypatch)
    assert message.startswith(f"Dagster's PostgreSQL storage (postgresql+psycopg2://postgres:"
                              f"***@{rest}) cannot be used: connection to server at")
    assert 'password authentication failed for user "postgres"' in message
    assert "guess3d" not in message and user.split(":")[1] not in message


@pytest.mark.slow
@pytest.mark.parametrize("interrupt", [False, True])
def test_a_server_stopped_mid_run_ends_the_command_in_one_line(interrupt, system_package,
                                                               tmp_path, mlflow_template):
    """PostgreSQL stopped (fast shutdown) while ``run`` fits its first partition: after
    Dagster's retries, the command ends with one line naming the storage and what to do,
    exit 2, and starts no other partition (it raised ``DagsterPostgresException`` in a
    traceback, exit 1); with Ctrl-C during the retries, exit 130. The retries are said in
    one line (each was four lines of psycopg2's)."""
    import signal

    import psutil

    system_package("the PostgreSQL storage test needs a PostgreSQL server", postgres_missing())
    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    with postgres_server(("dagster",)) as server:
        port = server.rsplit(":", 1)[1]
        env = {k: v for k, v in os.environ.items()
               if k not in ("DAGSTER_HOME", "MLFLOW_TRACKING_URI", "PWA_DATASETS")}
        env.update(PWA_PIPELINE_HOME=str(tmp_path), **{POSTGRES_ENV: f"{server}/dagster"})
        keys = ["hure_vasak|paper", "hure_vasak|default"]
        out = tmp_path / "out.txt"
        with open(out, "w") as sink:
            proc = subprocess.Popen(
                [sys.executable, "-m", "pwa_pipeline", "run",
                 *[a for k in keys for a in ("--partition", k)]], env=env, stdout=sink,
                stderr=subprocess.STDOUT, start_new_session=True)
        deadline = time.time() + 120
        while "pwa_fit" not in out.read_text():
            assert proc.poll() is None and time.time() < deadline, out.read_text()[-3000:]
            time.sleep(0.2)
        [postmaster] = [p for p in psutil.process_iter(["cmdline"]) if p.info["cmdline"]
                        and f"-p {port}" in " ".join(p.info["cmdline"])]
        postmaster.send_signal(signal.SIGINT)  # PostgreSQL's fast shutdown
        if interrupt:
            time.sleep(3)
            os.killpg(proc.pid, signal.SIGINT)
        try:
            status = proc.wait(timeout=180)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            raise AssertionError("not ended:\n" + out.read_text()[-6000:])
    text = out.read_text()
    assert "Traceback" not in text and "Stack Trace" not in text, text[-6000:]
    # dagster-postgres logged each retry, four lines each, for 30 s: said once, in one line
    assert "Retrying failed database" not in text and "sqlalche.me" not in text, text[-6000:]
    assert text.count("the Dagster instance's PostgreSQL storage does not answer (") == 1
    assert f"=== materialising {keys[1]} ===" not in text
    assert f"  not run to the end: {', '.join(keys)}" in text
    if interrupt:
        assert status == 130
        return
    assert status == 2
    assert text.rstrip().splitlines()[-1] == (
        "pwa-pipeline run: error: the Dagster instance's PostgreSQL storage failed during the "
        "run: too many retries for DB connection; check that the PostgreSQL server runs (and "
        "$PWA_DAGSTER_POSTGRES_URL), then run again (results already stored are kept)")
