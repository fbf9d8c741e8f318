"""The sweep job over every partitioned asset, and a schedule that requests every partition."""

import dagster as dg

from .jobs import SWEEP_SELECTION
from .partitions import all_keys, split_key, unavailable_datasets


def build_sweep(partitions_def: dg.MultiPartitionsDefinition
                ) -> tuple:
    """The ``sweep`` job (every asset of one partition) and ``sweep_schedule``."""
    job = dg.define_asset_job("sweep", selection=SWEEP_SELECTION,
                              executor_def=dg.in_process_executor,
                              description="Every asset of one partition, in one process "
                                          "(all but the unpartitioned leaderboard).")

    @dg.schedule(job=job, cron_schedule="0 2 * * 6",
                 default_status=dg.DefaultScheduleStatus.STOPPED)
    def sweep_schedule(context: dg.ScheduleEvaluationContext):
        """Weekly (Saturday 02:00), one run per partition whose data are available (the
        others are skipped, with the reason in the tick's log); off until turned on."""
        stamp = context.scheduled_execution_time.strftime("%Y%m%dT%H%M") \
            if context.scheduled_execution_time else "manual"
        missing = unavailable_datasets()
        for dataset, reason in missing.items():
            context.log.info(f"skipping the partitions of {dataset}: {reason}")
        keys = [k for k in all_keys(partitions_def) if split_key(k)[0] not in missing]
        if not keys:
            return dg.SkipReason(f"no data set is available: {missing}")
        return [dg.RunRequest(partition_key=k, run_key=f"{k}@{stamp}") for k in keys]

    return job, sweep_schedule
