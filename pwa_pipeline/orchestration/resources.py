"""Resources: data and hyper-parameter locations, and MLflow tracking."""

import base64
import contextlib
import json
import logging
import os
import tempfile
import urllib.error
import urllib.parse
import urllib.request
from importlib.metadata import version
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import dagster as dg
import numpy as np
import pandas as pd

from ..config import Configuration, HParamsFile
from ..datasets import Dataset, load_dataset
from ..datasets.user import DatasetRegistry
from .paths import (
    MLFLOW_TRAINING_VIEW,
    default_datasets_path,
    default_mlflow_ui_url,
    default_storage_dir,
    default_tracking_uri,
)

if TYPE_CHECKING:
    from .mlflow_models import ModelToLog

#: What a logged model needs to load elsewhere (pinned to the versions that logged it).
REQUIREMENTS = ("pwa-pipeline", "numpy", "scipy", "scikit-learn", "pandas")
#: Run tags that say where a run's model is (see :meth:`MLflowTracker.log_run`).
MODEL_TAGS = ("model_uri", "model_id", "model_run_id")
#: The experiment tag of MLflow 3 for classic model training (not GenAI); MLflow 3.17's UI
#: follows its own GenAI / model-training switch instead, so links add ``MLFLOW_TRAINING_VIEW``.
EXPERIMENT_KIND = ("mlflow.experimentKind", "custom_model_development")
#: sqlite tracking stores whose schema this process has created or checked.
_READY_STORES: set[str] = set()
#: How long :func:`_write_ahead_log` waits for a store that another process is reading.
WAL_WAIT_SECONDS = 5.0
#: Lock files of :meth:`MLflowTracker._models_lock` per sqlite store.
_MODEL_LOCKS = 16


def split_credentials(uri: str) -> tuple[str, str]:
    """``(uri without user:password@, base64 'user:password' or '')``."""
    parts = urllib.parse.urlsplit(uri)
    if parts.username is None:
        return uri, ""
    host = parts.hostname + (f":{parts.port}" if parts.port else "")
    token = base64.b64encode(f"{urllib.parse.unquote(parts.username)}:"
                             f"{urllib.parse.unquote(parts.password or '')}".encode()).decode()
    return urllib.parse.urlunsplit(parts._replace(netloc=host)), token


def mask_credentials(uri: str) -> str:
    """``uri`` with a password replaced by ``***``, for messages and logs."""
    parts = urllib.parse.urlsplit(uri)
    if parts.password is None:
        return uri
    return urllib.parse.urlunsplit(parts._replace(
        netloc=parts.netloc.replace(f":{parts.password}@", ":***@", 1)))


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
    datasets_path : str
        The registry of the user's data sets (``python -m pwa_pipeline add-dataset``); set by
        ``build_definitions`` like ``hparams_path``; empty: ``$PWA_DATASETS`` or
        ``<project>/storage/datasets.json``.
    cache_dir : str
        Cache of local models, of step 5, of the baselines and of scores and figures; empty:
        ``<project>/storage/cache``.
    cache_local_models : bool
        Reuse local models across hyper-parameter sets that differ only in later steps.
    cache_sub_models : bool
        Reuse step 5's refinement (``RefinedSubModels(memory=...)``) across sets whose
        clusterings consolidate to the same sub-models (e.g. sets that differ only in ε).
    cache_baselines : bool
        Reuse the fitted baselines across the sets of a data set with the same baseline
        settings.
    cache_scores : bool
        Reuse a model's scores and figures (prediction; for a PWA model also its switching
        and regions figures) across sets whose fitted models predict alike
        (:func:`~pwa_pipeline.orchestration.mlflow_models.predictor_fingerprint`): a
        baseline shared by the sets of a data set, or a PWA model that sets differing only
        in ε or MinPts end in.
    """

    kuka_path: str = ""
    hparams_path: str = ""
    datasets_path: str = ""
    cache_dir: str = ""
    cache_local_models: bool = True
    cache_sub_models: bool = True
    cache_baselines: bool = True
    cache_scores: bool = True

    def with_files(self, hparams_path: str | os.PathLike,
                   datasets_path: str | os.PathLike) -> "PipelineSettings":
        """A copy reading the hyper-parameter file and data-set registry given.

        (pydantic's ``model_copy(update=...)`` changes the attribute but not the
        configuration Dagster runs with, so the copy is built anew.)
        """
        values = {name: getattr(self, name) for name in type(self).model_fields}
        return type(self)(**{**values, "hparams_path": str(hparams_path),
                             "datasets_path": str(datasets_path)})

    def hparams(self) -> HParamsFile:
        """The hyper-parameter file, read and checked."""
        return HParamsFile(self.hparams_path or None)

    def registry(self) -> DatasetRegistry:
        """The user's registered data sets."""
        return DatasetRegistry(self.datasets_path or default_datasets_path())

    def dataset(self, name: str) -> Dataset:
        """The named data set (raises FileNotFoundError naming the path if its file is
        absent)."""
        return load_dataset(name, kuka_path=self.kuka_path or None, registry=self.registry())

    def configuration(self, hparams: str, dataset: str) -> Configuration:
        """The resolved configuration of one partition; a registered data set brings its
        orders (see :meth:`HParamsFile.configuration`)."""
        registry = self.registry()
        orders = registry.get(dataset).orders() if dataset in registry.names() else None
        return self.hparams().configuration(hparams, dataset, orders)

    def cache_root(self) -> Path:
        """The cache folder (local models, step 5, baselines, scores and figures)."""
        return Path(self.cache_dir).resolve() if self.cache_dir else default_storage_dir() / "cache"


class MLflowTracker(dg.ConfigurableResource):
    """Logs one MLflow run per method and partition materialisation.

    One experiment per data set (``<experiment_prefix>/<dataset>``); each run carries the
    hyper-parameters as params, the scores as metrics, the Dagster run id and partition as
    tags, and the parameter matrices and score table as artifacts.

    Failures are bounded: a tracking server is probed first (``timeout_seconds``), and every
    MLflow request then gets ``request_timeout`` seconds and ``request_retries`` retries
    (MLflow's own defaults, 120 s and 7 retries, stall an asset for minutes on a broken
    server). Credentials in the URI (``http://user:password@host``) are used for the probe and
    never printed. A new sqlite store is created under a file lock, so runs that start at once
    do not race in MLflow's schema migration, and is put in sqlite's write-ahead-log mode
    (:func:`_write_ahead_log`).

    Attributes
    ----------
    tracking_uri : str
        Empty: ``$MLFLOW_TRACKING_URI`` or the embedded ``sqlite:///<project>/mlflow.db``.
    experiment_prefix : str
    ui_url : str
        Where the MLflow UI of a local (sqlite) store is served; empty:
        ``$PWA_MLFLOW_UI_URL`` or ``http://127.0.0.1:5000`` (``mlflow ui``'s default). Run
        links point there, or at the tracking server itself, in the model-training view.
    timeout_seconds : float
        How long to wait for a tracking server's health probe before failing.
    request_timeout : float
        Seconds per MLflow HTTP request.
    request_retries : int
        Retries per MLflow HTTP request.
    """

    tracking_uri: str = ""
    experiment_prefix: str = "pwa-pipeline"
    ui_url: str = ""
    timeout_seconds: float = 5.0
    request_timeout: float = 10.0
    request_retries: int = 2

    def uri(self) -> str:
        """The tracking URI in use."""
        return self.tracking_uri or default_tracking_uri()

    def check_reachable(self) -> None:
        """Fail fast, with the URI (credentials masked) in the message, if the tracking store
        cannot be used."""
        uri = self.uri()
        if uri.startswith(("http://", "https://")):
            url, auth = split_credentials(uri)
            request = urllib.request.Request(url.rstrip("/") + "/health")
            if auth:
                request.add_header("Authorization", "Basic " + auth)
            try:
                with urllib.request.urlopen(request, timeout=self.timeout_seconds) as resp:
                    if resp.status != 200:
                        raise OSError(f"HTTP {resp.status}")
            except (OSError, urllib.error.URLError) as exc:
                raise dg.Failure(
                    description=(
                        f"MLflow tracking server {mask_credentials(uri)} cannot be reached "
                        f"({exc}). Start it, or unset MLFLOW_TRACKING_URI to use the embedded "
                        f"store; assets already materialised are kept."
                    )
                ) from None
        elif (db := self._sqlite_db()) is not None:
            folder = db.parent
            if not os.access(folder, os.W_OK):
                raise dg.Failure(description=f"MLflow store folder {folder} is not writable")

    def client(self):
        """An MLflow client on the tracking URI, the store created if new (see the class doc)."""
        import mlflow
        from mlflow.tracking import MlflowClient

        uri = self.uri()
        if uri.startswith(("http://", "https://")):
            # read by MLflow at each request; process-wide, as MLflow offers no other way
            os.environ["MLFLOW_HTTP_REQUEST_TIMEOUT"] = str(self.request_timeout)
            os.environ["MLFLOW_HTTP_REQUEST_MAX_RETRIES"] = str(self.request_retries)
            os.environ["MLFLOW_HTTP_REQUEST_BACKOFF_FACTOR"] = "1"
        # Artifact repositories of a tracking server resolve through the global URI.
        mlflow.set_tracking_uri(uri)
        if (db := self._sqlite_db()) is not None and uri not in _READY_STORES:
            from filelock import FileLock

            # the client's first use of a store creates and migrates its schema
            with FileLock(f"{db}.lock"):
                client = MlflowClient(tracking_uri=uri)
                client.search_experiments(max_results=1)
                _write_ahead_log(db)
            _READY_STORES.add(uri)
            return client
        return MlflowClient(tracking_uri=uri)

    def _sqlite_db(self) -> Path | None:
        """The database file of an embedded sqlite store; None for a tracking server."""
        uri = self.uri()
        return Path(uri[len("sqlite:///"):]) if uri.startswith("sqlite:///") else None

    def _models_lock(self, fingerprint: str | None):
        """For the embedded sqlite store, a lock held from looking for a run's logged model
        to the run's end, so that runs of other processes scoring the same model at the same
        moment (``run --jobs 2``) log it once: one of :data:`_MODEL_LOCKS` files in
        ``<database>.locks/``, chosen by the model's ``fingerprint``, so that runs of other
        models rarely wait. No lock for a run without a model (``fingerprint`` None), nor
        for a tracking server (its runs may come from other machines)."""
        from filelock import FileLock

        db = self._sqlite_db()
        if fingerprint is None or db is None:
            return contextlib.nullcontext()
        folder = db.parent / f"{db.name}.locks"
        folder.mkdir(exist_ok=True)
        return FileLock(folder / f"model-{int(fingerprint[:8], 16) % _MODEL_LOCKS}.lock")

    def _experiment(self, client, dataset: str) -> str:
        """Get or create the data set's experiment; another process creating it at the same
        moment is fine."""
        from mlflow.exceptions import MlflowException

        name = f"{self.experiment_prefix}/{dataset}"
        exp = client.get_experiment_by_name(name)
        if exp is not None:
            if exp.tags.get(EXPERIMENT_KIND[0]) is None:
                client.set_experiment_tag(exp.experiment_id, *EXPERIMENT_KIND)
            return exp.experiment_id
        location = None
        if (db := self._sqlite_db()) is not None:
            # beside the database, never relative to whichever process's working directory
            location = (db.parent / "mlartifacts" / dataset).as_uri()
        try:
            return client.create_experiment(name, artifact_location=location,
                                            tags=dict([EXPERIMENT_KIND]))
        except MlflowException:
            exp = client.get_experiment_by_name(name)
            if exp is None:
                raise
            return exp.experiment_id

    @staticmethod
    def _unmark_earlier(client, exp_id: str, run_id: str, hparams: str, method: str) -> None:
        """Tag the earlier runs of the same set and method ``latest=false`` (``run_id`` gets
        ``latest=true`` with its last tags), so that re-runs are told apart in the UI
        (filter ``tags.latest = 'true'``)."""
        earlier = client.search_runs(
            [exp_id], filter_string=f"tags.hparams = '{hparams}' and tags.method = '{method}' "
                                    f"and tags.latest = 'true'")
        for run in earlier:
            if run.info.run_id != run_id:
                client.set_tag(run.info.run_id, "latest", "false")

    @staticmethod
    def _logged_model(client, exp_id: str, method: str, fingerprint: str) -> dict | None:
        """The model tags (``model_uri``, ``model_id``, ``model_run_id``) of the latest
        finished run of ``method`` that logged or reused a model with this
        :meth:`~.mlflow_models.ModelToLog.fingerprint`, if that model is still there and
        ready (not deleted in the UI, say); else None."""
        from mlflow.entities import LoggedModelStatus
        from mlflow.exceptions import MlflowException

        runs = client.search_runs(
            [exp_id], max_results=1,
            filter_string=f"tags.method = '{method}' and attributes.status = 'FINISHED' "
                          f"and tags.model_fingerprint = '{fingerprint}'")
        tags = runs[0].data.tags if runs else {}
        if not set(MODEL_TAGS) <= tags.keys():
            return None
        try:
            status = client.get_logged_model(tags["model_id"]).status
        except MlflowException:  # deleted
            return None
        return {k: tags[k] for k in MODEL_TAGS} if status == LoggedModelStatus.READY else None

    def _log_model(self, run_id: str, registered_name: str, model: "ModelToLog",
                   logged: dict | None) -> dict:
        """Log the training table as the run's dataset, and ``model`` as its model, logged
        and registered, unless ``logged`` (the tags of :meth:`_logged_model`) names it
        already logged: then the run is linked to that model as its output. Returns the
        run's tags for its model: :data:`MODEL_TAGS`, and for a linked model a description
        (``mlflow.note.content``) that says which run logged it."""
        import mlflow
        from mlflow.entities import DatasetInput, InputTag, LoggedModelOutput
        from mlflow.utils.mlflow_tags import MLFLOW_DATASET_CONTEXT

        client = self.client()
        # as mlflow.log_input does, without making the run the active one
        client.log_inputs(run_id, datasets=[DatasetInput(
            model.training._to_mlflow_entity(),
            tags=[InputTag(MLFLOW_DATASET_CONTEXT, "training")])])
        if logged is None:
            with mlflow.start_run(run_id=run_id):  # the fluent log_model needs an active run
                info = _log_pyfunc(model, registered_name)
            return {"model_uri": info.model_uri, "model_id": info.model_id,
                    "model_run_id": run_id}
        client.log_outputs(run_id, [LoggedModelOutput(logged["model_id"], step=0)])
        return {**logged, "mlflow.note.content": _reuse_note(client, logged)}

    def run_url(self, run: "LoggedRun") -> str:
        """The link to a run in the MLflow UI (credentials never included)."""
        uri = self.uri()
        base = split_credentials(uri)[0] if uri.startswith(("http://", "https://")) \
            else self.ui_url or default_mlflow_ui_url()
        return (f"{base.rstrip('/')}/#/experiments/{run.experiment_id}/runs/{run.run_id}"
                f"{MLFLOW_TRAINING_VIEW}")

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
        model: "ModelToLog | None" = None,
        run_name: str | None = None,
    ) -> "LoggedRun":
        """Create, fill and close one run; returns its id and its experiment's.

        ``artifacts`` maps file names to dicts (written as JSON), DataFrames (as CSV), text
        or bytes (e.g. a rendered PNG; as they are), stored in one call.
        ``model`` is logged as the run's MLflow model (a pyfunc with signature and input
        example, registered as ``<prefix>.<dataset>.<method>``) and its training table as the
        run's dataset, unless a finished run of the method in the data set's experiment has
        the same model (equal :meth:`~.mlflow_models.ModelToLog.fingerprint`, e.g. a baseline
        shared by the sets of a sweep): then it is not logged or registered again, but linked
        to this run as its output, and the run's description links the run that logged it
        (on the embedded sqlite store, runs of other processes that score the same model at
        the same moment wait for each other, :meth:`_models_lock`, so one logs it).
        Either way the run is tagged ``model_uri`` (where the model is), ``model_id`` (its
        MLflow logged model), ``model_run_id`` (the run that logged it) and
        ``model_fingerprint``.
        ``run_name`` defaults to ``<method>|<hparams>``.
        """
        from mlflow.entities import Metric, Param, RunTag

        self.check_reachable()
        client = self.client()
        exp_id = self._experiment(client, dataset)
        run = client.create_run(exp_id, run_name=run_name or f"{method}|{hparams}",
                                tags={"dataset": dataset, "hparams": hparams,
                                      "method": method, **tags})
        run_id = run.info.run_id
        batch, batched = None, False
        try:
            # A diverged free run scores ±inf, which tracking stores reject: log ±1e300 (the
            # scores.csv artifact keeps the exact value).
            values = {k: float(v) for k, v in metrics.items() if v is not None}
            batch = {"metrics": [Metric(k, float(np.clip(v, -1e300, 1e300)), 0, 0)
                                 for k, v in values.items()],
                     "params": [Param(k, str(v))
                                for k, v in {"method": method, **params}.items()]}
            if artifacts:  # one call to the store for all of them
                with tempfile.TemporaryDirectory() as tmp:
                    for name, obj in artifacts.items():
                        _write_artifact(Path(tmp) / name, obj)
                    client.log_artifacts(run_id, tmp)
            fingerprint = model.fingerprint() if model is not None else None
            with self._models_lock(fingerprint):
                last = {} if model is None else {**self._log_model(
                    run_id, f"{self.experiment_prefix}.{dataset}.{method}", model,
                    self._logged_model(client, exp_id, method, fingerprint)),
                    "model_fingerprint": fingerprint}
                self._unmark_earlier(client, exp_id, run_id, hparams, method)
                # one batch (each is a round trip to the store): the metrics, parameters and
                # the tags known last (``tags`` were set when the run was created)
                batched = True
                client.log_batch(run_id, **batch, tags=[
                    RunTag(k, v) for k, v in {**last, "latest": "true"}.items()])
                client.set_terminated(run_id, "FINISHED")
        except BaseException as exc:
            # an interrupt (Ctrl-C, Dagster's termination) is a BaseException: end the run
            # as KILLED rather than leave it RUNNING forever, with the scores it has
            status = "FAILED" if isinstance(exc, Exception) else "KILLED"
            try:
                if batch is not None and not batched:
                    client.log_batch(run_id, **batch)
                client.set_terminated(run_id, status)
            except Exception as why:  # e.g. a sqlite store still locked by the write it broke
                logging.getLogger(__name__).warning(
                    f"MLflow run {run_id} could not be marked {status} ({why}); it stays "
                    f"RUNNING until `python -m pwa_pipeline doctor --repair`")
            raise  # the error or interrupt itself, never the failure to mark the run
        return LoggedRun(run_id, exp_id)


class LoggedRun(NamedTuple):
    """A run :meth:`MLflowTracker.log_run` logged (what :meth:`MLflowTracker.run_url` links
    to, without asking the store)."""

    run_id: str
    experiment_id: str


def _log_pyfunc(model: "ModelToLog", registered_name: str):
    """Log ``model`` as the active run's pyfunc model, registered as ``registered_name``;
    returns MLflow's ``ModelInfo``."""
    import mlflow
    from mlflow.models import infer_signature

    output = model.simulator.predict(None, model.input_example)
    # MLflow warns that a python_model object is stored with cloudpickle, at every log;
    # the module doc of mlflow_models says what loading needs instead
    pyfunc_log = logging.getLogger("mlflow.pyfunc")
    level = pyfunc_log.level
    pyfunc_log.setLevel(logging.ERROR)
    try:
        return mlflow.pyfunc.log_model(
            name="model", python_model=model.simulator,
            signature=infer_signature(model.input_example, output),
            input_example=model.input_example, registered_model_name=registered_name,
            # given, not inferred: inference imports and inspects the environment
            pip_requirements=[f"{name}=={version(name)}" for name in REQUIREMENTS])
    finally:
        pyfunc_log.setLevel(level)


def _write_ahead_log(db: Path) -> None:
    """Put the sqlite store ``db`` in write-ahead-log mode, as Dagster's sqlite files beside
    it are: a commit then writes the log once instead of a rollback journal and the file,
    and readers (the MLflow UI) no longer block a run's writes, nor it theirs. The mode is
    kept in the file, so MLflow's own connections and the UI's use it; the file's
    ``-wal`` and ``-shm`` companions are part of the store while a process has it open. A
    store another process is reading at that moment stays in its mode until the next
    process that readies it."""
    import sqlite3

    with contextlib.closing(sqlite3.connect(db, timeout=WAL_WAIT_SECONDS)) as conn:
        with contextlib.suppress(sqlite3.OperationalError):  # "database is locked"
            conn.execute("PRAGMA journal_mode=WAL")


def _reuse_note(client, logged: dict) -> str:
    """The description of a run that reuses the model another run logged (``logged``: the
    tags of ``MLflowTracker._logged_model``): a link to that run and how to load the model."""
    from mlflow.exceptions import MlflowException

    try:
        source = client.get_run(logged["model_run_id"]).info
        by = (f"[{source.run_name}](#/experiments/{source.experiment_id}/runs/"
              f"{source.run_id}{MLFLOW_TRAINING_VIEW})")
    except MlflowException:  # that run purged from the store, its model kept
        by = f"{logged['model_run_id']} (no longer in the store)"
    return (f"The model of this run was logged by run {by}, which scored the same fitted "
            f"model; load it with `mlflow.pyfunc.load_model(\"{logged['model_uri']}\")`.")


def _write_artifact(path: Path, obj) -> None:
    """Write an artifact of :meth:`MLflowTracker.log_run` to ``path``: bytes as they are, a
    DataFrame as CSV, text as it is, anything else as JSON."""
    if isinstance(obj, bytes):
        path.write_bytes(obj)
    elif isinstance(obj, pd.DataFrame):
        path.write_text(obj.to_csv(index=False), encoding="utf-8")
    elif isinstance(obj, str):
        path.write_text(obj, encoding="utf-8")
    else:
        path.write_text(json.dumps(obj, indent=2, default=float), encoding="utf-8")
