"""What the assets read about a fitted model and its data: the names of its regressors,
the comparison with a simulated system's ground truth, the key its scores and figures are
cached by, and metadata of an earlier materialisation."""


import dagster as dg

from ...datasets import Dataset
from ...datasets.registry import GroundTruth
from ...pwa import PWARX
from ...regressors import regressor_names
from ...scoring.truth import ground_truth_scores
from ..figures import context_title
from ..mlflow_models import (
    predictor_fingerprint,
)
from ..partitions import split_key


def phi_names(pwa: PWARX, data: Dataset) -> list[str]:
    return regressor_names(data.y_names, data.u_names, pwa.na, pwa.nb, pwa.affine)


def ground_truth(model: PWARX, data: Dataset) -> GroundTruth | None:
    """The data set's ground truth when it has one and the model has its structure."""
    truth = data.truth
    if truth is None or model.structured or (model.na, model.nb, model.affine) != (
            truth.na, truth.nb, truth.affine):
        return None
    return truth


def truth_metadata(model: PWARX, data: Dataset) -> dict:
    """Parameter error and region accuracy on the held-out data against the true system
    (simulated data sets), or why they are not given."""
    if data.truth is None:
        return {}
    truth = ground_truth(model, data)
    if truth is None:
        t = data.truth
        if model.structured:
            return {"ground_truth": "not comparable: the model has a structure of its own "
                                    "(form, outputs or scheduling)"}
        return {"ground_truth": f"not comparable: the model's (na, nb, affine) = "
                                f"{(model.na, model.nb, model.affine)}, the system's "
                                f"{(t.na, t.nb, t.affine)}"}
    return ground_truth_scores(model, truth.thetas, data.u_test, data.y_test, truth.modes_test)


def figure_context(partition_key: str, method: str) -> str:
    """The first line of a figure's title for the partition ``dataset|hparams`` and the
    method labelled ``method`` (``pwa_pipeline.orchestration.figures.context_title``):
    drawn by each set itself, never taken from a cache that sets share."""
    dataset, hparams = split_key(partition_key)
    return context_title(dataset, hparams, method)


def prediction_key(model, data: Dataset) -> tuple[str, str]:
    """What the scores and figure caches key on in place of ``model`` and ``data``: the
    model's ``predictor_fingerprint`` and the data's ``Dataset.digest`` (the same
    model on edited held-out data is scored again)."""
    return predictor_fingerprint(model, data.u_names, data.y_names), data.digest


def latest_metadata(context: dg.AssetExecutionContext, asset: str, key: str) -> float:
    """``key`` of the latest materialisation of ``asset`` for this partition (NaN if none)."""
    result = context.instance.fetch_materializations(
        dg.AssetRecordsFilter(asset_key=dg.AssetKey(asset),
                              asset_partitions=[context.partition_key]), limit=1)
    if not result.records:
        return float("nan")
    value = result.records[0].asset_materialization.metadata.get(key)
    return float("nan") if value is None else float(value.value)
