"""Where the pipeline keeps its files by default: absolute paths under the project, or the
asset store at ``$PWA_STORAGE`` (a folder or an fsspec URL shared by every machine)."""

import os
from pathlib import Path

from upath import UPath

from .files import store_root

#: Environment variable naming the asset store: a folder, or an fsspec URL such as
#: ``s3://bucket/pwa`` that every process running steps can reach.
STORAGE_ENV = "PWA_STORAGE"


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


#: The query that opens MLflow 3.17's UI in its model-training view: the UI keeps a global
#: GenAI / model-training switch (GenAI until the user flips it, stored in the browser) and
#: ignores the experiment's ``mlflow.experimentKind`` tag while that switch is shown.
MLFLOW_TRAINING_VIEW = "?workflowType=machine_learning"


def default_mlflow_ui_url() -> str:
    """``$PWA_MLFLOW_UI_URL``, else ``http://127.0.0.1:5000`` (``mlflow ui``'s default): where
    the MLflow UI of a local (sqlite) store is served, for the links the pipeline prints."""
    return (os.environ.get("PWA_MLFLOW_UI_URL") or "http://127.0.0.1:5000").rstrip("/")


def default_storage_dir() -> UPath:
    """``$PWA_STORAGE`` (a folder or an fsspec URL), else ``<project>/storage``: materialised
    assets, the caches and the exports (see `files.store_root`)."""
    return store_root(os.environ.get(STORAGE_ENV) or project_dir() / "storage")


def default_datasets_path() -> Path:
    """``$PWA_DATASETS``, else ``<project>/storage/datasets.json``: the user's registered data
    sets (`DatasetRegistry`). A local file whatever
    ``$PWA_STORAGE`` says, as the files it registers are: on several machines, point
    ``$PWA_DATASETS`` at a file they share."""
    env = os.environ.get("PWA_DATASETS")
    return Path(env).resolve() if env else project_dir() / "storage" / "datasets.json"


def dagster_home() -> Path:
    """``$DAGSTER_HOME``, else ``<project>/.dagster_home``."""
    env = os.environ.get("DAGSTER_HOME")
    return Path(env).resolve() if env else project_dir() / ".dagster_home"
