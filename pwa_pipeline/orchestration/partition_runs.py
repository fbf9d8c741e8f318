"""One partition's run in this process, as ``python -m pwa_pipeline run`` makes it.

Partitions run one after the other, each one run of the ``sweep`` job with every step in this
process: a partition's steps take seconds, while Dagster's multiprocess executor starts a
process per step (each importing Dagster, MLflow and scikit-learn), which costs more than
it saves. Runs at once go through Dagster's own machinery: a backfill launched in the UI,
which the daemon's run queue runs side by side, or ``--executor dask`` (`dask_sweep`).
"""

import socket

import dagster as dg

from .doctor import HOST_TAG
from .interrupts import interrupts_redelivered
from .jobs import SWEEP_JOB

#: The code location's name, as ``workspace.yaml`` and ``[tool.dg.project]`` give it.
LOCATION = "pwa_pipeline"
#: The tag by which Dagster's UI lists a run on its job's page (*Runs* tab): what it writes
#: itself on the runs it launches, ``<repository>@<location>``. A run executed in this
#: process has no code location of its own (Dagster offers no public way to give it one),
#: so the command line's runs carry it to be listed there with the UI's.
LOCATION_TAGS = {".dagster/repository": f"__repository__@{LOCATION}"}


def run_tags() -> dict[str, str]:
    """The tags of the command line's runs: `LOCATION_TAGS` and this host (for
    ``doctor``)."""
    return {**LOCATION_TAGS, HOST_TAG: socket.gethostname()}


#: What Dagster records of an interrupt: the failure of the step it came in (in process), or
#: of the run while its executor waited (for a busy dask scheduler, or for its tasks).
INTERRUPTS = ("DagsterExecutionInterruptedError", "KeyboardInterrupt")


def was_interrupted(result) -> bool:
    """Whether a partition's run ended by an interrupt (Ctrl-C, SIGINT): Dagster then fails
    the step it was in, or the run, with ``DagsterExecutionInterruptedError`` (a run that
    was asked to stop from the UI is cancelled instead)."""
    if hasattr(result, "interrupted"):
        return result.interrupted
    failures = (dg.DagsterEventType.STEP_FAILURE.value, dg.DagsterEventType.RUN_FAILURE.value)
    return any(e.event_type_value == dg.DagsterEventType.RUN_CANCELED.value
               or (e.event_type_value in failures
                   and getattr(e.event_specific_data, "error", None) is not None
                   and e.event_specific_data.error.cls_name in INTERRUPTS)
               for e in result.all_events)


def cli_definitions(tracking_uri: str = "") -> dg.Definitions:
    """The code location's definitions as the command line runs them: read now (a data set
    may have been registered since import), with the MLflow store at ``tracking_uri`` when
    given (``--tracking-uri``). Credentials in it go to the environment
    (`credentials_to_environment`), never into the configuration that runs store."""
    from .credentials import credentials_to_environment
    from .definitions import build_definitions
    from .tracking import MLflowTracker

    if tracking_uri:
        return build_definitions(
            mlflow=MLflowTracker(tracking_uri=credentials_to_environment(tracking_uri)))
    return build_definitions()


def materialize_partition(defs: dg.Definitions, key: str, instance: dg.DagsterInstance,
                          run_config: dict) -> dg.ExecuteInProcessResult:
    """One partition's run of the ``sweep`` job in this process, so that it is listed among
    the job's runs as a run launched in the UI is (errors are the run's, not raised); tagged
    by `run_tags`. A Ctrl-C that leaves it running is sent again
    (`interrupts_redelivered`)."""
    with interrupts_redelivered():
        return defs.resolve_job_def(SWEEP_JOB).execute_in_process(
            partition_key=key, instance=instance, run_config=run_config, tags=run_tags(),
            raise_on_error=False)
