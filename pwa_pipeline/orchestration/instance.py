"""The Dagster instance of the command line: created once, under a file lock.

Dagster creates the sqlite schema of ``$DAGSTER_HOME`` on first use; two processes doing that
at once leave two ``alembic_version`` rows, after which every run on that home fails at start.
:func:`prepare_instance` serialises the first use.
"""

import json
import os
import re
from pathlib import Path

import dagster as dg
from filelock import FileLock

from .paths import dagster_home

_SETTINGS = """telemetry:
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
#: What earlier versions wrote as ``dagster.yaml``: replaced by :func:`dagster_yaml`'s text.
_EARLIER = (_SETTINGS,)


def _storage_yaml(home: Path) -> str:
    """Dagster's sqlite storage of ``home`` in the files its default puts there
    (``history/``, ``history/runs/``, ``schedules/``), its event log through
    :class:`.event_log.PooledEventLogStorage`."""
    return f"""run_storage:
  module: dagster._core.storage.runs
  class: SqliteRunStorage
  config:
    base_dir: {json.dumps(str(home / "history"))}
event_log_storage:
  module: pwa_pipeline.orchestration.event_log
  class: PooledEventLogStorage
  config:
    base_dir: {json.dumps(str(home / "history" / "runs"))}
schedule_storage:
  module: dagster._core.storage.schedules
  class: SqliteScheduleStorage
  config:
    base_dir: {json.dumps(str(home / "schedules"))}
"""


def dagster_yaml(home: Path) -> str:
    """The ``dagster.yaml`` of ``home``: the UI's and run queue's settings, Dagster's sqlite
    storage (:func:`_storage_yaml`), and the compute logs in the folder Dagster's default
    puts them in (``storage/``), mirrored by
    :class:`.compute_logs.ThreadMirroredComputeLogManager`."""
    home = Path(home).resolve()
    return _SETTINGS + _storage_yaml(home) + f"""compute_logs:
  module: pwa_pipeline.orchestration.compute_logs
  class: ThreadMirroredComputeLogManager
  config:
    base_dir: {json.dumps(str(home / "storage"))}
"""


def _written_here(text: str) -> bool:
    """Whether ``text`` is a ``dagster.yaml`` this module wrote (now or earlier, for this home
    or for where it was before it moved) rather than one edited by hand, which is kept."""
    first = re.search(r'^    base_dir: ("[^"\n]*")$', text, re.MULTILINE)
    if first is None:
        return text in _EARLIER
    earlier_home = Path(json.loads(first.group(1))).parent
    # now, or before the compute logs' entry
    return text in (dagster_yaml(earlier_home), _SETTINGS + _storage_yaml(earlier_home))


def prepare_instance() -> dg.DagsterInstance:
    """``$DAGSTER_HOME`` (default ``<project>/.dagster_home``) with its ``dagster.yaml``
    (:func:`dagster_yaml`; one this module wrote earlier is brought up to date, one edited by
    hand is kept) and schema created, under ``.init.lock``; sets ``DAGSTER_HOME`` and returns
    the instance."""
    home = dagster_home()
    home.mkdir(parents=True, exist_ok=True)
    os.environ["DAGSTER_HOME"] = str(home)
    with FileLock(home / ".init.lock"):
        config = home / "dagster.yaml"
        if not config.exists() or _written_here(config.read_text()):
            config.write_text(dagster_yaml(home))
        instance = dg.DagsterInstance.get()
        instance.get_runs(limit=1)  # the first query creates and migrates the schema
    return instance
