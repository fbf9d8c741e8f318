"""A sweep on a dask cluster: each partition one run of ``sweep_dask`` whose steps are dask
tasks (``dagster_dask.dask_executor``).

The executor needs what :func:`dagster.materialize` cannot give it: a job that every worker
can rebuild (:func:`sweep_dask_job`, found by :func:`dagster.reconstructable`) and a
persistent Dagster instance that every worker writes its events to. The partitions run one
after the other on one scheduler (see :mod:`.jobs` for why), each run's steps in parallel on
the workers: the identification chain beside the two baselines.
"""

import contextlib
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import dagster as dg

from .io_manager import PartitionedFileIOManager
from .jobs import dask_run_config
from .partition_runs import run_tags


def sweep_dask_job() -> dg.JobDefinition:
    """The ``sweep_dask`` job of the code location, as every dask worker rebuilds it."""
    from .definitions import defs

    return defs.resolve_job_def("sweep_dask")


@contextlib.contextmanager
def dask_scheduler(address: str = "", n_workers: int = 2, processes: bool = True,
                   dashboard: str | None = ":8787") -> Iterator[str]:
    """The scheduler at ``address``, else a ``LocalCluster`` of ``n_workers`` single-threaded
    workers (processes, or threads of this process with ``processes=False``) for as long as
    the context lasts; yields the scheduler address.

    ``dashboard`` is where the LocalCluster serves dask's dashboard (another free port if
    taken; ``None``: none).
    """
    from dask.distributed import Client, LocalCluster

    with contextlib.ExitStack() as stack:
        if not address:
            address = stack.enter_context(LocalCluster(
                n_workers=n_workers, threads_per_worker=1, processes=processes,
                dashboard_address=dashboard)).scheduler_address
        _quiet_sizeof()
        with Client(address) as client:
            client.run(_quiet_sizeof)
        yield address


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
    ``instance`` must be persistent (the workers open it from its reference).
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
            success, run_id = result.success, result.run_id
        yield key, PartitionRun(key, success, run_id, io_manager)
