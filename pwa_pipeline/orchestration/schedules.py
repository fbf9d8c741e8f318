"""The sweep job over every partitioned asset, and a schedule that requests every partition."""

import dagster as dg

from .jobs import SWEEP_JOB, SWEEP_SELECTION
from .partitions import runnable_keys
from .settings import PipelineSettings


def build_sweep(partitions_def: dg.StaticPartitionsDefinition, settings: PipelineSettings
                ) -> tuple:
    """The ``sweep`` job (every asset of one partition) and ``sweep_schedule`` over the
    partitions that ``settings`` can run."""
    job = dg.define_asset_job(SWEEP_JOB, selection=SWEEP_SELECTION,
                              executor_def=dg.in_process_executor,
                              description="Every asset of one partition, in one process "
                                          "(all but the unpartitioned leaderboard).")

    @dg.schedule(job=job, cron_schedule="0 2 * * 6",
                 default_status=dg.DefaultScheduleStatus.STOPPED)
    def sweep_schedule(context: dg.ScheduleEvaluationContext):
        """Weekly (Saturday 02:00), one run per partition whose data are available and whose
        set has values for its data set (the others are skipped, with the reason in the
        tick's log); off until turned on."""
        stamp = context.scheduled_execution_time.strftime("%Y%m%dT%H%M") \
            if context.scheduled_execution_time else "manual"
        keys, skipped = runnable_keys(partitions_def, settings)
        for what, reason in skipped.items():
            context.log.info(f"skipping {what}: {reason}")
        if not keys:
            return dg.SkipReason(f"no partition can run: {skipped}")
        return [dg.RunRequest(partition_key=k, run_key=f"{k}@{stamp}") for k in keys]

    return job, sweep_schedule
