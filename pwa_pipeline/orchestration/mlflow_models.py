"""Fitted models as MLflow models: a pyfunc that simulates the model's outputs.

``mlflow.pyfunc.load_model("models:/<prefix>.<dataset>.<method>@<set>")`` in any process
with pwa-pipeline installed gives back the simulator of a logged run: the newest model of
hyper-parameter set ``<set>``, whose name is the alias of that version. Its input is a table
with the model's input columns and output columns; the outputs are given on the leading
warm-up rows (at least what the model needs, e.g. max(na, nb)) and empty (NaN) after. Its
output is the table of output columns: the warm-up rows as given, then the free-run
simulation (the same numbers as the model's ``simulate``). The logged model keeps what
simulation needs (its output groups' regions and sub-models, the orders); the record of its
fit (the fitted steps, the structure search's report) stays in the ``pwa_model`` asset.

The simulator is stored by MLflow with cloudpickle (``python_model.pkl``), unsigned: loading
it runs code, so only load models from stores you trust (``docs/guarantees.md``, "Loading a
registered MLflow model").
"""

import copy
from dataclasses import dataclass, replace

import joblib
import mlflow.pyfunc
import numpy as np
import pandas as pd

from ..datasets import Dataset
from .reporting import training_table


class Simulator(mlflow.pyfunc.PythonModel):
    """A fitted PWARX, LinearARX or SubspaceSS as an MLflow pyfunc (see the module doc).

    Parameters
    ----------
    model : fitted estimator with simulate(u, y_init)
    u_names, y_names : list of str
        The input and output column names.
    """

    def __init__(self, model, u_names: list[str], y_names: list[str]):
        self.model = model
        self.u_names = list(u_names)
        self.y_names = list(y_names)

    def __getstate__(self) -> dict:
        """The state MLflow pickles: the model without the record of its fit (the output
        groups' fitted steps, the structured fit and the search's report; the robot's
        paper setting: 69 MB of local models)."""
        return {**self.__dict__, "model": without_fit_record(self.model)}

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


def without_fit_record(model):
    """A copy of a fitted model that predicts, simulates and exports alike, without the
    record of its fit: an ARX model's output groups without their fitted steps, and no
    ``structure_fit_``, ``structure_search_`` or ``timings_`` (documented as the fit's
    record); another model as it is."""
    lean = copy.copy(model)
    if hasattr(model, "groups_"):
        lean.groups_ = [replace(g, steps={}) for g in model.groups_]
    for name in ("structure_fit_", "structure_search_", "timings_"):
        lean.__dict__.pop(name, None)
    return lean


def predictor_fingerprint(model, u_names: list[str], y_names: list[str]) -> str:
    """Hash of what a fitted model predicts with and of its column names: equal fingerprints
    simulate alike.

    For an ARX model, its output groups (regions and sub-models), lags, widths and training
    range, not the record of the fit nor the unfitted steps, so that sets of a sweep that end
    in the same model share one; for another model, its attributes but the fit's timings.
    """
    if hasattr(model, "groups_"):
        state = [[(g.outputs, g.regions, g.thetas) for g in model.groups_],
                 model.output_lags_, model.nb, model.affine, model.n_inputs_,
                 model.n_outputs_, model.signal_range_]
    else:
        state = {k: v for k, v in vars(model).items() if k != "timings_"}
    return joblib.hash([type(model).__qualname__, state, list(u_names), list(y_names)])


def example_table(u: np.ndarray, y: np.ndarray, u_names: list[str], y_names: list[str],
                  warmup: int, rows: int = 40) -> pd.DataFrame:
    """An input table for `Simulator`: ``rows`` samples, outputs given on ``warmup``."""
    y = y[:rows].copy()
    y[warmup:] = np.nan
    return pd.concat([pd.DataFrame(u[:rows], columns=u_names),
                      pd.DataFrame(y, columns=y_names)], axis=1)


@dataclass(frozen=True)
class ModelToLog:
    """What `log_run` logs as the
    run's model: the simulator, an input example (for the signature), and the training
    data as an MLflow dataset (`training_dataset`), logged as the run's dataset."""

    simulator: Simulator
    input_example: pd.DataFrame
    training: "mlflow.data.pandas_dataset.PandasDataset"

    def fingerprint(self) -> str:
        """`predictor_fingerprint` of the simulator's model and columns, so that a
        model is logged once however many runs score it."""
        sim = self.simulator
        return predictor_fingerprint(sim.model, sim.u_names, sim.y_names)


def training_dataset(data: Dataset) -> "mlflow.data.pandas_dataset.PandasDataset":
    """``data``'s `training_table` as an MLflow dataset named ``training``,
    digested by `digest` (a hash of every sample, where
    MLflow's own digest reads the first rows only)."""
    from mlflow.data import from_pandas

    return from_pandas(training_table(data), name="training", digest=data.digest[:20])
