"""What the assets read about a fitted model and its data: the names of its regressors,
the comparison with a simulated system's ground truth, what the model is (`model_note`),
and the key its scores and figures are cached by."""

from dataclasses import replace

from ..baselines.linear import LinearARX
from ..datasets import Dataset, GroundTruth
from ..pwa import PWARX
from ..pwa.limits import all_bounds
from ..regressors import regressor_names
from ..scoring.truth import embedded_thetas, ground_truth_scores
from .mlflow_models import predictor_fingerprint


def phi_names(pwa: PWARX, data: Dataset) -> list[str]:
    """φ's entry names in the data's channel names, at the model's lags."""
    return regressor_names(data.y_names, data.u_names, pwa.output_lags_, pwa.nb, pwa.affine)


def ground_truth(model: PWARX, data: Dataset) -> GroundTruth | None:
    """The data set's ground truth when it is a PWARX system's and the model's regressor
    holds the system's (its parameter matrices written over the model's regressor,
    `embedded_thetas`: a structure search's φ has na + 1 lags and a constant)."""
    truth = data.truth
    if truth is None or truth.thetas is None:
        return None
    lags = (model.output_lags_, model.nb, model.affine)
    if lags == (truth.na, truth.nb, truth.affine):
        return truth
    thetas = embedded_thetas(truth.thetas, len(data.y_names), len(data.u_names), truth.na,
                             truth.nb, truth.affine, *lags)
    return None if thetas is None else replace(truth, thetas=thetas, na=lags[0], nb=lags[1],
                                               affine=lags[2])


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
                                f"which lacks entries of the system's {(t.na, t.nb, t.affine)}"}
    return ground_truth_scores(model, truth.thetas, data.u_test, data.y_test, truth.modes_test)


def shown_params(model) -> tuple[dict, str]:
    """A fitted model's parameters as its page and its MLflow run show them, and what was
    left out: `resolved_params()` without the paper's steps (local models, clustering,
    sub-models, regions) when none of them ran (a structure search that kept no
    clustered regions): the values those steps choose from the data (n_ρ, ε, MinPts)
    were never chosen, and would show as None. The note says why they are missing, and,
    for a searched model, that its ``na``, ``nb``, ``form`` and ``outputs`` are bounds or
    unused (the structures hold what it chose); `""` for any other model."""
    params = model.resolved_params()
    if not isinstance(model, PWARX) or model.search is None:
        return params, ""
    searched = ("The structure search chose the model: na and nb are the largest orders it "
                "tried, form and outputs were not used, and structure_y1, structure_y2, … "
                "give each output's form, orders and regions.")
    if any(g.steps for g in model.groups_):
        return params, searched
    steps = tuple(model.step_objects())
    kept = {k: v for k, v in params.items() if k.split("__")[0] not in steps}
    return kept, (f"The paper's steps ({', '.join(steps)}) did not run: the structure search "
                  f"kept no clustered regions, so their parameters (n_rho, eps and min_pts "
                  f"among them, which those steps choose from the data) do not apply and "
                  f"are left out. {searched}")


def constant_text(model) -> str:
    """Whether a linear ARX model has a constant term (`affine`), in words: sets differ
    (the `auto` set's baseline has one, `default`'s none), and a comparison with the model
    without it is a comparison with the weaker one. `""` for any other model."""
    if not isinstance(model, LinearARX):
        return ""
    return "affine: with a constant term" if model.affine else "no constant term"


def model_note(model) -> str:
    """What a fitted model is when its method's name does not say it: the structure
    search's verdict (`SearchReport.verdict`, e.g. `"linear kept (no switching structure
    beat it)"`) for a searched PWARX, whether a linear ARX model has a constant
    (`constant_text`), `""` for any other model; then the outputs a PWARX holds at their
    limits (``"outputs held at their limits (y1 ≤ 10)"``, named as its structures name
    them), which its free run and its scores depend on. The scores tables carry it (column
    `model`) to the leaderboard."""
    report = getattr(model, "structure_search_", None)
    note = constant_text(model) if report is None else report.verdict
    held = held_outputs(model)
    return "; ".join(filter(None, (note, held and f"outputs held at their limits ({held})")))


def model_names(data: Dataset) -> str:
    """The data's channels under the names the model's structures and limits use
    (``"y1 = q1 [deg], …, u1 = tau1 [N·m], …"``: the estimator knows its outputs and inputs
    by position); empty when the data's names are those already."""
    pairs = [(f"y{j + 1}", name) for j, name in enumerate(data.y_names)]
    pairs += [(f"u{q + 1}", name) for q, name in enumerate(data.u_names)]
    if all(own == name for own, name in pairs):
        return ""
    return ", ".join(f"{own} = {data.label(name)}" for own, name in pairs)


def held_outputs(model) -> str:
    """A PWARX's output limits in words, its outputs named as its structures name them
    (``"y1 ≤ 10"``); empty for a model without any."""
    return all_bounds(getattr(model, "output_limits_", None),
                      [f"y{j + 1}" for j in range(getattr(model, "n_outputs_", 0))])


def prediction_key(model, data: Dataset) -> tuple[str, str]:
    """What the scores and figure caches key on in place of ``model`` and ``data``: the
    model's ``predictor_fingerprint`` and the data's ``Dataset.digest`` (the same
    model on edited held-out data is scored again)."""
    return predictor_fingerprint(model, data.u_names, data.y_names), data.digest
