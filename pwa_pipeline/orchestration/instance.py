"""The Dagster instance of the command line: created once, under a file lock.

Dagster creates the sqlite schema of ``$DAGSTER_HOME`` on first use; two processes doing that
at once leave two ``alembic_version`` rows, after which every run on that home fails at start.
:func:`prepare_instance` serialises the first use.
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


def prepare_instance() -> dg.DagsterInstance:
    """``$DAGSTER_HOME`` (default ``<project>/.dagster_home``) with its ``dagster.yaml`` and
    schema created, under ``.init.lock``; sets ``DAGSTER_HOME`` and returns the instance."""
    home = dagster_home()
    home.mkdir(parents=True, exist_ok=True)
    os.environ["DAGSTER_HOME"] = str(home)
    with FileLock(home / ".init.lock"):
        if not (home / "dagster.yaml").exists():
            (home / "dagster.yaml").write_text(DAGSTER_YAML)
        instance = dg.DagsterInstance.get()
        instance.get_runs(limit=1)  # the first query creates and migrates the schema
    return instance
