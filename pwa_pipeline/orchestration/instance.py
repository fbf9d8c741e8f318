"""The Dagster instance of the command line: ``$DAGSTER_HOME`` with its ``dagster.yaml``.

The file sets only the UI's and the run queue's settings: storage and compute logs are
Dagster's defaults for a home folder (sqlite files under ``history/`` and ``schedules/``, logs
under ``storage/``), which the UI's live run page follows. For several processes or people on
one instance, add Dagster's supported ``storage: postgres:`` section (``dagster-postgres``,
the ``postgres`` extra) by hand: a ``dagster.yaml`` edited by hand is kept as it is.
"""

import os

import dagster as dg
from filelock import FileLock

from .paths import dagster_home

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
#: What earlier versions of this module wrote beside :data:`DAGSTER_YAML`: storage classes of
#: this package that no longer exist. A file naming one is replaced.
_EARLIER_MODULES = ("pwa_pipeline.orchestration.event_log",
                    "pwa_pipeline.orchestration.compute_logs")


def prepare_instance() -> dg.DagsterInstance:
    """``$DAGSTER_HOME`` (default ``<project>/.dagster_home``) with its ``dagster.yaml``
    (:data:`DAGSTER_YAML`, written when missing or when an earlier version of this module
    wrote it) and its schema created; sets ``DAGSTER_HOME`` and returns the instance.

    The first use of a new home creates its sqlite schema; two processes doing that at once
    can leave it unusable, so the first use holds ``<home>/.init.lock``.
    """
    home = dagster_home()
    home.mkdir(parents=True, exist_ok=True)
    os.environ["DAGSTER_HOME"] = str(home)
    with FileLock(home / ".init.lock"):
        config = home / "dagster.yaml"
        if not config.exists() or any(m in config.read_text() for m in _EARLIER_MODULES):
            config.write_text(DAGSTER_YAML)
        instance = dg.DagsterInstance.get()
        instance.get_runs(limit=1)  # the first query creates and migrates the schema
    return instance
