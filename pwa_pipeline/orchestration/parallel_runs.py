"""Partitions materialised at once: this process runs some, worker processes the others.

``python -m pwa_pipeline run --jobs N`` keeps N partitions in flight: this process takes the
next waiting partition whenever its own run ends, and each of N − 1 worker processes does the
same. Each partition is one ``dg.materialize`` run on the same Dagster instance, asset store
and MLflow store, whichever process runs it; the stores take runs at once as they do under
``dagster dev`` (Dagster's sqlite storage with one event-log file per run; the asset store's
atomic signed files; the MLflow sqlite store created under a file lock, see
:class:`~pwa_pipeline.orchestration.resources.MLflowTracker`). The workers are started with
``spawn`` (a fork would copy this process's Dagster and BLAS threads) and import the code
location once each, while this process runs its first partition.

Most of a run is one thread (the clustering, sub-model and region steps, the baselines,
figures, MLflow logging, Dagster's events); two runs at once fill both cores of a 2-core
machine, at the cost of two processes' memory.
"""

import os
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing import get_context

import dagster as dg

from .dask_sweep import PartitionRun
from .interrupts import interrupts_redelivered
from .storage import PartitionedFileIOManager


def default_jobs() -> int:
    """Partitions at once by default: the CPUs this process may use, at most 2 (each run
    holds its own data and fitted models in memory)."""
    return max(1, min(2, len(os.sched_getaffinity(0))))


@dataclass
class LostRun:
    """A partition whose worker process ended before its run did (killed, out of memory), or
    was interrupted before Dagster could record it."""

    key: str
    reason: str
    success: bool = False
    interrupted: bool = False

    @property
    def run_id(self) -> str:
        return f"unknown: its worker process ended ({self.reason})"


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
    from .resources import MLflowTracker

    resources = dict(defs.resources)
    if tracking_uri:
        resources["mlflow"] = MLflowTracker(tracking_uri=tracking_uri)
    return resources


def materialize_partition(defs: dg.Definitions, key: str, resources: dict,
                          instance: dg.DagsterInstance, run_config: dict, selection
                          ) -> dg.ExecuteInProcessResult:
    """One partition's run in this process (errors are the run's, not raised); a Ctrl-C
    that leaves it running is sent again (:func:`~.interrupts.interrupts_redelivered`)."""
    with interrupts_redelivered():
        return dg.materialize(list(defs.assets), partition_key=key, selection=selection,
                              resources=resources, instance=instance, run_config=run_config,
                              raise_on_error=False)


_WORKER: dict = {}


def _worker_run(key: str, run_config: dict, tracking_uri: str) -> tuple[bool, str, bool]:
    """In a worker process: one partition's run; ``(success, run id, interrupted)``. The definitions,
    resources and instance are built at the worker's first run, from the environment this
    process was started with (``DAGSTER_HOME`` and the project's paths)."""
    from .definitions import build_definitions
    from .instance import prepare_instance
    from .jobs import SWEEP_SELECTION

    if not _WORKER:
        defs = build_definitions()
        _WORKER.update(defs=defs, resources=run_resources(defs, tracking_uri),
                       instance=prepare_instance())
    result = materialize_partition(_WORKER["defs"], key, _WORKER["resources"],
                                   _WORKER["instance"], run_config, SWEEP_SELECTION)
    return result.success, result.run_id, was_interrupted(result)


def _warm_up() -> None:
    """Import the code location in a worker before its first partition arrives."""
    from . import definitions  # noqa: F401


def partition_runs_at_once(keys: list[str], jobs: int, run_here: Callable[[str], object],
                           run_config: dict, tracking_uri: str,
                           io_manager: PartitionedFileIOManager,
                           announce: Callable[[str], None]
                           ) -> Iterator[tuple[str, object, float]]:
    """``(key, result, seconds)`` of every partition started, in the order they end; none
    is started once a run was interrupted (the runs in flight end and are yielded).

    ``run_here(key)`` runs a partition in this process; ``jobs − 1`` worker processes run
    the others with ``run_config`` and ``tracking_uri`` (empty: the default store), their
    results read back from ``io_manager``'s store (:class:`PartitionRun`). A worker process
    that dies (killed, out of memory; or a script calling the command line without an
    ``if __name__ == "__main__":`` guard, which ``spawn`` runs again in the worker) fails
    the partition it ran (:class:`LostRun`); this process runs the partitions still waiting.
    """
    waiting = deque(keys)
    lock, stop = threading.Lock(), threading.Event()
    finished: queue.Queue = queue.Queue()

    def take() -> str | None:
        with lock:
            return waiting.popleft() if waiting and not stop.is_set() else None

    def feed(pool: ProcessPoolExecutor) -> None:  # one worker's partitions, one at a time
        while (key := take()) is not None:
            announce(key)
            t0 = time.perf_counter()
            try:
                success, run_id, interrupted = pool.submit(_worker_run, key, run_config,
                                                           tracking_uri).result()
            except BrokenProcessPool as exc:  # the rest is left to this process
                finished.put((key, LostRun(key, str(exc)), time.perf_counter() - t0))
                return
            except KeyboardInterrupt:  # an interrupt outside the run's own handling
                stop.set()
                finished.put((key, LostRun(key, "interrupted", interrupted=True),
                              time.perf_counter() - t0))
                return
            if interrupted:
                stop.set()
            finished.put((key, PartitionRun(key, success, run_id, io_manager, interrupted),
                          time.perf_counter() - t0))

    with ProcessPoolExecutor(jobs - 1, mp_context=get_context("spawn")) as pool:
        for _ in range(jobs - 1):
            pool.submit(_warm_up)
        feeders = [threading.Thread(target=feed, args=(pool,), daemon=True)
                   for _ in range(jobs - 1)]
        for thread in feeders:
            thread.start()
        while (key := take()) is not None:
            announce(key)
            t0 = time.perf_counter()
            result = run_here(key)
            if was_interrupted(result):
                stop.set()
            yield key, result, time.perf_counter() - t0
            while not finished.empty():
                yield finished.get()
        while any(thread.is_alive() for thread in feeders) or not finished.empty():
            try:
                yield finished.get(timeout=0.2)
            except queue.Empty:
                pass
