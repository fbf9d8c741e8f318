"""Fitted models as MLflow models: a pyfunc that simulates the model's outputs.

``mlflow.pyfunc.load_model("models:/<prefix>.<dataset>.<method>/latest")`` in any process
with pwa-pipeline installed gives back the simulator of a logged run. Its input is a table
with the model's input columns and output columns; the outputs are given on the leading
warm-up rows (at least what the model needs, e.g. max(na, nb)) and empty (NaN) after. Its
output is the table of output columns: the warm-up rows as given, then the free-run
simulation (the same numbers as the model's ``simulate``). The logged PWARX keeps what
simulation needs (θ_i, the regions, the orders); the record of its fit (local models,
clusters, step 5, the rows' labels) stays in the ``pwa_model`` asset.
"""

import copy
import threading
from collections import OrderedDict
from dataclasses import dataclass

import joblib
import mlflow.pyfunc
import numpy as np
import pandas as pd
from pandas.api.types import is_numeric_dtype

from ..datasets import Dataset
from .reporting import training_table

_SCHEMA_ROWS = 100
"""Rows of the training table from which its MLflow schema is inferred."""


class Simulator(mlflow.pyfunc.PythonModel):
    """A fitted PWARX, LinearARX or SubspaceSS as an MLflow pyfunc (see the module doc).

    Parameters
    ----------
    model : fitted estimator with ``simulate(u, y_init)``
    u_names, y_names : list of str
        The input and output column names.
    """

    def __init__(self, model, u_names: list[str], y_names: list[str]):
        self.model = model
        self.u_names = list(u_names)
        self.y_names = list(y_names)

    def __getstate__(self) -> dict:
        """The state MLflow pickles: the model without the record of its fit
        (:attr:`PWARX.FIT_RECORD <pwa_pipeline.pwa.PWARX.FIT_RECORD>`; the robot's paper
        setting: 69 MB of local models)."""
        model = copy.copy(self.model)
        for name in getattr(model, "FIT_RECORD", ()):
            model.__dict__.pop(name, None)
        return {**self.__dict__, "model": model}

    def predict(self, context, model_input: pd.DataFrame, params=None) -> pd.DataFrame:
        """Simulate from the warm-up rows of ``model_input``.

        Raises
        ------
        ValueError
            If a column is missing or no leading row gives every output.
        """
        missing = [c for c in self.u_names + self.y_names if c not in model_input.columns]
        if missing:
            raise ValueError(f"input table lacks column(s) {missing}; it needs "
                             f"{self.u_names + self.y_names}")
        y = model_input[self.y_names].to_numpy(float)
        given = ~np.isnan(y).any(axis=1)
        warmup = int(np.argmin(given)) if not given.all() else len(given)
        if warmup == 0:
            raise ValueError("no warm-up: give every output on the first rows of the table")
        u = model_input[self.u_names].to_numpy(float)
        simulated = self.model.simulate(u, y[:warmup])
        return pd.DataFrame(simulated, columns=self.y_names, index=model_input.index)


def predictor_fingerprint(model, u_names: list[str], y_names: list[str]) -> str:
    """Hash of what a fitted model predicts with and of its column names: equal fingerprints
    simulate alike.

    For a PWARX, its :meth:`~pwa_pipeline.pwa.PWARX.prediction_state` (θ_i, regions, orders;
    not the record of the fit nor the unfitted steps, so that sets of a sweep that end in
    the same model share one); for another model, all its attributes.
    """
    state = model.prediction_state() if hasattr(model, "prediction_state") else vars(model)
    return joblib.hash([type(model).__qualname__, state, list(u_names), list(y_names)])


def example_table(u: np.ndarray, y: np.ndarray, u_names: list[str], y_names: list[str],
                  warmup: int, rows: int = 40) -> pd.DataFrame:
    """An input table for :class:`Simulator`: ``rows`` samples, outputs given on ``warmup``."""
    y = y[:rows].copy()
    y[warmup:] = np.nan
    return pd.concat([pd.DataFrame(u[:rows], columns=u_names),
                      pd.DataFrame(y, columns=y_names)], axis=1)


@dataclass(frozen=True)
class ModelToLog:
    """What :meth:`~pwa_pipeline.orchestration.resources.MLflowTracker.log_run` logs as the
    run's model: the simulator, an input example (for the signature), and the training
    data as an MLflow dataset (:func:`training_dataset`), logged as the run's dataset."""

    simulator: Simulator
    input_example: pd.DataFrame
    training: "mlflow.data.pandas_dataset.PandasDataset"

    def fingerprint(self) -> str:
        """:func:`predictor_fingerprint` of the simulator's model and columns, so that a
        model is logged once however many runs score it."""
        sim = self.simulator
        return predictor_fingerprint(sim.model, sim.u_names, sim.y_names)


def table_dataset(table: pd.DataFrame) -> "mlflow.data.pandas_dataset.PandasDataset":
    """A training table as an MLflow dataset named ``training``, its schema taken from the
    first rows.

    MLflow infers a dataset's schema by testing every cell for a missing value (1.3 s a run
    on the robot's 40k × 13 table); the table has no missing value (the data are validated
    finite) and one type per column, so its first rows give the same schema. Its digest is
    :func:`pandas_digest`'s, MLflow's without testing numeric cells.
    """
    from mlflow.data import from_pandas
    from mlflow.models import infer_signature

    data = from_pandas(table, name="training", digest=pandas_digest(table))
    data.__dict__["schema"] = infer_signature(table.head(_SCHEMA_ROWS)).inputs
    return data


_TRAINING_DATASETS: OrderedDict[str, "mlflow.data.pandas_dataset.PandasDataset"] = OrderedDict()
_KEPT_DATASETS = 4
_DATASETS_LOCK = threading.Lock()


def training_dataset(data: Dataset) -> "mlflow.data.pandas_dataset.PandasDataset":
    """:func:`table_dataset` of ``data``'s :func:`~.reporting.training_table`, built once per
    :attr:`~pwa_pipeline.datasets.Dataset.digest` in a process (the ``_KEPT_DATASETS`` most
    recently used are kept): the three runs of every set of a sweep log the same one,
    neither stacking the experiments nor hashing the table again."""
    with _DATASETS_LOCK:
        kept = _TRAINING_DATASETS.pop(data.digest, None)
    if kept is None:
        kept = table_dataset(training_table(data))
    with _DATASETS_LOCK:
        _TRAINING_DATASETS[data.digest] = kept  # most recently used last
        while len(_TRAINING_DATASETS) > _KEPT_DATASETS:
            _TRAINING_DATASETS.popitem(last=False)
    return kept


def pandas_digest(table: pd.DataFrame) -> str:
    """MLflow's digest of a table (``mlflow.data.digest_utils.compute_pandas_digest``: its
    first rows' text and numeric columns hashed with its length and column names), without
    the type test of every cell of the numeric columns, which hold no text (on the robot's
    40k × 13 training table, most of the time MLflow's digest takes).
    """
    from mlflow.data.digest_utils import MAX_ROWS, get_normalized_md5_digest

    text = table.columns[[not is_numeric_dtype(table[c]) and bool(table[c].map(type).eq(str).all())
                          for c in table.columns]]
    head = table.head(MAX_ROWS)
    head = head[text.union(head.select_dtypes(include=[np.number]).columns)]
    return get_normalized_md5_digest([pd.util.hash_pandas_object(head).values,
                                      np.int64(len(table))]
                                     + [str(c).encode() for c in table.columns])
