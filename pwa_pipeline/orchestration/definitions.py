"""Dagster definitions of the pwa-pipeline code location."""

import os

import dagster as dg

from ..config import load_hparams
from ..datasets import DATASETS
from .assets import build_assets
from .io_manager import PartitionedFileIOManager
from .jobs import build_jobs, build_sensors
from .partitions import build_partitions
from .paths import default_datasets_path
from .registry import DatasetRegistry
from .schedules import build_sweep
from .settings import PipelineSettings
from .tracking import MLflowTracker


def build_definitions(hparams_path: str | os.PathLike | None = None,
                      datasets_path: str | os.PathLike | None = None, **resources
                      ) -> dg.Definitions:
    """The assets, sweep job, schedule and resources for one hyper-parameter file and one
    registry of user data sets.

    The partitions and the ``settings`` resource read the same files: ``hparams_path``
    (default ``$PWA_HPARAMS`` or ``data/hparams.toml``) gives the ``hparams`` dimension and
    ``datasets_path`` (default ``$PWA_DATASETS`` or ``<project>/storage/datasets.json``)
    adds the registered data sets to the ``dataset`` dimension. Both are read and checked
    here, so a bad set (or a table for an unknown data set) fails when the definitions load;
    a data set registered later appears when the definitions are reloaded. ``resources``
    replace the defaults (``io_manager``, ``settings``, ``mlflow``); a replacement
    ``settings`` gets both paths set to these files.
    """
    hparams = load_hparams(hparams_path)
    registry = DatasetRegistry(datasets_path or default_datasets_path())
    registered = registry.names()
    unknown = sorted(hparams.datasets - set(DATASETS) - set(registered))
    if unknown:
        raise ValueError(f"{hparams.path} has tables for unknown data set(s) {unknown}; the "
                         f"data sets are {[*DATASETS, *registered]}")
    partitions_def = build_partitions(hparams, registered)
    settings = resources.pop("settings", PipelineSettings()).with_files(hparams.path,
                                                                        registry.path)
    job, schedule = build_sweep(partitions_def, settings)
    return dg.Definitions(
        assets=build_assets(partitions_def),
        jobs=[job, *build_jobs()],
        schedules=[schedule],
        sensors=build_sensors(),
        # One process per run: the steps take seconds, while the multiprocess executor
        # starts a process per step, each importing Dagster, MLflow and scikit-learn.
        executor=dg.in_process_executor,
        resources={
            "io_manager": PartitionedFileIOManager(),
            "mlflow": MLflowTracker(),
            **resources,
            "settings": settings,
        },
    )


def partitions_of(defs: dg.Definitions) -> dg.StaticPartitionsDefinition:
    """The partitions every partitioned asset of ``defs`` shares."""
    return next(a.partitions_def for a in defs.assets if a.partitions_def is not None)


defs = build_definitions()
__all__ = ["build_definitions", "defs", "partitions_of"]
