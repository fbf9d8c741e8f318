"""The Dagster instance of the command line: ``$DAGSTER_HOME`` with its ``dagster.yaml``.

The generated file sets the UI's and the run queue's settings and, when
``$PWA_DAGSTER_POSTGRES_URL`` is set, Dagster's supported PostgreSQL storage
(``dagster-postgres``, the ``postgres`` extra: ``storage: postgres:`` reading the URL from
that variable, so that the file holds no password and every machine sharing it reads its
own environment). Unset, storage and compute logs are Dagster's defaults for a home folder
(sqlite files under ``history/`` and ``schedules/``, logs under ``storage/``), which the UI's
live run page follows. A file this module generated follows the variable; a ``dagster.yaml``
edited by hand is kept as it is.
"""

import contextlib
import logging
import os
import urllib.parse
from collections.abc import Iterator

import dagster as dg
from filelock import FileLock

from .credentials import mask_credentials
from .paths import dagster_home

#: Environment variable holding the URL of the Dagster instance's PostgreSQL database,
#: ``postgresql+psycopg2://user:password@host:5432/dagster``.
POSTGRES_ENV = "PWA_DAGSTER_POSTGRES_URL"
DAGSTER_YAML = """telemetry:
  enabled: false
nux:
  enabled: false
run_queue:
  # a run launched from the UI leaves the queue within a second (Dagster's default: 5 s)
  dequeue_interval_seconds: 1
  # sweep_dask runs share dask task keys (see pwa_pipeline.orchestration.jobs): one at a time
  tag_concurrency_limits:
    - key: "pwa/executor"
      value: "dask"
      limit: 1
"""
#: `DAGSTER_YAML` with Dagster's PostgreSQL storage (runs, event logs, schedules).
POSTGRES_YAML = DAGSTER_YAML + f"""storage:
  postgres:
    postgres_url:
      env: {POSTGRES_ENV}
"""
#: What earlier versions of this module wrote beside `DAGSTER_YAML`: storage classes of
#: this package that no longer exist. A file naming one is replaced.
_EARLIER_MODULES = ("pwa_pipeline.orchestration.event_log",
                    "pwa_pipeline.orchestration.compute_logs")
#: Seconds to wait for a PostgreSQL server before giving up (libpq's default: for ever).
CONNECT_TIMEOUT = 10


def check_postgres_url(url: str) -> None:
    """Raise a ValueError saying what is wrong with a PostgreSQL URL for Dagster's storage
    (password masked): not PostgreSQL, no database named, or a driver not installed
    (SQLAlchemy 2.1 reads ``postgresql://`` as psycopg 3; ``dagster-postgres`` installs
    psycopg2, named by ``postgresql+psycopg2://``)."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    shown = mask_credentials(url)
    parts = urllib.parse.urlsplit(url)
    if not parts.scheme.startswith("postgresql"):
        raise ValueError(f"${POSTGRES_ENV} {shown} is not a PostgreSQL URL (expected "
                         f"postgresql+psycopg2://user:password@host:5432/database)")
    if not parts.path.strip("/"):
        raise ValueError(f"${POSTGRES_ENV} {shown} names no database (expected "
                         f"postgresql+psycopg2://user:password@host:5432/database)")
    try:
        make_url(url).get_dialect().import_dbapi()
    except (ImportError, NoSuchModuleError, ArgumentError) as exc:
        raise ValueError(f"${POSTGRES_ENV} {shown}: its driver cannot be loaded ({exc}); "
                         f"name psycopg2, which dagster-postgres installs: "
                         f"postgresql+psycopg2://…") from None


def probe_postgres(url: str) -> None:
    """Connect once to the database at ``url`` (within `CONNECT_TIMEOUT` seconds) and
    raise a ValueError with the server's own reason if that fails: Dagster's storages retry
    for about 12 s and then report only that they retried."""
    from sqlalchemy import create_engine, text
    from sqlalchemy.exc import SQLAlchemyError
    from sqlalchemy.pool import NullPool

    engine = create_engine(url, poolclass=NullPool,
                           connect_args={"connect_timeout": CONNECT_TIMEOUT})
    try:
        with engine.connect() as connection:
            connection.execute(text("SELECT 1"))
    except SQLAlchemyError as exc:
        reason = str(getattr(exc, "orig", None) or exc).strip().splitlines()[0]
        password = urllib.parse.urlsplit(url).password
        if password:  # psycopg2 names host, port, user and database, never the password
            reason = reason.replace(password, "***")
        raise ValueError(f"Dagster's PostgreSQL storage ({mask_credentials(url)}) cannot be "
                         f"used: {reason}. Start the server, or fix the URL in "
                         f"${POSTGRES_ENV}; nothing was run") from None
    finally:
        engine.dispose()


def instance_yaml() -> str:
    """The ``dagster.yaml`` this module generates: `POSTGRES_YAML` when
    ``$PWA_DAGSTER_POSTGRES_URL`` is set (checked by `check_postgres_url`, its server
    by `probe_postgres`), else `DAGSTER_YAML`."""
    url = os.environ.get(POSTGRES_ENV, "")
    if not url:
        return DAGSTER_YAML
    check_postgres_url(url)
    probe_postgres(url)
    return POSTGRES_YAML


def prepare_instance() -> dg.DagsterInstance:
    """``$DAGSTER_HOME`` (default ``<project>/.dagster_home``) with its ``dagster.yaml``
    (`instance_yaml`, written when missing, when this module generated it, or when an
    earlier version of this module wrote it) and its schema created; sets ``DAGSTER_HOME``
    and returns the instance.

    The first use of a new home creates its sqlite schema; two processes doing that at once
    can leave it unusable, so the first use holds ``<home>/.init.lock``. A PostgreSQL server
    that does not answer within `CONNECT_TIMEOUT` seconds, or refuses the
    credentials, raises a ValueError naming the URL (password masked) and the reason.
    """
    wanted = instance_yaml()
    home = dagster_home()
    home.mkdir(parents=True, exist_ok=True)
    os.environ["DAGSTER_HOME"] = str(home)
    with FileLock(home / ".init.lock"):
        config = home / "dagster.yaml"
        if not config.exists() or config.read_text() in (DAGSTER_YAML, POSTGRES_YAML) \
                or any(m in config.read_text() for m in _EARLIER_MODULES):
            config.write_text(wanted)
        try:
            instance = dg.DagsterInstance.get()
            instance.get_runs(limit=1)  # the first query creates and migrates the schema
        except Exception as exc:
            url = os.environ.get(POSTGRES_ENV, "")
            if "postgres" not in config.read_text():
                raise
            # psycopg2's message names host and port, never the password; masked all the same
            message = str(exc).split("\n")[0]
            password = urllib.parse.urlsplit(url).password
            if password:
                message = message.replace(password, "***")
            raise ValueError(
                f"Dagster's PostgreSQL storage ({mask_credentials(url) or config}) cannot be "
                f"used: {message}. Start the server, or fix the URL in ${POSTGRES_ENV}; "
                f"nothing was run") from None
    return instance


class _RetriesInOneLine(logging.Filter):
    """dagster-postgres logs each retry of a lost connection on the root logger, a
    4-line psycopg2 message every second or so for about 30 s: the first is said in one
    line of ours, the others dropped."""

    PREFIX = "Retrying failed database"

    def __init__(self) -> None:
        super().__init__()
        self.said = False

    def filter(self, record: logging.LogRecord) -> bool:
        if not str(record.msg).startswith(self.PREFIX):
            return True
        if self.said:
            return False
        self.said = True
        cause = str(record.args[0]).splitlines()[0] if record.args else "no cause given"
        record.msg, record.args = ("the Dagster instance's PostgreSQL storage does not answer "
                                   "(%s); Dagster retries for about 30 s", (cause,))
        return True


@contextlib.contextmanager
def retries_in_one_line() -> Iterator[None]:
    """While the context lasts, dagster-postgres' retries of a lost connection are said in
    one line (`_RetriesInOneLine`); the command's own line then says what failed."""
    retries = _RetriesInOneLine()
    logging.getLogger().addFilter(retries)
    try:
        yield
    finally:
        logging.getLogger().removeFilter(retries)
