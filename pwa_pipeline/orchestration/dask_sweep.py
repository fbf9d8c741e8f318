"""A sweep on a dask cluster: each partition one run of ``sweep_dask`` whose steps are dask
tasks (``dagster_dask.dask_executor``).

The executor needs what `dagster.materialize` cannot give it: a job that every worker
can rebuild (`sweep_dask_job`, found by `dagster.reconstructable`) and a
persistent Dagster instance that every worker writes its events to (on several machines:
PostgreSQL, see `instance`). The partitions run one after the other on one scheduler
(see `jobs` for why), each run's steps in parallel on the workers: the identification
chain beside the two baselines. The workers are given this process's stores in the run
configuration (`worker_run_config`), and are checked to reach them before any run.
"""

import contextlib
import logging
import urllib.parse
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass

import dagster as dg

from .credentials import mask_credentials
from .files import store_root
from .io_manager import PartitionedFileIOManager
from .jobs import CONNECT_TIMEOUT, dask_run_config
from .partition_runs import (
    ServiceLost,
    root_cause,
    run_tags,
    was_interrupted,
    with_one_line_console,
)
from .signed_pickles import KEY_FILE

#: Schemes of dask's communication layers an address may name.
SCHEMES = ("tcp", "tls", "ucx", "inproc", "ws", "wss")
#: Seconds to wait for a first worker to join a scheduler before giving up.
WORKER_TIMEOUT = 30


def sweep_dask_job() -> dg.JobDefinition:
    """The ``sweep_dask`` job of the code location, as every dask worker rebuilds it, with
    the command line's `one_line_console` logger as ``console``."""
    from .definitions import defs

    return with_one_line_console(defs).resolve_job_def("sweep_dask")


def check_address(address: str) -> None:
    """Raise a ValueError unless ``address`` reads as a dask scheduler's address
    (``tcp://host:8786``)."""
    parts = urllib.parse.urlsplit(address)
    if parts.scheme not in SCHEMES or not parts.netloc:
        raise ValueError(f"{address!r} is not a dask scheduler address (expected "
                         f"tcp://host:8786, as `dask scheduler` prints it)")


@contextlib.contextmanager
def dask_scheduler(address: str = "", n_workers: int = 2, processes: bool = True,
                   dashboard: str | None = ":8787", stores: Sequence[str] = ()
                   ) -> Iterator[str]:
    """The scheduler at ``address``, else a ``LocalCluster`` of ``n_workers`` single-threaded
    workers (processes, or threads of this process with ``processes=False``) for as long as
    the context lasts; yields the scheduler address.

    ``dashboard`` is where the LocalCluster serves dask's dashboard (another free port if
    taken; ``None``: none). A scheduler given by ``address`` must answer within
    `CONNECT_TIMEOUT` seconds and have a worker within `WORKER_TIMEOUT`,
    whose workers must import pwa-pipeline and find the signing key of each store of
    ``stores`` (the asset store and the cache, created by this process): else a ValueError
    says which.
    """
    from dask.distributed import Client, LocalCluster

    with contextlib.ExitStack() as stack:
        if address:
            check_address(address)
        else:
            address = stack.enter_context(LocalCluster(
                n_workers=n_workers, threads_per_worker=1, processes=processes,
                dashboard_address=dashboard)).scheduler_address
        _quiet_sizeof()
        try:
            client = Client(address, timeout=CONNECT_TIMEOUT)
        except OSError as exc:  # dask's own TimeoutError is an OSError
            raise ValueError(f"the dask scheduler {address} does not answer within "
                             f"{CONNECT_TIMEOUT} s ({exc}); start it with `dask scheduler`, "
                             f"or check the address") from None
        with client:
            _check_workers(client, address, stores)
        yield address


def check_scheduler(address: str, key: str) -> None:
    """Raise `ServiceLost` unless the scheduler at `address` still answers (within
    `CONNECT_TIMEOUT` seconds): checked after a partition's run failed, so that no further
    partition starts against a scheduler that is gone (its runs would only fail in turn)."""
    from dask.distributed import Client

    try:
        with Client(address, timeout=CONNECT_TIMEOUT, set_as_default=False):
            pass
    except OSError as exc:  # dask's own TimeoutError is an OSError
        raise ServiceLost(
            f"the dask scheduler {address} stopped answering during {key} ({exc}); no "
            f"further partition was started: start the scheduler and its workers again "
            f"(`dask scheduler`, `dask worker {address}`), then run again") from None


def _check_workers(client, address: str, stores: Sequence[str]) -> None:
    """Raise a ValueError unless the scheduler has a worker, every worker runs
    pwa-pipeline's code and sees every store of ``stores`` (see `dask_scheduler`)."""
    try:
        client.wait_for_workers(1, timeout=WORKER_TIMEOUT)
    except TimeoutError:
        raise ValueError(f"no dask worker joined the scheduler {address} within "
                         f"{WORKER_TIMEOUT} s; start one with `dask worker {address}`") from None
    try:
        missing = client.run(_missing_stores, list(stores))
    except Exception as exc:  # raised on a worker: an import, or its unpickling
        raise ValueError(f"the workers of {address} cannot run pwa-pipeline's code "
                         f"({type(exc).__name__}: {exc}); install pwa-pipeline, the same "
                         f"version, where they run") from None
    for worker, lost in missing.items():
        if lost:
            raise ValueError(
                f"dask worker {worker} does not see the store(s) "
                f"{', '.join(mask_credentials(s) for s in lost)} that this process writes "
                f"(no {KEY_FILE} there): give every machine one store, e.g. "
                f"PWA_STORAGE=s3://bucket/pwa or a shared folder")


def _missing_stores(stores: list[str]) -> list[str]:
    """On a worker: silence `_quiet_sizeof`'s warning, and return the stores of
    ``stores`` whose signing key this worker cannot see."""
    _quiet_sizeof()
    return [s for s in stores if not (store_root(s) / KEY_FILE).exists()]


def worker_run_config(resources: Mapping[str, object]) -> dict:
    """Run configuration giving the workers the stores this process resolved from its own
    settings and environment (a worker's may differ): the asset store, the cache folder and
    the MLflow tracking URI. One holding a password is left out (run configuration is stored
    with the run and shown in the Dagster UI): the workers then read ``$PWA_STORAGE`` or
    ``$MLFLOW_TRACKING_URI`` of their own environment."""
    given = {("io_manager", "base_dir"): str(resources["io_manager"].root()),
             ("settings", "cache_dir"): str(resources["settings"].cache_root()),
             ("mlflow", "tracking_uri"): resources["mlflow"].uri()}
    return {"resources": {name: {"config": {field: value}}
                          for (name, field), value in given.items()
                          if urllib.parse.urlsplit(value).password is None}}


def step_failures(instance: dg.DagsterInstance, run_id: str) -> list[str]:
    """Why the steps of a run failed, one line each (`<step>: <reason>`: the failure's
    description, else its `root_cause`), read from the instance: a step on a worker logged
    its failure there, not in this process."""
    reasons = []
    for record in instance.all_logs(run_id, of_type=dg.DagsterEventType.STEP_FAILURE):
        data = record.dagster_event.event_specific_data
        failure = getattr(data, "user_failure_data", None)
        text = failure.description if failure is not None and failure.description else (
            root_cause(data.error) if data.error is not None else "no reason recorded")
        reasons.append(f"{record.dagster_event.step_key}: {text.splitlines()[0]}")
    return reasons


@contextlib.contextmanager
def quiet_client_logs() -> Iterator[None]:
    """Silence this process's ``distributed`` loggers (its client, locks and semaphores)
    while the context lasts, then restore their levels: a scheduler lost mid-run made them
    print several stack traces of reconnection attempts before the command's own line
    (`check_scheduler`), which says what happened and what to do."""
    names = ["distributed", *(n for n in logging.root.manager.loggerDict
                              if n.startswith("distributed."))]
    levels = {n: logging.getLogger(n).level for n in names}
    for n in names:
        logging.getLogger(n).setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for n, level in levels.items():
            logging.getLogger(n).setLevel(level)


def _quiet_sizeof() -> None:
    """Silence distributed's warning, at every task, that it cannot size Dagster's events."""
    logging.getLogger("distributed.sizeof").setLevel(logging.ERROR)


@dataclass
class PartitionRun:
    """One partition's ``sweep_dask`` run, whose steps ran in other processes: whether it
    succeeded or was interrupted, its run id, and its
    outputs read from the store (a ``JobExecutionResult`` reads them without the partition)."""

    key: str
    success: bool
    run_id: str
    io_manager: PartitionedFileIOManager
    interrupted: bool = False

    def asset_value(self, asset: str):
        """The stored value of ``asset`` for this partition."""
        return self.io_manager.load(dg.AssetKey(asset), self.key)


def sweep_on_dask(keys: list[str], instance: dg.DagsterInstance, address: str,
                  run_config: dict | None = None,
                  before: Callable[[str], None] | None = None,
                  io_manager: PartitionedFileIOManager | None = None
                  ) -> Iterator[tuple[str, PartitionRun]]:
    """Run ``sweep_dask`` for each partition key in turn on the scheduler at ``address``.

    Yields ``(key, run)``. ``run_config`` is merged with the cluster's (e.g. resources,
    loggers); ``before(key)`` is called as each run starts; ``io_manager`` is the store the
    runs write to (default: the code location's), which the outputs are read from.
    ``instance`` must be persistent (the workers open it from its reference). Each run
    holds the scheduler's `RUN_LOCK` (its executor takes it), so that other
    runs on the same scheduler wait for it rather than share its task names (see
    `jobs`).
    """
    from .definitions import defs, partitions_of

    partitions_def = partitions_of(defs)
    io_manager = io_manager or defs.resources["io_manager"]
    job = dg.reconstructable(sweep_dask_job)
    config = {**(run_config or {}), **dask_run_config(address)}
    for key in keys:
        if before is not None:
            before(key)
        tags = {**run_tags(), **partitions_def.get_tags_for_partition_key(key)}
        with dg.execute_job(job, instance, run_config=config, tags=tags) as result:
            run = PartitionRun(key, result.success, result.run_id, io_manager,
                               was_interrupted(result))
        yield key, run
