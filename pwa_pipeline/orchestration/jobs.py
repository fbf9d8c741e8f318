"""The jobs beside ``sweep``: ``sweep_dask`` (the same assets, steps on a dask cluster) and
``refresh_leaderboard`` (the cross-partition ranking), and the dask cluster they run on.

``sweep`` (in `schedules`) runs every step of a partition in one process: a partition
launched from the UI costs one process start-up, not one per step. ``sweep_dask`` hands
each step to a dask cluster through ``dagster_dask.dask_executor``: a scheduler at
``$PWA_DASK_SCHEDULER`` (``tcp://host:8786``, started on its own with ``dask scheduler``,
its workers with ``dask worker tcp://host:8786``) when set, else a ``LocalCluster`` that the
run starts for itself (two single-threaded worker processes; Dagster steps are not
thread-safe). The launchpad shows that configuration and lets it be changed per run.

One limit of ``dagster-dask`` 0.29: it names each dask task ``<job>.<step>``, so two runs of
``sweep_dask`` in flight on the same scheduler would share task keys, and dask would hand
one run the other's results. Runs on a shared scheduler therefore take turns, each with
every worker: the executor (`dask_executor`) holds the scheduler's lock
`RUN_LOCK` (a ``distributed.Lock``, a lease that dask frees when the holding process
dies) for as long as it runs, whoever launched the run: the command line, the UI, a
schedule. The runs launched from the UI also carry the tag `EXECUTOR_TAG`, which the
instance's run queue admits one at a time (see `instance`), so that the UI never
starts more than one LocalCluster. An option of ``dagster-dask`` to name tasks by run would
let runs share a scheduler at once.
"""

import os
from collections.abc import Callable

import dagster as dg

from .interrupts import interruptible

#: The one asset that is not partitioned: it reads every partition of the scores.
LEADERBOARD = "leaderboard"
#: The job of every asset of one partition (built in `schedules`), and the leaderboard's.
SWEEP_JOB, LEADERBOARD_JOB = "sweep", "refresh_leaderboard"
#: What a sweep run materialises: every asset of one partition.
SWEEP_SELECTION = dg.AssetSelection.all() - dg.AssetSelection.assets(LEADERBOARD)
#: Environment variable naming the dask scheduler of ``sweep_dask`` (unset: a LocalCluster).
SCHEDULER_ENV = "PWA_DASK_SCHEDULER"
#: The LocalCluster a ``sweep_dask`` run starts when no scheduler is given.
LOCAL_CLUSTER = {"n_workers": 2, "threads_per_worker": 1}
#: Tag of the ``sweep_dask`` runs, which the run queue admits one at a time.
EXECUTOR_TAG = ("pwa/executor", "dask")
#: The ``distributed.Lock`` on a shared scheduler that every ``sweep_dask`` run holds while
#: it runs (see the module doc).
RUN_LOCK = "pwa-pipeline/sweep_dask"
#: Seconds of each wait for the scheduler's lock, which a waiting run repeats.
LOCK_POLL = 1.0
#: Seconds to wait for a dask scheduler to answer before giving up.
CONNECT_TIMEOUT = 10


def dask_cluster(address: str | None = None) -> dict:
    """The ``cluster`` configuration of ``dagster_dask.dask_executor``: the scheduler at
    ``address`` (default ``$PWA_DASK_SCHEDULER``), else a LocalCluster."""
    address = os.environ.get(SCHEDULER_ENV, "") if address is None else address
    if address:
        return {"existing": {"address": address}}
    return {"local": dict(LOCAL_CLUSTER)}


def dask_run_config(address: str | None = None) -> dict:
    """Run configuration selecting `dask_cluster` for a ``sweep_dask`` run."""
    return {"execution": {"config": {"cluster": dask_cluster(address)}}}


@dg.executor(
    name="dask",
    config_schema={"cluster": dg.Field(dg.Selector({
        "existing": dg.Field({"address": dg.StringSource},
                             description="Connect to an existing scheduler."),
        "local": dg.Field(dg.Permissive(), is_required=False,
                          description="LocalCluster keyword arguments."),
    }))},
    requirements=dg.multiple_process_executor_requirements(),
)
def dask_executor(init_context):
    """``dagster_dask.dask_executor`` on the configured cluster, taking turns on a shared
    scheduler (`taking_turns`). It is imported when a run uses it: importing dask's
    distributed takes about 2 s, which every process loading the code location (each run of
    ``sweep`` included) would otherwise pay. Its configuration is the ``existing`` and
    ``local`` clusters of ``dagster_dask``'s.

    ``dagster_dask`` checks that the run's executor is its own, so the lock wraps the
    ``execute`` method of the executor it returns rather than the executor."""
    from dagster_dask import dask_executor as executor

    created = executor.executor_creation_fn(init_context)
    existing = init_context.executor_config["cluster"].get("existing")
    if existing:
        created.execute = taking_turns(created.execute, existing["address"])
    return created


def taking_turns(execute: Callable, address: str) -> Callable:
    """``execute`` (an executor's `dagster.Executor.execute`) run while holding the
    lock `RUN_LOCK` of the dask scheduler at ``address``, so that runs on one
    scheduler never share task keys (see the module doc). A run that has to wait says so in
    its log and can be stopped while it waits (`interrupts.interruptible`)."""

    def locked(plan_context, execution_plan):
        from dask.distributed import Client, Lock, Variable

        with Client(address, timeout=CONNECT_TIMEOUT, set_as_default=False) as client:
            lock = Lock(RUN_LOCK, scheduler_rpc=client.scheduler, loop=client.loop)
            holder = Variable(f"{RUN_LOCK}/holder", client=client)
            if not lock.acquire(timeout=0):
                plan_context.log.info(
                    f"Waiting for the dask scheduler {address}: {_holder(holder)} holds it. "
                    f"This run's steps start when it ends; terminate this run to give up.")
                with interruptible("waiting for the dask scheduler"):
                    while not lock.acquire(timeout=LOCK_POLL):
                        pass
                plan_context.log.info(f"The dask scheduler {address} is free: this run's "
                                      f"steps start.")
            run = plan_context.dagster_run
            try:
                holder.set(f"the sweep_dask run {run.run_id} (partition "
                           f"{run.tags.get('dagster/partition', '-')})")
                yield from execute(plan_context, execution_plan)
            finally:
                try:
                    holder.delete()
                    lock.release()
                except OSError:  # the scheduler is gone, and the lease with it
                    pass

    return locked


def _holder(holder) -> str:
    """Which run holds the scheduler, as the holder wrote it in the dask ``Variable``
    ``holder`` (from when it takes the lock until it releases it)."""
    try:
        return holder.get(timeout=2)
    except TimeoutError:
        return "another sweep_dask run"


#: The automation sensor that refreshes the leaderboard after sweep runs, on by default so
#: that it is never stale while the daemon runs (``dagster dev`` starts it); it launches
#: nothing while no scores change. The command line refreshes it at its end.
LEADERBOARD_SENSOR = "leaderboard_refresh"


def build_sensors() -> list:
    """The automation sensor of the leaderboard's condition (evaluated every 30 s by the
    daemon)."""
    return [dg.AutomationConditionSensorDefinition(
        LEADERBOARD_SENSOR, target=dg.AssetSelection.assets(LEADERBOARD),
        default_status=dg.DefaultSensorStatus.RUNNING, minimum_interval_seconds=30,
        description="Refreshes the leaderboard after any partition's scores change.")]


def build_jobs() -> list:
    """``sweep_dask`` and ``refresh_leaderboard`` (``sweep`` and its schedule are built in
    `schedules`)."""
    sweep_dask = dg.define_asset_job(
        "sweep_dask", selection=SWEEP_SELECTION, executor_def=dask_executor,
        config=dask_run_config(), tags=dict([EXECUTOR_TAG]),
        description="Every asset of one partition, each step a task on a dask cluster "
                    f"(${SCHEDULER_ENV}, else a LocalCluster started by the run).")
    leaderboard = dg.define_asset_job(
        LEADERBOARD_JOB, selection=dg.AssetSelection.assets(LEADERBOARD),
        executor_def=dg.in_process_executor,
        description="Ranks every data set × hyper-parameter set × method from the stored "
                    "scores of every partition materialised so far.")
    return [sweep_dask, leaderboard]
