"""What the assets read about a fitted model and its data: the names of its regressors,
the comparison with a simulated system's ground truth, what the model is (`model_note`),
and the key its scores and figures are cached by."""

from ..datasets import Dataset, GroundTruth
from ..pwa import PWARX
from ..regressors import regressor_names
from ..scoring.truth import ground_truth_scores
from .mlflow_models import predictor_fingerprint


def phi_names(pwa: PWARX, data: Dataset) -> list[str]:
    """φ's entry names in the data's channel names, at the model's lags."""
    return regressor_names(data.y_names, data.u_names, pwa.output_lags_, pwa.nb, pwa.affine)


def ground_truth(model: PWARX, data: Dataset) -> GroundTruth | None:
    """The data set's ground truth when it is a PWARX system's and the model has its
    regressor."""
    truth = data.truth
    if truth is None or truth.thetas is None or (model.output_lags_, model.nb, model.affine) != (
            truth.na, truth.nb, truth.affine):
        return None
    return truth


def truth_metadata(model: PWARX, data: Dataset) -> dict:
    """Parameter error and region accuracy on the held-out data against the true system
    (simulated data sets), or why they are not given."""
    if data.truth is None or data.truth.thetas is None:
        return {}
    truth = ground_truth(model, data)
    if truth is None:
        t = data.truth
        return {"ground_truth": f"not comparable: the model's regressor has (output lags, nb, "
                                f"affine) = {(model.output_lags_, model.nb, model.affine)}, "
                                f"the system's {(t.na, t.nb, t.affine)}"}
    return ground_truth_scores(model, truth.thetas, data.u_test, data.y_test, truth.modes_test)


def model_note(model) -> str:
    """What a fitted model is when its method's name does not say it: the structure
    search's verdict (`SearchReport.verdict`, e.g. ``"linear kept (no switching structure
    beat it)"``) for a searched PWARX, ``""`` for any other model. The scores tables carry
    it (column ``model``) to the leaderboard."""
    report = getattr(model, "structure_search_", None)
    return "" if report is None else report.verdict


def prediction_key(model, data: Dataset) -> tuple[str, str]:
    """What the scores and figure caches key on in place of ``model`` and ``data``: the
    model's ``predictor_fingerprint`` and the data's ``Dataset.digest`` (the same
    model on edited held-out data is scored again)."""
    return predictor_fingerprint(model, data.u_names, data.y_names), data.digest
