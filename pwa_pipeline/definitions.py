"""Dagster definitions of the pwa-pipeline code location."""

import dagster as dg

from .pipeline.assets import ASSETS
from .pipeline.resources import MLflowTracker, PipelineConfig
from .pipeline.schedules import sweep_job, sweep_schedule
from .pipeline.storage import PartitionedFileIOManager

defs = dg.Definitions(
    assets=ASSETS,
    jobs=[sweep_job],
    schedules=[sweep_schedule],
    resources={
        "io_manager": PartitionedFileIOManager(),
        "config": PipelineConfig(),
        "mlflow": MLflowTracker(),
    },
)
