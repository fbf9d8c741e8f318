"""Where the pipeline keeps its files by default: absolute paths under the project."""

import os
from pathlib import Path


def project_dir() -> Path:
    """``$PWA_PIPELINE_HOME``, else the checkout holding ``pyproject.toml``, else the cwd.

    Always absolute, so that every process (CLI, ``dagster dev``, ``mlflow ui``) agrees.
    """
    env = os.environ.get("PWA_PIPELINE_HOME")
    if env:
        return Path(env).resolve()
    checkout = Path(__file__).resolve().parents[2]
    if (checkout / "pyproject.toml").is_file():
        return checkout
    return Path.cwd().resolve()


def default_tracking_uri() -> str:
    """``$MLFLOW_TRACKING_URI``, else the embedded store ``sqlite:///<project>/mlflow.db``."""
    return os.environ.get("MLFLOW_TRACKING_URI") or f"sqlite:///{project_dir() / 'mlflow.db'}"


def default_storage_dir() -> Path:
    """``<project>/storage``: materialised assets and the local-model cache."""
    return project_dir() / "storage"


def default_datasets_path() -> Path:
    """``$PWA_DATASETS``, else ``<project>/storage/datasets.json``: the user's registered data
    sets (:class:`~pwa_pipeline.datasets.user.DatasetRegistry`)."""
    env = os.environ.get("PWA_DATASETS")
    return Path(env).resolve() if env else default_storage_dir() / "datasets.json"


def dagster_home() -> Path:
    """``$DAGSTER_HOME``, else ``<project>/.dagster_home``."""
    env = os.environ.get("DAGSTER_HOME")
    return Path(env).resolve() if env else project_dir() / ".dagster_home"
