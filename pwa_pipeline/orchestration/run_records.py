"""What one MLflow run of a method records: its parameters, metrics, tags, artifacts and
description, built in one place from the partition's configuration, the fitted model and
its evaluation (`method_run`)."""

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..config import Configuration
from ..datasets import Dataset
from ..methods import METHODS
from ..pwa import PWARX
from ..pwa.limits import all_bounds
from ..scoring.conventions import single_run_scores
from ..scoring.evaluation import Evaluation
from .model_facts import constant_text, phi_names, shown_params, truth_metadata
from .reporting import diverged_tags, model_params, score_metrics
from .tracking import RUN_COLOUR, model_description


@dataclass(frozen=True)
class MethodRun:
    """The content of one method's MLflow run (`MLflowTracker.log_run`'s arguments but the model)."""

    dataset: str
    hparams: str
    method: str
    params: dict
    metrics: dict[str, float]
    tags: dict[str, str]
    artifacts: dict[str, object]
    description: str
    fit_seconds: float


def benchmark_metric(model, data: Dataset) -> dict[str, float]:
    """A measured benchmark's own figure of merit on its held-out record
    (``benchmark/<convention>``, e.g. ``benchmark/rmse_mm_from_20``), for a data set that
    has one (`Dataset.convention`) and a free run that did not diverge (a diverged
    run has its onset among the scores instead). Prefixed, as the per-output scores, so
    that a run keeps its few unprefixed headline metrics and the chart view its few
    charts."""
    if data.convention is None:
        return {}
    score = float(np.mean(single_run_scores(model, data.u_test, data.y_test, data.convention)))
    return {f"benchmark/{data.convention.name}": score} if np.isfinite(score) else {}


def method_run(configuration: Configuration, method: str, model, evaluation: Evaluation,
               data: Dataset, *, control=None, tags: dict[str, str] | None = None
               ) -> MethodRun:
    """The run of ``method``'s fitted ``model`` scored by ``evaluation`` on ``data``.

    Parameters are the model's own (`shown_params`: every parameter, the values the
    fit chose filled in), the evaluation's warm-up and what the model says of itself under
    `model/` (`model_params`: sub-models, output groups, ε and the noise share where the
    paper's clustering ran, the ground truth's errors, the structure search's, the
    state-space export's, and whether a linear model has a constant, `constant_text`);
    metrics are the scores (`score_metrics`) and the fit's seconds, from the model
    (`timings_`); tags are the data set, set and method, `tags`, the method's colour
    in MLflow's UI (`RUN_COLOUR`) and, for a diverged free run, its scores as every page
    shows them (`diverged_tags`).

    Parameters
    ----------
    configuration : Configuration
    method : str
    model : fitted estimator
    evaluation : Evaluation
    data : Dataset
    control : ControlModel, optional
        The PWA model's state-space export and stability report, logged with it.
    tags : dict, optional
        More tags (the Dagster run, the partition).
    """
    fit_seconds = float(sum(getattr(model, "timings_", {}).values())) or float("nan")
    facts, artifacts = {}, {}
    if isinstance(model, PWARX):
        facts.update(n_submodels=model.n_submodels_, output_groups=len(model.groups_),
                     **truth_metadata(model, data))
        if held := all_bounds(model.output_limits_, [data.label(y) for y in data.y_names]):
            facts["limits"] = held
        if "clustering" in model.steps_:
            facts.update(noise_share=model.steps_["clustering"].noise_share_,
                         eps=model.steps_["clustering"].eps_)
        artifacts["parameter_matrices.json"] = {
            "regressors": phi_names(model, data), "outputs": data.y_names,
            "structures": model.structures_,
            "groups": [{"outputs": [data.y_names[j] for j in g.outputs],
                        "regions": g.n_regions, "theta": g.thetas.tolist()}
                       for g in model.groups_]}
        if (search := getattr(model, "structure_search_", None)) is not None:
            # the columns a reader compares first, numbers to 4 significant digits
            artifacts["structure_search.csv"] = _search_table(search.table)
            facts.update(search_linear=bool(search.linear),
                         search_budget_spent=bool(search.budget_spent),
                         search_time_limited=bool(search.time_limited),
                         search_candidates=search.n_candidates,
                         search_validation_nrmse=search.validation_nrmse,
                         search_linear_nrmse=search.linear_nrmse,
                         search_seconds=search.seconds)
    if control is not None:
        ss, report = control.state_space, control.stability
        facts.update(control_modes=ss.n_modes, lyapunov_certified=bool(report.certified),
                     max_spectral_radius=float(np.max(report.spectral_radius)))
        artifacts.update({f"control/{name}": text for name, text in control.files.items()})
        artifacts["control/stability.json"] = report.to_dict()
    if (constant := constant_text(model)):
        facts["constant"] = constant
    metrics = {**score_metrics(evaluation), **benchmark_metric(model, data),
               **({"fit_seconds": float(f"{fit_seconds:.4g}")} if np.isfinite(fit_seconds)
                  else {})}
    params = {**shown_params(model)[0], "warmup": configuration.warmup,
              **model_params(facts)}
    ds, hp = configuration.dataset, configuration.hparams
    return MethodRun(
        dataset=ds, hparams=hp, method=method, params=params, metrics=metrics,
        tags={**(tags or {}), **diverged_tags(evaluation),
              **({RUN_COLOUR: METHODS[method].colour} if method in METHODS else {})},
        artifacts={"scores.csv": evaluation.table, **artifacts},
        description=model_description(ds, hp, method, metrics, params),
        fit_seconds=fit_seconds)


def _search_table(table: pd.DataFrame) -> pd.DataFrame:
    """The search report's table as logged: its columns in reading order, NRMSE to 4
    significant digits."""
    return table[["stage", "outputs", "validation_nrmse", "outcome", "regions", "seconds",
                  "structure"]].assign(validation_nrmse=lambda t: t.validation_nrmse.map(
                      lambda v: float(f"{v:.4g}")))
