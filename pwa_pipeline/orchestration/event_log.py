"""The command line's Dagster event log: Dagster's sqlite event log, its connections kept open.

Dagster's :class:`~dagster._core.storage.event_log.sqlite.SqliteEventLogStorage` (the default
of a sqlite ``$DAGSTER_HOME``) builds a new SQLAlchemy engine, and opens a new sqlite
connection, for every statement it runs: each event of a pipeline run (step starts, inputs
loaded, outputs, asset materialisations, checks) is stored through two fresh engines (the
run's file and the cross-run index), whose SQL is compiled anew each time, since SQLAlchemy
caches compiled statements per engine. :class:`PooledEventLogStorage` keeps one engine per
database file instead (the ``KEPT_ENGINES`` most recently used), each holding one open
connection, and changes nothing else: the same files, schema, transactions and lock (one
thread at a time, as Dagster's), so a home written by either class is read by the other, and
the UI, daemon and run workers that load the ``dagster.yaml`` of :mod:`.instance` use it too.
An idle sqlite connection holds no lock, so other processes write the files as before; the
connections are closed before :meth:`wipe` deletes the runs' files.

Its connections to files in write-ahead-log mode (every file Dagster creates: its ``_initdb``
sets ``journal_mode=WAL``) commit with ``PRAGMA synchronous=NORMAL`` rather than sqlite's
default ``FULL``: a commit then writes the log without waiting for the disk to flush it, which
the disk does at each checkpoint. In WAL mode this cannot corrupt the file; what a power cut
or operating-system crash (not a crash of the process) can lose is the last events committed
before it, as sqlite documents. A file in any other journal mode keeps ``FULL``. And the
schema checks Dagster makes at every asset event and input (:meth:`has_table`,
:meth:`has_secondary_index`, the asset-key table's columns) remember what they have found:
Dagster's migrations add tables, columns and completed data migrations, never remove them;
only :meth:`wipe` empties the index, and forgets. What is not found is asked again each time,
so a migration by another process is seen.

Each run gets a file of its own, which Dagster's ``_initdb`` creates through its migration
tool (alembic: the schema's revisions read from its scripts, the tables created, the file
stamped with the latest revision) at the run's first event. This class does that once per
process, on a file of its own, and gives each new run's file a copy of it: the same schema,
stamp, journal mode and permissions, put in place with a hard link, which never replaces a file another
process created meanwhile (that file is then initialised as Dagster does). Measured by
``benchmarks/event_log.py``.
"""

import tempfile
from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from dagster._core.storage.event_log.sqlite.sqlite_event_log import (
    INDEX_SHARD_NAME,
    SQLITE_BUSY_TIMEOUT_SECONDS,
    SqliteEventLogStorage,
    create_engine,
)
from dagster._serdes import ConfigurableClassData
from sqlalchemy import event
from sqlalchemy.engine import Engine
from sqlalchemy.pool import QueuePool

#: Engines (each with its open connection) kept: the index's and the latest runs'.
KEPT_ENGINES = 16
_DAGSTERS = SqliteEventLogStorage
"""The class whose schema checks :class:`PooledEventLogStorage` remembers."""


class PooledEventLogStorage(SqliteEventLogStorage):
    """:class:`SqliteEventLogStorage` keeping one SQLAlchemy engine with one open connection
    per database file (the ``KEPT_ENGINES`` most recently used), so that statements are
    compiled once and files opened once; its ``dagster.yaml`` configuration is the same
    (``base_dir``)."""

    def __init__(self, base_dir: str, inst_data: ConfigurableClassData | None = None):
        # before Dagster's __init__, which may index a new home through _connect
        self._engines: OrderedDict[str, Engine] = OrderedDict()  # most recently used last
        self._found: set[tuple[str, str]] = set()  # (kind, name) the schema checks found
        self._new_run_file: tuple[bytes, int] | None = None  # made once: bytes, mode
        super().__init__(base_dir, inst_data)

    @classmethod
    def from_config_value(cls, inst_data, config_value) -> "PooledEventLogStorage":
        return cls(inst_data=inst_data, **config_value)

    def _dispose_engines(self) -> None:
        with self._db_lock:
            engines, self._engines = self._engines, OrderedDict()
            for engine in engines.values():
                engine.dispose()

    def wipe(self) -> None:
        """Close the connections, then delete the runs' files and empty the index as
        Dagster's class does."""
        self._dispose_engines()
        self._found.clear()  # the index is emptied: ask it again
        super().wipe()

    def dispose(self) -> None:
        """Close the connections and stop the file watcher."""
        self._dispose_engines()
        super().dispose()

    def _remembered(self, kind: str, name: str, ask: Callable[[], bool]) -> bool:
        """``ask()``, until it answers True for this ``kind`` and ``name``: then True."""
        if (kind, name) not in self._found:
            if not ask():
                return False
            self._found.add((kind, name))
        return True

    def has_table(self, table_name: str) -> bool:
        """Whether the index has ``table_name``, asked of the file until it is found."""
        return self._remembered("table", table_name,
                                lambda: _DAGSTERS.has_table(self, table_name))

    def has_secondary_index(self, name: str) -> bool:
        """Whether the data migration ``name`` is complete, asked of the index until it is."""
        return self._remembered("migration", name,
                                lambda: _DAGSTERS.has_secondary_index(self, name))

    def _has_asset_key_col_on_connection(self, conn, column_name: str) -> bool:
        """Whether the asset-key table has ``column_name``, asked of ``conn`` until it has."""
        return self._remembered("column", column_name, lambda: _DAGSTERS.
                                _has_asset_key_col_on_connection(self, conn, column_name))

    @contextmanager
    def _connect(self, shard: str) -> Iterator:
        """A connection in a transaction on ``shard``'s file, as Dagster's ``_connect``, from
        the shard's kept engine."""
        with self._db_lock:
            # one connection (the lock lets one thread in at a time), more only if nested;
            # SQLAlchemy lets a pooled sqlite connection serve any thread
            engine = self._engines.pop(shard, None) or _engine(self.conn_string_for_shard(shard))
            self._engines[shard] = engine
            while len(self._engines) > KEPT_ENGINES:
                self._engines.popitem(last=False)[1].dispose()
            if shard not in self._initialized_dbs:
                if not self._created_from_copy(shard):
                    self._initdb(engine)
                self._initialized_dbs.add(shard)
                engine.dispose()  # a new file is in WAL mode only now: connect again
            with engine.connect() as conn, conn.begin():
                yield conn

    def _created_from_copy(self, shard: str) -> bool:
        """Create the file of a new run ``shard`` as a copy of the one :meth:`_initdb` made
        once in this process; False (nothing done) for the index or a file that exists."""
        # imported here: the UI's and daemon's processes load this class, not the pipeline
        from .storage import create_new

        path = Path(self.path_for_shard(shard))
        if shard == INDEX_SHARD_NAME or path.exists():
            return False
        if self._new_run_file is None:
            with tempfile.TemporaryDirectory() as tmp:
                made = Path(tmp) / "run.db"
                engine = create_engine(f"sqlite:///{made}")
                self._initdb(engine)
                engine.dispose()  # the last connection closed moves its WAL into the file
                # the bytes, and the permissions sqlite gave the file (the umask's)
                self._new_run_file = made.read_bytes(), made.stat().st_mode & 0o777
        return create_new(path, *self._new_run_file)


def _engine(conn_string: str) -> Engine:
    """An engine keeping one open connection to a file (two more while nested), each set to
    ``synchronous=NORMAL`` when the file is in WAL mode."""
    engine = create_engine(conn_string, poolclass=QueuePool, pool_size=1, max_overflow=2,
                           connect_args={"timeout": SQLITE_BUSY_TIMEOUT_SECONDS})
    event.listen(engine, "connect", _normal_sync_in_wal_mode)
    return engine


def _normal_sync_in_wal_mode(connection, _record) -> None:
    cursor = connection.cursor()
    if cursor.execute("PRAGMA journal_mode").fetchone()[0] == "wal":
        cursor.execute("PRAGMA synchronous=NORMAL")
    cursor.close()
