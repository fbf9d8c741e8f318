"""Resources for materialising the pipeline in a test: its own asset store, caches and a
copy of the migrated MLflow store, reading the hyper-parameter file and registry of the
definitions under test."""

import shutil
from pathlib import Path

from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.settings import PipelineSettings
from pwa_pipeline.orchestration.tracking import MLflowTracker


def run_resources(tmp_path: Path, mlflow_template: Path, settings: PipelineSettings) -> dict:
    """``io_manager``, ``settings`` and ``mlflow`` under ``tmp_path`` (MLflow in
    ``tmp_path / "mlflow.db"``)."""
    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    return {"io_manager": PartitionedFileIOManager(base_dir=str(tmp_path / "storage")),
            "settings": PipelineSettings(cache_dir=str(tmp_path / "cache"))
            .with_files(settings.hparams_path, settings.datasets_path),
            "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{db}")}
