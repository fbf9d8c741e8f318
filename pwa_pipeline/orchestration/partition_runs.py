"""One partition's run in this process, as ``python -m pwa_pipeline run`` makes it.

Partitions run one after the other, each one run of the ``sweep`` job with every step in this
process: a partition's steps take seconds, while Dagster's multiprocess executor starts a
process per step (each importing Dagster, MLflow and scikit-learn), which costs more than
it saves. Runs at once go through Dagster's own machinery: a backfill launched in the UI,
which the daemon's run queue runs side by side, or ``--executor dask`` (`dask_sweep`).
"""

import logging
import socket
import sys

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


class ServiceLost(ValueError):
    """A store or service the runs need stopped working in the middle of a run (the Dagster
    instance's storage, a dask scheduler): no further partition starts. Its message is one
    line naming the service, the cause and what to do."""


def _storage_fault(exc: Exception, instance: dg.DagsterInstance) -> ServiceLost | None:
    """`exc`, raised by the Dagster instance's storage out of a run, as a `ServiceLost`
    naming the storage (its home, or PostgreSQL) and the database's own reason; None for
    any other error."""
    from sqlalchemy.exc import SQLAlchemyError

    if not (isinstance(exc, SQLAlchemyError)
            or type(exc).__name__ == "DagsterPostgresException"):
        return None
    reason = str(getattr(exc, "orig", None) or exc).strip().splitlines()[0]
    if "postgres" in type(instance.run_storage).__name__.lower():
        what, advice = "PostgreSQL storage", ("check that the PostgreSQL server runs "
                                              "(and $PWA_DAGSTER_POSTGRES_URL), then run again")
    else:
        what = f"storage in {instance.root_directory}"
        advice = ("free space on that disk, then run again" if "full" in reason
                  or "disk I/O" in reason else "check it with `python -m pwa_pipeline doctor`")
    return ServiceLost(f"the Dagster instance's {what} failed during the run: {reason}; "
                       f"{advice} (results already stored are kept)")


def root_cause(error) -> str:
    """The first line of what made a step or run fail: Dagster's `SerializableErrorInfo`
    (an event's `error`) followed down its `cause` chain past Dagster's own wrappers
    (`Error occurred while executing op "X":`) to the error the code raised; an interrupt
    as such."""
    while error.cause is not None and (error.cls_name or "").startswith("Dagster"):
        error = error.cause
    if error.cls_name in INTERRUPTS:
        return "interrupted (Ctrl-C or SIGTERM)"
    lines = error.message.strip().splitlines()
    if not lines:
        return error.cls_name or "no reason recorded"
    qualified, colon, text = lines[0].partition(": ")
    if colon and error.cls_name and qualified.endswith(error.cls_name):
        # a class named by its module path; a Dagster Failure's description alone
        return text if error.cls_name == "Failure" else f"{error.cls_name}: {text}"
    return lines[0]


class _OneLine(logging.Formatter):
    """A Dagster log record on one line: the event's own line, and for a failure its
    `root_cause` instead of the stack traces (kept in the run's events, shown in the
    UI)."""

    def format(self, record: logging.LogRecord) -> str:
        line = record.getMessage().split("\n")[0]
        event = getattr(record, "dagster_meta", {}).get("dagster_event")
        error = getattr(event.event_specific_data, "error", None) if event else None
        if error is not None:
            line = f"{line} Cause: {root_cause(error)}"
        return f"{self.formatTime(record, '%Y-%m-%d %H:%M:%S')} - {record.levelname} - {line}"


@dg.logger(config_schema={"log_level": dg.Field(str, is_required=False, default_value="INFO")},
           description="Dagster's events on stderr, one line each (a failure with its cause)")
def one_line_console(init_context) -> logging.Logger:
    """The command line's `console` logger (`_OneLine`)."""
    logger = logging.Logger("pwa_pipeline.run", level=init_context.logger_config["log_level"])
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_OneLine())
    logger.addHandler(handler)
    return logger


def with_one_line_console(defs: dg.Definitions) -> dg.Definitions:
    """``defs`` with the `one_line_console` logger as ``console``, as the command line and
    the dask workers run their jobs."""
    return dg.Definitions.merge(defs, dg.Definitions(loggers={"console": one_line_console}))


def cli_definitions(tracking_uri: str = "") -> dg.Definitions:
    """The code location's definitions as the command line runs them: read now (a data set
    may have been registered since import), with the MLflow store at ``tracking_uri`` when
    given (`--tracking-uri`) and the `one_line_console` logger as `console`.
    Credentials in it go to the environment (`credentials_to_environment`), never into the
    configuration that runs store."""
    from .credentials import credentials_to_environment
    from .definitions import build_definitions
    from .tracking import MLflowTracker

    resources = ({"mlflow": MLflowTracker(tracking_uri=credentials_to_environment(tracking_uri))}
                 if tracking_uri else {})
    return with_one_line_console(build_definitions(**resources))


def materialize_partition(defs: dg.Definitions, key: str, instance: dg.DagsterInstance,
                          run_config: dict) -> dg.ExecuteInProcessResult:
    """One partition's run of the ``sweep`` job in this process, so that it is listed among
    the job's runs as a run launched in the UI is (errors are the run's, not raised); tagged
    by `run_tags`. A Ctrl-C that leaves it running is sent again
    (`interrupts_redelivered`). The instance's storage failing (a full disk, a PostgreSQL
    server stopped) raises `ServiceLost`, or KeyboardInterrupt when Ctrl-C came while it
    retried."""
    with interrupts_redelivered() as interrupted:
        try:
            return defs.resolve_job_def(SWEEP_JOB).execute_in_process(
                partition_key=key, instance=instance, run_config=run_config, tags=run_tags(),
                raise_on_error=False)
        except Exception as exc:
            if (fault := _storage_fault(exc, instance)) is None:
                raise
            if interrupted.is_set():  # Ctrl-C while the storage retried: an interrupt
                raise KeyboardInterrupt from None
            raise fault from None
