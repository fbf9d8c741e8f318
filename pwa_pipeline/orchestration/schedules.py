"""The sweep job over every asset, and a schedule that requests every partition."""

import dagster as dg

from .partitions import all_keys


def build_sweep(partitions_def: dg.MultiPartitionsDefinition
                ) -> tuple:
    """The ``sweep`` job (every asset of one partition) and ``sweep_schedule``."""
    job = dg.define_asset_job("sweep", selection=dg.AssetSelection.all(),
                              description="Every asset of one partition.")

    @dg.schedule(job=job, cron_schedule="0 2 * * 6",
                 default_status=dg.DefaultScheduleStatus.STOPPED)
    def sweep_schedule(context: dg.ScheduleEvaluationContext):
        """Weekly (Saturday 02:00), one run per partition; off until turned on in the UI."""
        stamp = context.scheduled_execution_time.strftime("%Y%m%dT%H%M") \
            if context.scheduled_execution_time else "manual"
        for key in all_keys(partitions_def):
            yield dg.RunRequest(partition_key=key, run_key=f"{key}@{stamp}")

    return job, sweep_schedule
