"""The command line's Dagster home: its dagster.yaml, and the event log that reuses engines."""

import os
import sqlite3

import dagster as dg
import pytest
from dagster._core.storage.event_log.sqlite import sqlite_event_log
from dagster._core.storage.event_log.sqlite.sqlite_event_log import SqliteEventLogStorage

from pwa_pipeline.orchestration import event_log
from pwa_pipeline.orchestration.instance import (
    _SETTINGS,
    _storage_yaml,
    dagster_yaml,
    prepare_instance,
)

PARTS = dg.StaticPartitionsDefinition(["a", "b"])


@dg.asset(partitions_def=PARTS)
def source() -> int:
    return 1


@dg.asset(partitions_def=PARTS)
def derived(source: int) -> int:
    return source + 1


def _open_files() -> set[str]:
    """The files this process has open."""
    return {os.path.realpath(f"/proc/self/fd/{fd}") for fd in os.listdir("/proc/self/fd")}


@pytest.fixture
def home(tmp_path, monkeypatch):
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    return tmp_path / "home"


def _materialise(instance, partition: str):
    return dg.materialize([source, derived], partition_key=partition, instance=instance,
                          resources={"io_manager": dg.mem_io_manager})


def test_the_home_stores_events_with_one_engine_per_file(home, monkeypatch):
    created = []
    real = event_log.create_engine
    monkeypatch.setattr(event_log, "create_engine",
                        lambda *a, **k: created.append(a[0]) or real(*a, **k))
    instance = prepare_instance()
    assert type(instance.event_log_storage) is event_log.PooledEventLogStorage
    result = _materialise(instance, "a")
    assert result.success
    events = instance.all_logs(result.run_id)
    assert len(events) > 20
    # the run's file and the cross-run index: one engine each, however many events
    run_shard = [c for c in created if result.run_id in c]
    assert len(run_shard) == 1 and len(created) <= 3, created
    # the same files and rows as Dagster's own class reads them
    plain = SqliteEventLogStorage(str(home / "history" / "runs"))
    assert [e.dagster_event_type for e in plain.get_logs_for_run(result.run_id)] == \
        [e.dagster_event_type for e in events]
    second = _materialise(instance, "b")
    record = instance.fetch_materializations(
        dg.AssetRecordsFilter(asset_key=dg.AssetKey("derived"), asset_partitions=["b"]),
        limit=1).records[0]
    assert record.run_id == second.run_id
    assert plain.fetch_materializations(dg.AssetKey("derived"), limit=5).records[0].run_id \
        == second.run_id


def test_events_written_by_another_process_are_read_and_wipe_closes_the_files(home):
    instance = prepare_instance()
    storage = instance.event_log_storage
    first = _materialise(instance, "a")
    # another process (Dagster's own class on the same files) runs partition b meanwhile
    (home / "dagster-default.yaml").write_text(_SETTINGS)
    other = dg.DagsterInstance.from_config(str(home), config_filename="dagster-default.yaml")
    assert type(other.event_log_storage) is SqliteEventLogStorage
    other_run = _materialise(other, "b")
    latest = instance.fetch_materializations(
        dg.AssetRecordsFilter(asset_key=dg.AssetKey("derived"), asset_partitions=["b"]),
        limit=1).records[0]
    assert latest.run_id == other_run.run_id
    runs_dir = home / "history" / "runs"
    assert str(runs_dir / f"{first.run_id}.db") in _open_files()
    storage.wipe()
    # no run's file open (wipe empties the index through a connection of its own)
    assert not [f for f in _open_files() if f.startswith(str(runs_dir))
                and not os.path.basename(f).startswith("index.db")]
    assert not (runs_dir / f"{first.run_id}.db").exists()
    again = _materialise(instance, "a")
    plain = SqliteEventLogStorage(str(runs_dir))
    assert len(plain.get_logs_for_run(again.run_id)) == len(instance.all_logs(again.run_id))


def test_the_engines_kept_are_bounded(home, monkeypatch):
    monkeypatch.setattr(event_log, "KEPT_ENGINES", 3)
    storage = prepare_instance().event_log_storage
    disposed = []
    for shard in ["r1", "r2", "r3", "r4", "r5"]:
        with storage.run_connection(shard) as conn:
            conn.exec_driver_sql("select 1")
        engine = storage._engines[shard]
        engine.dispose = lambda e=engine: disposed.append(e)
    assert list(storage._engines) == ["r3", "r4", "r5"]
    # the UI's threads share the storage: r5's open connection used from another thread
    from concurrent.futures import ThreadPoolExecutor

    def query():
        with storage.run_connection("r5") as conn:
            return conn.exec_driver_sql("select 2").scalar()

    with ThreadPoolExecutor(1) as pool:
        assert pool.submit(query).result() == 2
    assert list(storage._engines) == ["r3", "r4", "r5"]
    with storage.run_connection("r3"):  # used again: the most recent
        pass
    with storage.run_connection("r6"):
        pass
    assert list(storage._engines) == ["r5", "r3", "r6"]
    assert [e.url.database.rsplit("/", 1)[1] for e in disposed] == ["r1.db", "r2.db", "r4.db"]


def test_dagster_yaml_written_earlier_is_brought_up_to_date_and_one_edited_is_kept(
        home, tmp_path):
    home.mkdir()
    config = home / "dagster.yaml"
    config.write_text(_SETTINGS)  # what the command line wrote before
    prepare_instance()
    assert config.read_text() == dagster_yaml(home)
    config.write_text(dagster_yaml(tmp_path / "moved-from"))  # a home moved here
    prepare_instance()
    assert config.read_text() == dagster_yaml(home)
    config.write_text(_SETTINGS + _storage_yaml(home))  # before the compute logs' entry
    prepare_instance()
    assert config.read_text() == dagster_yaml(home)
    edited = dagster_yaml(home) + "run_monitoring:\n  enabled: true\n"
    config.write_text(edited)
    instance = prepare_instance()
    assert config.read_text() == edited
    assert instance.run_monitoring_enabled
    assert type(instance.compute_log_manager).__name__ == "ThreadMirroredComputeLogManager"
    assert os.environ["DAGSTER_HOME"] == str(home)


def _pragmas(storage, shard: str) -> tuple[str, int]:
    """Journal mode and synchronous level of the kept connection to ``shard``'s file."""
    with storage._engines[shard].connect() as conn:
        return (conn.exec_driver_sql("PRAGMA journal_mode").scalar(),
                conn.exec_driver_sql("PRAGMA synchronous").scalar())


def test_files_in_wal_mode_commit_without_waiting_for_the_disk(home):
    instance = prepare_instance()
    storage = instance.event_log_storage
    result = _materialise(instance, "a")
    # the run's new file (WAL only once Dagster has created it) and the index: NORMAL (1)
    assert _pragmas(storage, result.run_id) == ("wal", 1)
    assert _pragmas(storage, "index") == ("wal", 1)
    # a file in another journal mode (set by another program) keeps sqlite's FULL (2)
    storage.dispose()
    with sqlite3.connect(home / "history" / "runs" / f"{result.run_id}.db") as conn:
        conn.execute("PRAGMA journal_mode=DELETE")
    assert len(instance.all_logs(result.run_id)) > 20
    assert _pragmas(storage, result.run_id) == ("delete", 2)


def test_has_table_asks_the_file_until_it_finds_the_table(home, monkeypatch):
    storage = prepare_instance().event_log_storage
    asked = []
    real = sqlite_event_log.create_engine
    monkeypatch.setattr(sqlite_event_log, "create_engine",
                        lambda *a, **k: asked.append(a[0]) or real(*a, **k))
    assert [storage.has_table("asset_event_tags") for _ in range(3)] == [True] * 3
    assert [storage.has_table("no_such_table") for _ in range(2)] == [False] * 2
    assert len(asked) == 3  # once for the table found, each time for the one missing


def test_schema_checks_ask_the_index_until_they_find_and_forget_at_wipe(home, monkeypatch):
    """Dagster asks, at every asset event and input, whether a data migration is complete and
    whether the asset-key table has a column: each is asked of the index until found."""
    storage = prepare_instance().event_log_storage
    asked = []
    for name in ("has_secondary_index", "_has_asset_key_col_on_connection"):
        real = getattr(SqliteEventLogStorage, name)
        monkeypatch.setattr(SqliteEventLogStorage, name,
                            lambda *a, real=real, name=name: asked.append(name) or real(*a))
    checks = [lambda: storage.has_secondary_index("asset_key_table"),
              lambda: storage.has_asset_key_col("cached_status_data")]
    assert [check() for check in checks for _ in range(3)] == [True] * 6
    assert asked == ["has_secondary_index", "_has_asset_key_col_on_connection"]
    assert [storage.has_secondary_index("no_such_migration") for _ in range(2)] == [False] * 2
    assert [storage.has_asset_key_col("no_such_column") for _ in range(2)] == [False] * 2
    assert len(asked) == 6  # what is missing is asked each time
    storage.wipe()  # empties the index and forgets what was found
    asked.clear()
    assert [check() for check in checks] == [True, True]
    assert len(asked) == 2


def _schema(path) -> tuple[list, list, str, int]:
    """Tables and indexes, the alembic stamp, the journal mode and the permissions of a
    sqlite file."""
    with sqlite3.connect(path) as conn:
        return (sorted(conn.execute("select type, name, sql from sqlite_master")),
                conn.execute("select version_num from alembic_version").fetchall(),
                conn.execute("PRAGMA journal_mode").fetchone()[0], path.stat().st_mode & 0o777)


def test_new_run_files_are_copies_of_one_made_by_dagster(home, tmp_path, monkeypatch):
    instance = prepare_instance()
    storage = instance.event_log_storage
    initialised = []
    real = storage._initdb
    monkeypatch.setattr(storage, "_initdb", lambda *a, **k: initialised.append(a) or real(*a, **k))
    runs = [_materialise(instance, p) for p in ("a", "b", "a")]
    assert len(initialised) == 1  # once for the process, not once per run
    # each run's file as Dagster's own class creates one: schema, stamp, journal mode and
    # permissions (those sqlite gives a new file, not mkstemp's 0600)
    plain = SqliteEventLogStorage(str(tmp_path / "plain"))
    with plain.run_connection("r") as conn:
        conn.exec_driver_sql("select 1")
    reference = _schema(tmp_path / "plain" / "r.db")
    assert reference[1] and reference[2] == "wal" and reference[3] != 0o600
    runs_dir = home / "history" / "runs"
    other = SqliteEventLogStorage(str(runs_dir))  # Dagster's class, as another process
    for run in runs:
        assert _schema(runs_dir / f"{run.run_id}.db") == reference
        assert len(other.get_logs_for_run(run.run_id)) > 20
    # a run's file another process created first is kept, events and all
    other.store_event(instance.all_logs(runs[0].run_id)[0]._replace(run_id="elsewhere"))
    with storage.run_connection("elsewhere") as conn:
        assert conn.exec_driver_sql("select count(*) from event_logs").scalar() == 1
    assert len(initialised) == 2  # that file initialised (checked) as Dagster does


def test_the_seconds_to_3x_bring_the_caches_speed_up_to_3x():
    from benchmarks.event_log import seconds_to_target

    needed = seconds_to_target(109.0, 41.7, 12)
    assert 109.0 / (41.7 - 11 * needed["with_cache_only"]) == pytest.approx(3.0)
    saved = 12 * needed["every_set"]
    assert (109.0 - saved) / (41.7 - saved) == pytest.approx(3.0)
    assert seconds_to_target(120.0, 30.0, 12) == {"with_cache_only": 0.0, "every_set": 0.0}


def test_a_sweeps_summary_divides_the_totals_of_its_arms():
    from benchmarks.event_log import summarise

    def arm(first, later):
        return [{"seconds": first, "success": True}] + [{"seconds": later, "success": True}] * 11

    runs = {"pooled|with_cache": arm(8.0, 2.0), "pooled|without_cache": arm(9.0, 8.0),
            "floor": arm(1.0, 0.5)}
    summary = summarise(runs, ("pooled",))
    assert summary["arms"]["pooled|with_cache"] == {
        "total_seconds": 30.0, "first_set_seconds": 8.0, "later_sets_median_seconds": 2.0,
        "succeeded": 12}
    assert summary["speed_up"] == {"pooled": pytest.approx(97.0 / 30.0)}
    assert summary["best_speed_up_over_floor"] == pytest.approx(97.0 / (8.0 + 11 * 0.5))
    assert summary["seconds_to_3x"] == {"with_cache_only": 0.0, "every_set": 0.0}
