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
connections are closed before :meth:`wipe` deletes the runs' files. Measured by
``benchmarks/event_log.py``.
"""

from collections import OrderedDict
from collections.abc import Iterator
from contextlib import contextmanager

from dagster._core.storage.event_log.sqlite.sqlite_event_log import (
    SQLITE_BUSY_TIMEOUT_SECONDS,
    SqliteEventLogStorage,
    create_engine,
)
from dagster._serdes import ConfigurableClassData
from sqlalchemy.engine import Engine
from sqlalchemy.pool import QueuePool

#: Engines (each with its open connection) kept: the index's and the latest runs'.
KEPT_ENGINES = 16


class PooledEventLogStorage(SqliteEventLogStorage):
    """:class:`SqliteEventLogStorage` keeping one SQLAlchemy engine with one open connection
    per database file (the ``KEPT_ENGINES`` most recently used), so that statements are
    compiled once and files opened once; its ``dagster.yaml`` configuration is the same
    (``base_dir``)."""

    def __init__(self, base_dir: str, inst_data: ConfigurableClassData | None = None):
        # before Dagster's __init__, which may index a new home through _connect
        self._engines: OrderedDict[str, Engine] = OrderedDict()  # most recently used last
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
        super().wipe()

    def dispose(self) -> None:
        """Close the connections and stop the file watcher."""
        self._dispose_engines()
        super().dispose()

    @contextmanager
    def _connect(self, shard: str) -> Iterator:
        """A connection in a transaction on ``shard``'s file, as Dagster's ``_connect``, from
        the shard's kept engine."""
        with self._db_lock:
            # one connection (the lock lets one thread in at a time), more only if nested;
            # SQLAlchemy lets a pooled sqlite connection serve any thread
            engine = self._engines.pop(shard, None) or create_engine(
                self.conn_string_for_shard(shard), poolclass=QueuePool, pool_size=1,
                max_overflow=2, connect_args={"timeout": SQLITE_BUSY_TIMEOUT_SECONDS})
            self._engines[shard] = engine
            while len(self._engines) > KEPT_ENGINES:
                self._engines.popitem(last=False)[1].dispose()
            if shard not in self._initialized_dbs:
                self._initdb(engine)
                self._initialized_dbs.add(shard)
            with engine.connect() as conn, conn.begin():
                yield conn
