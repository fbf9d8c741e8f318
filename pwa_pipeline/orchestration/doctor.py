"""Finding and repairing what interrupted runs leave behind.

A run killed with SIGKILL (or a machine that stops) cannot clean up: its Dagster run stays
STARTED, its MLflow run RUNNING, and a temporary file may stay beside the file it was writing.
:func:`find_orphans` lists them; :func:`repair` marks the runs failed / killed and deletes the
temporary files. Anything younger than ``older_than`` seconds is taken for a live run.
"""

import time
from dataclasses import dataclass, field
from pathlib import Path

import dagster as dg

from .files import STALE_SECONDS, sweep_stale_tmp


@dataclass
class Orphans:
    """What :func:`find_orphans` found."""

    dagster_runs: list[str] = field(default_factory=list)
    mlflow_runs: list[str] = field(default_factory=list)
    temporary_files: list[Path] = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.dagster_runs or self.mlflow_runs or self.temporary_files)


def _stale_tmp(roots: list[Path], older_than: float) -> list[Path]:
    cutoff = time.time() - older_than
    return sorted(p for root in roots if root.is_dir() for p in root.rglob(".*.tmp")
                  if p.is_file() and p.stat().st_mtime < cutoff)


def find_orphans(instance: dg.DagsterInstance, mlflow_client, roots: list[Path],
                 older_than: float = STALE_SECONDS) -> Orphans:
    """Dagster runs STARTED/STARTING, MLflow runs RUNNING, and temporary files under
    ``roots``, all older than ``older_than`` seconds."""
    cutoff = time.time() - older_than
    records = instance.get_run_records(dg.RunsFilter(
        statuses=[dg.DagsterRunStatus.STARTED, dg.DagsterRunStatus.STARTING]))
    dagster_runs = [r.dagster_run.run_id for r in records
                    if (r.start_time or r.create_timestamp.timestamp()) < cutoff]
    mlflow_runs = []
    if mlflow_client is not None:
        experiments = [e.experiment_id for e in mlflow_client.search_experiments()]
        if experiments:
            mlflow_runs = [r.info.run_id for r in mlflow_client.search_runs(
                experiments, filter_string="attributes.status = 'RUNNING'")
                if r.info.start_time / 1000 < cutoff]
    return Orphans(dagster_runs, mlflow_runs, _stale_tmp(roots, older_than))


def repair(orphans: Orphans, instance: dg.DagsterInstance, mlflow_client,
           older_than: float = STALE_SECONDS) -> None:
    """Mark the orphaned Dagster runs failed and MLflow runs KILLED; delete the temporary
    files."""
    for run_id in orphans.dagster_runs:
        run = instance.get_run_by_id(run_id)
        instance.report_run_failed(run, "marked failed by `pwa_pipeline doctor`: its process "
                                        "is gone (interrupted or killed)")
    for run_id in orphans.mlflow_runs:
        mlflow_client.set_terminated(run_id, "KILLED")
    for folder in {p.parent for p in orphans.temporary_files}:
        sweep_stale_tmp(folder, older_than)
