"""Resources: data and hyper-parameter locations, and MLflow tracking."""

import json
import os
import urllib.error
import urllib.request
from pathlib import Path

import dagster as dg
import numpy as np
import pandas as pd

from ..config import Configuration, HParamsFile
from ..datasets import Dataset, load_dataset
from .paths import default_storage_dir, default_tracking_uri


class PipelineSettings(dg.ConfigurableResource):
    """Where the pipeline reads its inputs and caches local models.

    Attributes
    ----------
    kuka_path : str
        The KUKA ``.mat`` file or its folder; empty: ``$PWA_KUKA_DATA`` or
        ``../shared/data/kuka-kr300`` beside the project.
    hparams_path : str
        The hyper-parameter file. :func:`~pwa_pipeline.orchestration.definitions.build_definitions`
        sets it to the file its partitions were read from; empty: ``$PWA_HPARAMS`` or
        ``data/hparams.toml``.
    cache_dir : str
        Local-model cache; empty: ``<project>/storage/cache``.
    cache_local_models : bool
        Reuse local models across hyper-parameter sets that differ only in later steps.
    """

    kuka_path: str = ""
    hparams_path: str = ""
    cache_dir: str = ""
    cache_local_models: bool = True

    def with_hparams(self, path: str | os.PathLike) -> "PipelineSettings":
        """A copy reading the hyper-parameter file ``path``.

        (pydantic's ``model_copy(update=...)`` changes the attribute but not the
        configuration Dagster runs with, so the copy is built anew.)
        """
        values = {name: getattr(self, name) for name in type(self).model_fields}
        return type(self)(**{**values, "hparams_path": str(path)})

    def dataset(self, name: str) -> Dataset:
        """The named data set (raises FileNotFoundError naming the KUKA path if absent)."""
        return load_dataset(name, kuka_path=self.kuka_path or None)

    def configuration(self, hparams: str, dataset: str) -> Configuration:
        """The resolved configuration of one partition (the file read and checked once)."""
        return HParamsFile(self.hparams_path or None).configuration(hparams, dataset)

    def cache_root(self) -> Path:
        """The local-model cache folder."""
        return Path(self.cache_dir).resolve() if self.cache_dir else default_storage_dir() / "cache"


class MLflowTracker(dg.ConfigurableResource):
    """Logs one MLflow run per method and partition materialisation.

    One experiment per data set (``<experiment_prefix>/<dataset>``); each run carries the
    hyper-parameters as params, the scores as metrics, the Dagster run id and partition as
    tags, and the parameter matrices and score table as artifacts.

    Attributes
    ----------
    tracking_uri : str
        Empty: ``$MLFLOW_TRACKING_URI`` or the embedded ``sqlite:///<project>/mlflow.db``.
    experiment_prefix : str
    timeout_seconds : float
        How long to wait for a tracking server before failing.
    """

    tracking_uri: str = ""
    experiment_prefix: str = "pwa-pipeline"
    timeout_seconds: float = 5.0

    def uri(self) -> str:
        """The tracking URI in use."""
        return self.tracking_uri or default_tracking_uri()

    def check_reachable(self) -> None:
        """Fail fast, with the URI in the message, if the tracking store cannot be used."""
        uri = self.uri()
        if uri.startswith(("http://", "https://")):
            try:
                with urllib.request.urlopen(uri.rstrip("/") + "/health",
                                            timeout=self.timeout_seconds) as resp:
                    if resp.status != 200:
                        raise OSError(f"HTTP {resp.status}")
            except (OSError, urllib.error.URLError) as exc:
                raise dg.Failure(
                    description=(
                        f"MLflow tracking server {uri} cannot be reached ({exc}). Start it, "
                        f"or unset MLFLOW_TRACKING_URI to use the embedded store; assets "
                        f"already materialised are kept."
                    )
                ) from None
        elif uri.startswith("sqlite:///"):
            folder = Path(uri[len("sqlite:///"):]).parent
            if not os.access(folder, os.W_OK):
                raise dg.Failure(description=f"MLflow store folder {folder} is not writable")

    def _client(self):
        import mlflow
        from mlflow.tracking import MlflowClient

        # Artifact repositories of a tracking server resolve through the global URI.
        mlflow.set_tracking_uri(self.uri())
        return MlflowClient(tracking_uri=self.uri())

    def _experiment(self, client, dataset: str) -> str:
        name = f"{self.experiment_prefix}/{dataset}"
        exp = client.get_experiment_by_name(name)
        if exp is not None:
            return exp.experiment_id
        location = None
        if self.uri().startswith("sqlite:///"):
            # beside the database, never relative to whichever process's working directory
            db = Path(self.uri()[len("sqlite:///"):])
            location = (db.parent / "mlartifacts" / dataset).as_uri()
        return client.create_experiment(name, artifact_location=location)

    def log_run(
        self,
        *,
        dataset: str,
        hparams: str,
        method: str,
        params: dict,
        metrics: dict[str, float],
        tags: dict[str, str],
        artifacts: dict[str, object],
    ) -> str:
        """Create, fill and close one run; returns its id.

        ``artifacts`` maps file names to dicts (written as JSON), DataFrames (as CSV) or
        matplotlib figures (as PNG).
        """
        from mlflow.entities import Metric, Param, RunTag

        self.check_reachable()
        client = self._client()
        exp_id = self._experiment(client, dataset)
        run = client.create_run(exp_id, run_name=f"{method}|{hparams}",
                                tags={"dataset": dataset, "hparams": hparams,
                                      "method": method, **tags})
        run_id = run.info.run_id
        try:
            # A diverged free run scores ±inf, which tracking stores reject: log ±1e300 (the
            # scores.csv artifact keeps the exact value).
            values = {k: float(v) for k, v in metrics.items() if v is not None}
            finite = {k: float(np.clip(v, -1e300, 1e300)) for k, v in values.items()}
            client.log_batch(
                run_id,
                metrics=[Metric(k, v, 0, 0) for k, v in finite.items()],
                params=[Param(k, str(v)) for k, v in {"method": method, **params}.items()],
                tags=[RunTag(k, str(v)) for k, v in tags.items()],
            )
            for name, obj in artifacts.items():
                if hasattr(obj, "savefig"):
                    client.log_figure(run_id, obj, name)
                elif isinstance(obj, pd.DataFrame):
                    client.log_text(run_id, obj.to_csv(index=False), name)
                else:
                    client.log_text(run_id, json.dumps(obj, indent=2, default=float), name)
            client.set_terminated(run_id, "FINISHED")
        except Exception:
            client.set_terminated(run_id, "FAILED")
            raise
        return run_id
