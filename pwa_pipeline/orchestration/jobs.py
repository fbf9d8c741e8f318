"""The jobs beside ``sweep``: ``sweep_dask`` (the same assets, steps on a dask cluster) and
``refresh_leaderboard`` (the cross-partition ranking), and the dask cluster they run on.

``sweep`` (in :mod:`.schedules`) runs every step of a partition in one process: a partition
launched from the UI costs one process start-up, not one per step. ``sweep_dask`` hands
each step to a dask cluster through ``dagster_dask.dask_executor``: a scheduler at
``$PWA_DASK_SCHEDULER`` (``tcp://host:8786``, started on its own with ``dask scheduler``,
its workers with ``dask worker tcp://host:8786``) when set, else a ``LocalCluster`` that the
run starts for itself (two single-threaded worker processes; Dagster steps are not
thread-safe). The launchpad shows that configuration and lets it be changed per run.

One limit of ``dagster-dask`` 0.29: it names each dask task ``<job>.<step>``, so two runs of
``sweep_dask`` in flight on the same scheduler would share task keys, and dask would hand
one run the other's results. Runs on a shared scheduler therefore take turns, each with
every worker: the command line's runs hold the scheduler's lock :data:`RUN_LOCK` (a
``distributed.Lock``, a lease that dask frees when the holding process dies) while they
run, so that any number of clients may sweep at once (:mod:`.dask_sweep`), and the runs
launched from the UI carry the tag :data:`EXECUTOR_TAG` that the instance's run queue admits
one at a time (see :mod:`.instance`).
"""

import os

import dagster as dg

#: The one asset that is not partitioned: it reads every partition of the scores.
LEADERBOARD = "leaderboard"
#: The job of every asset of one partition (built in :mod:`.schedules`), and the leaderboard's.
SWEEP_JOB, LEADERBOARD_JOB = "sweep", "refresh_leaderboard"
#: What a sweep run materialises: every asset of one partition.
SWEEP_SELECTION = dg.AssetSelection.all() - dg.AssetSelection.assets(LEADERBOARD)
#: Environment variable naming the dask scheduler of ``sweep_dask`` (unset: a LocalCluster).
SCHEDULER_ENV = "PWA_DASK_SCHEDULER"
#: The LocalCluster a ``sweep_dask`` run starts when no scheduler is given.
LOCAL_CLUSTER = {"n_workers": 2, "threads_per_worker": 1}
#: Tag of the ``sweep_dask`` runs, which the run queue admits one at a time.
EXECUTOR_TAG = ("pwa/executor", "dask")
#: The ``distributed.Lock`` on a shared scheduler that the command line's ``sweep_dask`` runs
#: hold while they run (see the module doc).
RUN_LOCK = "pwa-pipeline/sweep_dask"


def dask_cluster(address: str | None = None) -> dict:
    """The ``cluster`` configuration of ``dagster_dask.dask_executor``: the scheduler at
    ``address`` (default ``$PWA_DASK_SCHEDULER``), else a LocalCluster."""
    address = os.environ.get(SCHEDULER_ENV, "") if address is None else address
    if address:
        return {"existing": {"address": address}}
    return {"local": dict(LOCAL_CLUSTER)}


def dask_run_config(address: str | None = None) -> dict:
    """Run configuration selecting :func:`dask_cluster` for a ``sweep_dask`` run."""
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
    """``dagster_dask.dask_executor``, imported when a run uses it: importing dask's
    distributed takes about 2 s, which every process loading the code location (each run of
    ``sweep`` included) would otherwise pay. Its configuration is the ``existing`` and
    ``local`` clusters of ``dagster_dask``'s."""
    from dagster_dask import dask_executor as executor

    return executor.executor_creation_fn(init_context)


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
    :mod:`.schedules`)."""
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
