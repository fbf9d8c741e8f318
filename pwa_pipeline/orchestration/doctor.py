"""Finding and repairing what interrupted runs leave behind.

A run killed with SIGKILL (or a machine that stops) cannot clean up: its Dagster run stays
NOT_STARTED, STARTING or STARTED, its MLflow runs RUNNING, and a temporary file may stay beside
the file it was writing. `find_orphans` lists them; `repair` marks the runs failed
/ killed and deletes the temporary files.

A Dagster run is left behind when none of the processes that logged its events is alive on
this machine (a run on one machine's sqlite storage, or one that the command line tagged with
this host); a run that logged no process yet is given `START_GRACE` seconds. A run of
another machine, whose processes cannot be seen from here, is taken for left behind only once
older than ``older_than``. An MLflow run RUNNING is left behind when the Dagster run that
opened it (its ``dagster_run_id`` tag) is no longer going; one without that tag, or opened by a
run of another Dagster instance, once older than ``older_than``.

A run killed while it logs its model (``mlflow.pyfunc.log_model``, from 0.2 s after its MLflow
run opens) leaves the logged model PENDING, and a registry that registers asynchronously
can leave a model version PENDING_REGISTRATION. Either is left behind once older than
``older_than`` (`doctor`'s ``--older-than``, an hour by default: logging a model takes seconds);
`repair` marks such a logged model FAILED (MLflow's status for a logging that did not end)
and deletes such a model version (``MlflowClient.delete_model_version``).
"""

import socket
import time
from dataclasses import dataclass, field
from pathlib import Path

import dagster as dg
import psutil

from .files import STALE_SECONDS, sweep_stale_tmp

#: Seconds a run may go without logging its process before it is taken for left behind.
START_GRACE = 60.0
#: Run tag naming the machine whose process runs it (set by the command line).
HOST_TAG = "pwa/host"
#: The statuses of a run that has not ended.
GOING = (dg.DagsterRunStatus.NOT_STARTED, dg.DagsterRunStatus.STARTING,
         dg.DagsterRunStatus.STARTED)


@dataclass
class Orphans:
    """What `find_orphans` found."""

    dagster_runs: list[str] = field(default_factory=list)
    mlflow_runs: list[str] = field(default_factory=list)
    temporary_files: list[Path] = field(default_factory=list)
    #: Logged models (ids) PENDING, and model versions ``(name, version)``
    #: PENDING_REGISTRATION, older than ``older_than``.
    pending_models: list[str] = field(default_factory=list)
    pending_versions: list[tuple[str, str]] = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.dagster_runs or self.mlflow_runs or self.temporary_files
                    or self.pending_models or self.pending_versions)


def _all_pages(search, **kwargs) -> list:
    """Every result of an MLflow search that returns pages."""
    found, token = [], None
    while True:
        page = search(**kwargs, page_token=token)
        found.extend(page)
        token = page.token
        if not token:
            return found


def _pending(mlflow_client, experiments: list[str], cutoff_ms: float
             ) -> tuple[list[str], list[tuple[str, str]]]:
    """The logged models PENDING and model versions PENDING_REGISTRATION created before
    ``cutoff_ms`` (see the module doc)."""
    models = [m.model_id for m in
              _all_pages(mlflow_client.search_logged_models, experiment_ids=experiments)
              if m.status == "PENDING" and m.creation_timestamp < cutoff_ms
              ] if experiments else []
    versions = [(v.name, v.version) for v in _all_pages(mlflow_client.search_model_versions)
                if v.status == "PENDING_REGISTRATION" and v.creation_timestamp < cutoff_ms]
    return models, versions


def _stale_tmp(roots: list[Path], older_than: float) -> list[Path]:
    cutoff = time.time() - older_than
    return sorted(p for root in roots if root.is_dir() for p in root.rglob(".*.tmp")
                  if p.is_file() and p.stat().st_mtime < cutoff)


def _alive(pid: int, since: float) -> bool:
    """Whether process ``pid`` runs and was started by ``since`` (a later one reuses the
    number)."""
    try:
        return psutil.Process(pid).create_time() <= since + 1.0
    except (psutil.NoSuchProcess, psutil.AccessDenied, ValueError):
        return False


def _left_behind(instance: dg.DagsterInstance, record, local: bool, now: float,
                 older_than: float) -> bool:
    """Whether the going run of ``record`` has no live process (see the module doc)."""
    run = record.dagster_run
    created = record.create_timestamp.timestamp()
    if not (local or run.tags.get(HOST_TAG) == socket.gethostname()):
        return created < now - older_than
    events = [e for e in instance.all_logs(run.run_id)
              if e.is_dagster_event and e.dagster_event.pid is not None]
    if not events:
        return created < now - START_GRACE
    return not any(_alive(e.dagster_event.pid, e.timestamp) for e in events)


def find_orphans(instance: dg.DagsterInstance, mlflow_client, roots: list[Path],
                 older_than: float = STALE_SECONDS) -> Orphans:
    """Dagster runs not ended whose processes are gone, MLflow runs RUNNING whose Dagster run
    is no longer going, and temporary files under ``roots`` older than ``older_than``
    seconds."""
    now = time.time()
    local = type(instance.run_storage).__name__.startswith("Sqlite")
    records = instance.get_run_records(dg.RunsFilter(statuses=list(GOING)))
    dagster_runs = [r.dagster_run.run_id for r in records
                    if _left_behind(instance, r, local, now, older_than)]
    going = {r.dagster_run.run_id for r in records} - set(dagster_runs)
    mlflow_runs, models, versions = [], [], []
    if mlflow_client is not None:
        experiments = [e.experiment_id for e in mlflow_client.search_experiments()]
        models, versions = _pending(mlflow_client, experiments, (now - older_than) * 1000)
        if experiments:
            mlflow_runs = [r.info.run_id for r in mlflow_client.search_runs(
                experiments, filter_string="attributes.status = 'RUNNING'")
                if (r.data.tags["dagster_run_id"] not in going
                    if instance.has_run(r.data.tags.get("dagster_run_id", ""))
                    else r.info.start_time / 1000 < now - older_than)]
    return Orphans(dagster_runs, mlflow_runs, _stale_tmp(roots, older_than), models, versions)


def repair(orphans: Orphans, instance: dg.DagsterInstance, mlflow_client,
           older_than: float = STALE_SECONDS) -> None:
    """Mark the orphaned Dagster runs failed and MLflow runs KILLED, the logged models left
    PENDING FAILED; delete the model versions left PENDING_REGISTRATION and the temporary
    files (one line printed per model and version)."""
    for run_id in orphans.dagster_runs:
        run = instance.get_run_by_id(run_id)
        instance.report_run_failed(run, "marked failed by `pwa_pipeline doctor`: its process "
                                        "is gone (interrupted or killed)")
    for run_id in orphans.mlflow_runs:
        mlflow_client.set_terminated(run_id, "KILLED")
    for model_id in orphans.pending_models:
        mlflow_client.finalize_logged_model(model_id, "FAILED")
        print(f"Marked the logged model {model_id} FAILED (left PENDING by a killed logging).")
    for name, version in orphans.pending_versions:
        mlflow_client.delete_model_version(name, version)
        print(f"Deleted {name} version {version} (left PENDING_REGISTRATION).")
    for folder in {p.parent for p in orphans.temporary_files}:
        sweep_stale_tmp(folder, older_than)
