"""One partition's run in this process, as ``python -m pwa_pipeline run`` makes it.

Partitions run one after the other, each one ``dg.materialize`` run with every step in this
process: a partition's steps take seconds, while Dagster's multiprocess executor starts a
process per step (each importing Dagster, MLflow and scikit-learn), which costs more than
it saves. Runs at once go through Dagster's own machinery: a backfill launched in the UI,
which the daemon's run queue runs side by side, or ``--executor dask`` (:mod:`.dask_sweep`).
"""

import socket

import dagster as dg

from .doctor import HOST_TAG
from .interrupts import interrupts_redelivered


def was_interrupted(result) -> bool:
    """Whether a partition's run ended by an interrupt (Ctrl-C, SIGINT): Dagster then fails
    the step it was in with ``DagsterExecutionInterruptedError`` and returns."""
    if hasattr(result, "interrupted"):
        return result.interrupted
    return any(e.event_type_value == "STEP_FAILURE" and e.event_specific_data.error is not None
               and e.event_specific_data.error.cls_name == "DagsterExecutionInterruptedError"
               for e in result.all_events)


def run_resources(defs: dg.Definitions, tracking_uri: str = "") -> dict:
    """The resources of a partition's run: the code location's, with the MLflow store at
    ``tracking_uri`` when given (the command line's ``--tracking-uri``)."""
    from .tracking import MLflowTracker

    resources = dict(defs.resources)
    if tracking_uri:
        resources["mlflow"] = MLflowTracker(tracking_uri=tracking_uri)
    return resources


def materialize_partition(defs: dg.Definitions, key: str, resources: dict,
                          instance: dg.DagsterInstance, run_config: dict, selection
                          ) -> dg.ExecuteInProcessResult:
    """One partition's run in this process (errors are the run's, not raised), tagged with
    this host for ``doctor``; a Ctrl-C that leaves it running is sent again
    (:func:`~.interrupts.interrupts_redelivered`)."""
    with interrupts_redelivered():
        return dg.materialize(list(defs.assets), partition_key=key, selection=selection,
                              resources=resources, instance=instance, run_config=run_config,
                              tags={HOST_TAG: socket.gethostname()}, raise_on_error=False)
