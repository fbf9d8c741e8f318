"""The ``mlflow`` resource: one MLflow run per method and partition materialisation."""

import errno
import functools
import json
import logging
import os
import re
import sqlite3
import tempfile
import time
import urllib.error
import urllib.request
from importlib.metadata import version
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import dagster as dg
import numpy as np
import pandas as pd

from ..scoring.evaluation import score_text
from .credentials import mask_credentials, split_credentials, user_and_password
from .paths import MLFLOW_TRAINING_VIEW, default_mlflow_ui_url, default_tracking_uri
from .reporting import MODEL

if TYPE_CHECKING:
    from .mlflow_models import ModelToLog

#: What a logged model needs to load elsewhere (pinned to the versions that logged it).
REQUIREMENTS = ("pwa-pipeline", "numpy", "scipy", "scikit-learn", "pandas")
#: Run tags that say where a run's model is (see `MLflowTracker.log_run`).
MODEL_TAGS = ("model_uri", "model_id", "model_run_id")
#: The experiment tag of MLflow 3 for classic model training (not GenAI); MLflow 3.17's UI
#: follows its own GenAI / model-training switch instead, so links add ``MLFLOW_TRAINING_VIEW``.
EXPERIMENT_KIND = ("mlflow.experimentKind", "custom_model_development")
#: The run tag MLflow's UI reads a run's colour from (and writes when a user picks one in
#: its colour picker); MLflow has no other way to set it, and otherwise colours a run by a
#: hash of its id, so that two methods' runs can share a colour. Each method's runs carry
#: the method's colour (`Method.colour`).
RUN_COLOUR = "mlflow.runColor"
#: sqlite tracking stores whose schema this process has created or checked.
_READY_STORES: set[str] = set()


class StoreProblem(NamedTuple):
    """What is wrong with a sqlite tracking store (see `store_problem`)."""

    message: str
    #: Whether ``doctor --repair`` moves it aside: a store half made, holding no run.
    half_made: bool


@functools.cache
def _schema_head() -> str:
    """The schema version (alembic revision) this MLflow creates."""
    import mlflow
    from alembic.script import ScriptDirectory

    return ScriptDirectory(str(Path(mlflow.__file__).parent / "store" / "db_migrations")
                           ).get_current_head()


def store_problem(db: Path) -> StoreProblem | None:
    """None if the sqlite tracking store ``db`` is absent or whole; else what is wrong.

    A store is half made when it cannot be read, has no schema version, or has a version that
    is not this MLflow's and holds no run (what SIGKILL during MLflow's schema creation left
    before stores were created in a temporary file). One with runs at another version is
    out of date, for ``mlflow db upgrade``, and never moved.
    """
    if not db.is_file():
        return None
    half = (f"MLflow store {db} is half made ({{}}): every run would fail on it; run "
            f"`python -m pwa_pipeline doctor --repair` to move it aside (it is kept)")
    try:
        con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
        try:
            tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master "
                                                "WHERE type = 'table'")}
            versions = ([r[0] for r in con.execute("SELECT version_num FROM alembic_version")]
                        if "alembic_version" in tables else [])
            runs = (con.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
                    if "runs" in tables else 0)
        finally:
            con.close()
    except sqlite3.Error as why:
        return StoreProblem(half.format(f"cannot be read: {why}"), True)
    if not tables:
        return None  # an empty file: MLflow creates the schema in it
    if not versions:
        return StoreProblem(half.format("no schema version"), True)
    if versions != [head := _schema_head()]:
        if runs == 0:
            return StoreProblem(half.format(f"schema version {versions} and no run"), True)
        return StoreProblem(f"MLflow store {db} has schema version {versions[0]}, not this "
                            f"MLflow's {head}: back it up, then run `mlflow db upgrade "
                            f"sqlite:///{db}`", False)
    return None


def move_store_aside(db: Path) -> Path:
    """Rename the sqlite store ``db`` to ``<db>.broken-<time>`` (never deleted); the new
    name."""
    aside = db.with_name(f"{db.name}.broken-{time.strftime('%Y%m%dT%H%M%S')}")
    os.replace(db, aside)
    return aside


def _create_store(db: Path) -> None:
    """Create the sqlite store ``db`` with MLflow's schema in a temporary file beside it and
    move it into place once complete (called under the store's file lock)."""
    from mlflow.tracking import MlflowClient

    for left in db.parent.glob(f".{db.name}.*.tmp"):  # left by a creation killed before
        left.unlink(missing_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{db.name}.", suffix=".tmp", dir=db.parent)
    os.close(fd)
    try:
        MlflowClient(tracking_uri=f"sqlite:///{tmp}").search_experiments(max_results=1)
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, db)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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
    do not race in MLflow's schema migration, and in a temporary file moved into place once
    complete, so that a kill meanwhile leaves no half-made store; a half-made one is refused
    before any run (see `store_problem`).

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
    request_timeout: int = 10
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
            if (problem := store_problem(db)) is not None:
                raise dg.Failure(description=problem.message)

    def client(self):
        """An MLflow client on the tracking URI, the store created if new (see the class doc)."""
        import mlflow
        from mlflow.tracking import MlflowClient

        uri = self.uri()
        if uri.startswith(("http://", "https://")):
            # read by MLflow at each request; process-wide, as MLflow offers no other way.
            # The credentials go to MLflow's own variables, so that no URI it puts in an
            # error message holds the password
            uri, user, password = user_and_password(uri)
            os.environ.update({
                "MLFLOW_HTTP_REQUEST_TIMEOUT": str(self.request_timeout),
                "MLFLOW_HTTP_REQUEST_MAX_RETRIES": str(self.request_retries),
                "MLFLOW_HTTP_REQUEST_BACKOFF_FACTOR": "1",
                **({} if user is None else {"MLFLOW_TRACKING_USERNAME": user}),
                **({} if password is None else {"MLFLOW_TRACKING_PASSWORD": password})})
        # Artifact repositories of a tracking server resolve through the global URI.
        mlflow.set_tracking_uri(uri)
        if (db := self._sqlite_db()) is not None and uri not in _READY_STORES:
            from filelock import FileLock

            # the client's first use of a store creates and migrates its schema: done whole
            # in a file beside it, so that a kill meanwhile leaves no half-made store
            with FileLock(f"{db}.lock"):
                if not db.exists():
                    _create_store(db)
                client = MlflowClient(tracking_uri=uri)
                client.search_experiments(max_results=1)
            _READY_STORES.add(uri)
            return client
        return MlflowClient(tracking_uri=uri)

    def _sqlite_db(self) -> Path | None:
        """The database file of an embedded sqlite store; None for a tracking server."""
        uri = self.uri()
        return Path(uri[len("sqlite:///"):]) if uri.startswith("sqlite:///") else None

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
        `fingerprint`, if that model is still there and
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
                   logged: dict | None, version_tags: dict[str, str], description: str
                   ) -> dict:
        """Log the training table as the run's dataset, and ``model`` as its model, logged
        and registered (the new version tagged with ``version_tags`` and described by
        ``description``), unless ``logged`` (the tags of `_logged_model`) names it
        already logged: then the run is linked to that model as its output. Returns the
        run's tags for its model: `MODEL_TAGS`, and for a linked model a description
        (``mlflow.note.content``) that says which run logged it."""
        import mlflow
        from mlflow.entities import LoggedModelOutput

        client = self.client()
        # the fluent log_input and log_model need an active run; this one ends later, in
        # log_run, with its status
        with mlflow.start_run(run_id=run_id):
            mlflow.log_input(model.training, context="training")
            if logged is None:
                info = _log_pyfunc(model)
                version = _register(client, registered_name, info, run_id, version_tags,
                                    description)
                _name_version(client, registered_name, version, version_tags)
                return {"model_uri": info.model_uri, "model_id": info.model_id,
                        "model_run_id": run_id}
        client.log_outputs(run_id, [LoggedModelOutput(logged["model_id"], step=0)])
        linked = client.search_model_versions(
            f"name = '{registered_name}' and run_id = '{logged['model_run_id']}'")
        if linked:  # the version the other run registered is this set's model too
            _name_version(client, registered_name, max(int(v.version) for v in linked),
                          version_tags)
        return {**logged, "mlflow.note.content": _reuse_note(client, logged)}

    def ui_base(self) -> str:
        """Where the MLflow UI of this store is served: the tracking server itself, or
        ``ui_url`` for a local store (credentials never included)."""
        uri = self.uri()
        base = split_credentials(uri)[0] if uri.startswith(("http://", "https://")) \
            else self.ui_url or default_mlflow_ui_url()
        return base.rstrip("/")

    def run_url(self, run: "LoggedRun") -> str:
        """The link to a run in the MLflow UI, in its model-training view."""
        return (f"{self.ui_base()}/#/experiments/{run.experiment_id}/runs/{run.run_id}"
                f"{MLFLOW_TRAINING_VIEW}")

    def experiment_url(self, dataset: str) -> str | None:
        """The link to the runs of ``dataset``'s experiment in the MLflow UI, in its
        model-training view (MLflow 3.17's experiment list opens an experiment in its GenAI
        overview, whatever its kind); None while the experiment does not exist."""
        exp = self.client().get_experiment_by_name(f"{self.experiment_prefix}/{dataset}")
        return None if exp is None else (f"{self.ui_base()}/#/experiments/"
                                         f"{exp.experiment_id}/runs{MLFLOW_TRAINING_VIEW}")

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
        started: float | None = None,
        description: str = "",
    ) -> "LoggedRun":
        """Create, fill and close one run; returns its id and its experiment's.

        ``artifacts`` maps file names to dicts (written as JSON), DataFrames (as CSV), text
        or bytes (e.g. a rendered PNG; as they are), stored in one call.
        ``model`` is logged as the run's MLflow model (a pyfunc with signature and input
        example, registered as ``<prefix>.<dataset>.<method>``) and its training table as the
        run's dataset, unless a finished run of the method in the data set's experiment has
        the same model (equal `fingerprint`, e.g. a baseline
        shared by the sets of a sweep): then it is not logged or registered again, but linked
        to this run as its output, and the run's description links the run that logged it
        (runs of other processes that score the same model at the same moment may each log
        it).
        Either way the version is given the alias of `hparams` (`set_alias`), the alias
        `BEST` moves to the best of the sets' versions (`point_best`), and the
        registered model gets its description and tags (`registered_model_description`); the
        run is tagged ``model_uri`` (where the model is), ``model_id`` (its
        MLflow logged model), ``model_run_id`` (the run that logged it) and
        ``model_fingerprint``.
        ``run_name`` defaults to ``<method>|<hparams>``. ``started`` (seconds since the epoch,
        default now) is the run's start, so that its duration spans the fit it scores;
        ``description`` is the run's description (Markdown, ``mlflow.note.content``), to
        which a reused model's note is added.
        """
        from mlflow.entities import Metric, Param, RunTag

        self.check_reachable()
        client = self.client()
        exp_id = self._experiment(client, dataset)
        run = client.create_run(
            exp_id, run_name=run_name or f"{method}|{hparams}",
            start_time=None if started is None else int(1000 * started),
            tags={"dataset": dataset, "hparams": hparams, "method": method, **tags,
                  **({"mlflow.note.content": description} if description else {})})
        run_id = run.info.run_id
        batch, batched = None, False
        try:
            # tracking stores reject ±inf, and NaN draws no chart: a value not finite (a
            # fit time not recorded, say) is left out
            values = {k: float(v) for k, v in metrics.items() if v is not None}
            values = {k: v for k, v in values.items() if np.isfinite(v)}
            batch = {"metrics": [Metric(k, v, 0, 0) for k, v in values.items()],
                     "params": [Param(k, str(v))
                                for k, v in {"method": method, **params}.items()]}
            if artifacts:  # one call to the store for all of them
                with tempfile.TemporaryDirectory() as tmp:
                    for name, obj in artifacts.items():
                        _write_artifact(Path(tmp) / name, obj)
                    client.log_artifacts(run_id, tmp)
            fingerprint = model.fingerprint() if model is not None else None
            # (the run's colour in MLflow's UI is the run's, not a fact of the version)
            version_tags = {"dataset": dataset, "hparams": hparams, "method": method,
                            "mlflow_run_id": run_id,
                            **{k: v for k, v in tags.items() if k != RUN_COLOUR}}
            last = {} if model is None else {**self._log_model(
                run_id, f"{self.experiment_prefix}.{dataset}.{method}", model,
                self._logged_model(client, exp_id, method, fingerprint), version_tags,
                model_description(dataset, hparams, method, values, params)),
                "model_fingerprint": fingerprint}
            if "mlflow.note.content" in last and description:
                last["mlflow.note.content"] = f"{description}\n\n{last['mlflow.note.content']}"
            self._unmark_earlier(client, exp_id, run_id, hparams, method)
            # one batch: the metrics, parameters and the tags known last (``tags`` were set
            # when the run was created)
            batched = True
            client.log_batch(run_id, **batch, tags=[
                RunTag(k, v) for k, v in {**last, "latest": "true"}.items()])
            if model is not None:  # (its score is logged now)
                point_best(client, f"{self.experiment_prefix}.{dataset}.{method}")
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
            if (full := _disk_full(exc)) is not None:  # said with the store it names
                raise dg.Failure(description=(
                    f"MLflow store {mask_credentials(self.uri())} could not be written: "
                    f"{full}; free space on its disk, then materialise the partition again "
                    f"(its assets already stored are kept)")) from exc
            raise  # the error or interrupt itself, never the failure to mark the run
        return LoggedRun(run_id, exp_id)


def _disk_full(exc: BaseException) -> str | None:
    """What ``exc`` says, when it says that the disk is full: an OSError ENOSPC (or over
    quota), or sqlite's `database or disk is full` / `disk I/O error`, which name no file;
    None for any other error."""
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return exc.strerror or "no space left on device"
    return next((reason for reason in ("database or disk is full", "disk I/O error")
                 if reason in str(exc)), None)


class LoggedRun(NamedTuple):
    """A run `MLflowTracker.log_run` logged (what `MLflowTracker.run_url` links
    to, without asking the store)."""

    run_id: str
    experiment_id: str


def model_description(dataset: str, hparams: str, method: str, metrics: dict[str, float],
                      params: dict | None = None) -> str:
    """What a run scored, and its registered model version: the model, what it was fitted
    on, its headline scores on the held-out experiments (``metrics``, named as
    `score_metrics` names them; the mean over the outputs, to 4 significant digits, where
    MLflow's UI may show 2 decimals; a diverged free run as `score_text` shows it,
    with where it diverged), and from its parameters (`params`, `MODEL` facts) a PWA
    model's sub-models and output limits and whether a linear ARX model has a
    constant."""
    params = params or {}
    parts = [f"The {method} model of data set {dataset}, hyper-parameter set {hparams}."]
    shown = [f"{label} {name} {metrics[key]:.4g}" for label, name, key in (
        ("one-step", "NRMSE", "one_step_nrmse"), ("free-run", "NRMSE", "free_run_nrmse"),
        ("free-run", "R²", "free_run_r2")) if key in metrics]
    if metrics.get("free_run_diverged"):
        shown.append(f"free-run NRMSE {score_text(np.nan, 'nrmse', diverged=True)} from "
                     f"sample {int(metrics['free_run_divergence_sample'])} of held-out "
                     f"experiment {int(metrics['free_run_divergence_experiment'])}")
    if shown:
        parts.append("Held-out " + ", ".join(shown) + " (mean over the outputs).")
    if f"{MODEL}n_submodels" in params:
        parts.append(f"{params[f'{MODEL}n_submodels']} sub-model(s).")
    if limits := params.get(f"{MODEL}limits"):
        parts.append(f"Outputs held at their limits where they reach them: {limits}.")
    if constant := params.get(f"{MODEL}constant"):
        parts.append(f"{constant[0].upper()}{constant[1:]}.")
    if "fit_seconds" in metrics:
        parts.append(f"Fitted in {metrics['fit_seconds']:.3g} s.")
    return " ".join(parts)


#: The registered model alias of the best version across sets (`point_best`).
BEST = "best"


def set_alias(hparams: str) -> str:
    """The registered model alias of hyper-parameter set ``hparams``: its name, or
    ``set-<name>`` for a name MLflow reserves (``latest``, and ``v<digits>``, which name
    versions) or this module gives another meaning (`BEST`). Set names are letters,
    digits, `_` and `-`, which aliases allow."""
    reserved = hparams.lower() in ("latest", BEST) or re.fullmatch(r"[vV]\d+", hparams)
    return f"set-{hparams}" if reserved else hparams


def point_best(client, registered_name: str) -> None:
    """Point the alias `BEST` at the version, among those a set's alias points at, whose
    run scored the lowest free-run NRMSE (the headline score; a diverged run logs none and
    is never best, nor one whose run is gone from the store); the lowest version number
    among equals. No alias while no version has a score."""
    from mlflow.exceptions import MlflowException

    scores = {}
    for alias, number in client.get_registered_model(registered_name).aliases.items():
        if alias != BEST:
            run_id = client.get_model_version(registered_name, str(number)).run_id
            try:
                score = client.get_run(run_id).data.metrics.get("free_run_nrmse")
            except MlflowException:  # (purged by `mlflow gc`: its score is not known)
                continue
            if score is not None and np.isfinite(score):
                scores[int(number)] = score
    if scores:
        best = min(sorted(scores), key=scores.get)
        client.set_registered_model_alias(registered_name, BEST, str(best))


def registered_model_description(dataset: str, method: str, registered_name: str) -> str:
    """The registered model's own description: what it is and how to load one set's."""
    return (f"The {method} model of data set {dataset}, one version per fit by pwa-pipeline. "
            f"Each hyper-parameter set's newest version has the set's name as its alias: "
            f"load it as `models:/{registered_name}@<set>` (e.g. "
            f"`models:/{registered_name}@default`); `{BEST}` is the version of lowest "
            f"held-out free-run NRMSE across the sets; `latest` is whichever set ran last.")


def _name_version(client, registered_name: str, version, version_tags: dict[str, str]
                  ) -> None:
    """Point the alias of the version's set (`set_alias`) at ``version``, and give the
    registered model its description and its ``dataset`` and ``method`` tags."""
    dataset, method = version_tags["dataset"], version_tags["method"]
    client.set_registered_model_alias(registered_name, set_alias(version_tags["hparams"]),
                                      str(version))
    client.update_registered_model(
        registered_name,
        description=registered_model_description(dataset, method, registered_name))
    for key, value in (("dataset", dataset), ("method", method)):
        client.set_registered_model_tag(registered_name, key, value)


def _register(client, registered_name: str, info, run_id: str, version_tags: dict[str, str],
              description: str) -> str:
    """Register the logged model ``info`` (MLflow's ``ModelInfo``) of run ``run_id`` as a
    new version of ``registered_name`` (created if need be), tagged with ``version_tags`` and
    described by ``description``; returns the version. Through the client, which prints
    nothing: the fluent registration prints "Successfully registered model" or "already
    exists" to stderr at every run."""
    from mlflow.exceptions import MlflowException

    try:
        client.create_registered_model(registered_name)
    except MlflowException as exc:
        if exc.error_code not in ("RESOURCE_ALREADY_EXISTS", "ALREADY_EXISTS"):
            raise
    return client.create_model_version(
        registered_name, source=info.model_uri, run_id=run_id, tags=version_tags,
        description=description, model_id=info.model_id).version


def _log_pyfunc(model: "ModelToLog"):
    """Log ``model`` as the active run's pyfunc model; returns MLflow's ``ModelInfo``."""
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
            input_example=model.input_example,
            # given, not inferred: inference imports and inspects the environment
            pip_requirements=[f"{name}=={version(name)}" for name in REQUIREMENTS])
    finally:
        pyfunc_log.setLevel(level)


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
            f"model; load it with `mlflow.pyfunc.load_model(\"{logged['model_uri']}\")` "
            f"(a cloudpickle: loading it runs code, so only from a store you trust).")


def _write_artifact(path: Path, obj) -> None:
    """Write an artifact of `MLflowTracker.log_run` to ``path``: bytes as they are, a
    DataFrame as CSV, text as it is, anything else as JSON (``path`` may be in a
    subfolder, e.g. ``control/...``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(obj, bytes):
        path.write_bytes(obj)
    elif isinstance(obj, pd.DataFrame):
        path.write_text(obj.to_csv(index=False), encoding="utf-8")
    elif isinstance(obj, str):
        path.write_text(obj, encoding="utf-8")
    else:
        path.write_text(json.dumps(obj, indent=2, default=float), encoding="utf-8")
