"""Dagster definitions of the pwa-pipeline code location."""

import os

import dagster as dg

from ..config import HParamsFile
from ..datasets import DATASETS
from .assets import build_assets
from .jobs import build_jobs
from .partitions import build_partitions
from .resources import MLflowTracker, PipelineSettings
from .schedules import build_sweep
from .storage import PartitionedFileIOManager


def build_definitions(hparams_path: str | os.PathLike | None = None, **resources
                      ) -> dg.Definitions:
    """The assets, sweep job, schedule and resources for one hyper-parameter file.

    The partitions' set names and the ``settings`` resource read the same file
    (``hparams_path``; default ``$PWA_HPARAMS`` or ``data/hparams.toml``), which is read and
    validated here, so a bad set (or a table for an unknown data set) fails when the
    definitions load. ``resources`` replace the
    defaults (``io_manager``, ``settings``, ``mlflow``); a replacement ``settings`` gets
    ``hparams_path`` set to that file.
    """
    hparams = HParamsFile(hparams_path)
    unknown = sorted(hparams.datasets - set(DATASETS))
    if unknown:
        raise ValueError(f"{hparams.path} has tables for unknown data set(s) {unknown}; the "
                         f"data sets are {list(DATASETS)}")
    partitions_def = build_partitions(hparams)
    job, schedule = build_sweep(partitions_def)
    settings = resources.pop("settings", PipelineSettings())
    return dg.Definitions(
        assets=build_assets(partitions_def),
        jobs=[job, *build_jobs()],
        schedules=[schedule],
        # One process per run: the steps take seconds, while the multiprocess executor
        # started a process per step (each importing Dagster, MLflow and scikit-learn) and
        # a UI-launched partition took 88 s for 3 s of compute.
        executor=dg.in_process_executor,
        resources={
            "io_manager": PartitionedFileIOManager(),
            "mlflow": MLflowTracker(),
            **resources,
            "settings": settings.with_hparams(hparams.path),
        },
    )


def partitions_of(defs: dg.Definitions) -> dg.MultiPartitionsDefinition:
    """The partitions every partitioned asset of ``defs`` shares."""
    return next(a.partitions_def for a in defs.assets if a.partitions_def is not None)


defs = build_definitions()
__all__ = ["build_definitions", "defs", "partitions_of"]
