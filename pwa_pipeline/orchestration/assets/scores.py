"""Each fitted model scored on held-out data (one MLflow run each), and the methods side
by side."""

import time

import dagster as dg
import numpy as np
import pandas as pd

from ...config import Configuration
from ...datasets import Dataset
from ...methods import METHODS, Method
from ...plotting import PredictionDisplay, context_title
from ...pwa import PWARX
from ...scoring.comparison import mean_scores
from ...scoring.evaluation import Evaluation, evaluate
from ..caches import SignedMemory
from ..checks import (
    COMPARISON_CHECKS,
    comparison_results,
)
from ..images import png_markdown, to_png
from ..mlflow_models import (
    ModelToLog,
    Simulator,
    example_table,
    training_dataset,
)
from ..partitions import split_key
from ..reporting import (
    markdown,
    model_metrics,
    nrmse_summary,
    rounded,
    score_metrics,
)
from ..settings import PipelineSettings
from ..tracking import MLflowTracker, model_description
from .control import ControlModel
from .model_facts import phi_names, prediction_key, truth_metadata


def scored(model, data: Dataset, warmup: int, key: tuple[str, str]) -> Evaluation:
    """``model`` scored on ``data``'s held-out experiments by the evaluation protocol: what
    the scores assets cache (``cache_scores``), keyed by ``key`` (``prediction_key``) in
    place of the model and the data. Numbers only: the prediction figure is drawn from them
    by each set, with its own title and the data's units, which a shared entry could not
    hold (the sets sharing it differ in name, and units are not in the data's digest)."""
    return evaluate(model, data.u_test, data.y_test, warmup=warmup, output_names=data.y_names)


def scores_asset(method: Method, partitions_def):
    # the PWA run also logs the state-space model (beside the registered model it exports)
    control_in = {"control_model": dg.AssetIn("control_model")} if method.name == "pwa" else {}
    @dg.asset(name=f"{method.name}_scores", partitions_def=partitions_def, group_name="scores",
              kinds={"pandas", "mlflow"}, ins={"model": dg.AssetIn(f"{method.name}_model"),
                                                **control_in},
              description=f"The {method.label} model scored on held-out data by the "
                          f"evaluation protocol (one-step and free run), tracked in MLflow; "
                          f"the scores cached by what the model predicts with "
                          f"(``cache_scores``), the same for every set whose model predicts "
                          f"alike. Its page shows the *prediction* figure: measured output, "
                          f"one-step prediction and free run of the first held-out "
                          f"experiment, per output in the data's units, titled with the data "
                          f"set, set and method.")
    def scores(context: dg.AssetExecutionContext, mlflow: MLflowTracker,
               settings: PipelineSettings, configuration: Configuration,
               raw_benchmark: Dataset, model, **control: ControlModel | None
               ) -> pd.DataFrame:
        began = time.time()
        data = raw_benchmark
        dataset, hparams = split_key(context.partition_key)
        # the scores are cached (shared by the sets whose models predict alike), the figure
        # drawn from them for this partition: its set in the title, the data's units
        memory = SignedMemory(settings.cache_root(), "scores", warn=context.log.warning)
        score = memory.cache(scored, ignore=["model", "data"]) if settings.cache_scores \
            else scored
        ev = score(model, data, configuration.warmup, prediction_key(model, data))
        figure = PredictionDisplay.from_evaluation(
            ev, data, configuration.warmup, context=context_title(dataset, hparams, method.label)).figure_
        png = to_png(figure)
        context.log.info(f"{method.label}: one-step NRMSE {ev.mean('one_step'):.4g}, free run "
                         f"{ev.mean('free_run'):.4g}{' (diverged)' if ev.diverged() else ''}")
        fit_seconds = float(sum(getattr(model, "timings_", {}).values())) or float("nan")
        facts, artifacts = {}, {}
        if isinstance(model, PWARX):
            steps = next((g.steps for g in model.groups_ if g.steps), {})
            facts.update(n_submodels=model.n_submodels_, output_groups=len(model.groups_),
                         **truth_metadata(model, data))
            if "clustering" in steps:
                facts.update(noise_share=steps["clustering"].noise_share_,
                             eps=steps["clustering"].eps_)
            names = phi_names(model, data)
            artifacts["parameter_matrices.json"] = {
                "regressors": names, "outputs": data.y_names,
                "structures": model.structures_,
                "groups": [{"outputs": [data.y_names[j] for j in g.outputs],
                            "regions": g.n_regions, "theta": g.thetas.tolist()}
                           for g in model.groups_]}
            if (search := getattr(model, "structure_search_", None)) is not None:
                # the columns a reader compares first, numbers to 4 significant digits
                artifacts["structure_search.csv"] = search.table[
                    ["stage", "outputs", "validation_nrmse", "outcome", "regions", "seconds",
                     "structure"]].assign(validation_nrmse=lambda t: t.validation_nrmse.map(
                         lambda v: float(f"{v:.4g}")))
                facts.update(search_linear=float(search.linear),
                             search_time_limited=float(search.time_limited),
                             search_validation_nrmse=search.validation_nrmse,
                             search_linear_nrmse=search.linear_nrmse,
                             search_seconds=search.seconds)
        if (exported := control.get("control_model")) is not None:
            ss, report = exported.state_space, exported.stability
            facts.update(control_modes=ss.n_modes, lyapunov_certified=float(report.certified),
                         max_spectral_radius=float(np.max(report.spectral_radius)))
            artifacts.update({f"control/{name}": text for name, text in exported.files.items()})
            artifacts["control/stability.json"] = report.to_dict()
        metrics = {**score_metrics(ev), **model_metrics(facts),
                   **model_metrics({"fit_seconds": fit_seconds}, prefix="")}
        params = {k: v for k, v in {**configuration.params(method.name),
                                    **model.resolved_params()}.items()
                  if k not in ("dataset", "hparams")}  # (tags of the run)
        t0 = time.perf_counter()
        run = mlflow.log_run(
            dataset=dataset, hparams=hparams, method=method.name, params=params,
            metrics=metrics, description=model_description(dataset, hparams, method.name,
                                                           metrics),
            # the run spans the fit it scores (when the fit time was recorded)
            started=began - (0.0 if np.isnan(fit_seconds) else fit_seconds),
            tags={"dagster_run_id": context.run.run_id, "partition": str(context.partition_key)},
            artifacts={"scores.csv": ev.table, "prediction.png": png, **artifacts},
            model=ModelToLog(
                simulator=Simulator(model, data.u_names, data.y_names),
                input_example=example_table(data.u_test[0], data.y_test[0], data.u_names,
                                            data.y_names, configuration.warmup),
                training=training_dataset(data)))
        log_seconds = time.perf_counter() - t0
        context.add_output_metadata(rounded({
            "prediction": dg.MetadataValue.md(png_markdown(png, figure.get_suptitle())),
            "scores_from_cache": memory.hits > 0,
            "mlflow_run_id": run.run_id, "mlflow_run": dg.MetadataValue.url(mlflow.run_url(run)),
            "mlflow_log_seconds": log_seconds,
            "free_run_diverged": ev.diverged(), **nrmse_summary(ev.table)}))
        return ev.table

    return scores


def comparison_asset(partitions_def):
    @dg.asset(partitions_def=partitions_def, group_name="comparison", kinds={"pandas"},
              check_specs=COMPARISON_CHECKS,
              ins={name: dg.AssetIn(f"{name}_scores") for name in METHODS})
    def comparison(context: dg.AssetExecutionContext, **scores: pd.DataFrame):
        """Every method's scores side by side (one-step and free run)."""
        table = pd.concat([scores[name].assign(method=name) for name in METHODS],
                          ignore_index=True)
        yield dg.Output(table, metadata={"mean_scores": markdown(mean_scores(table))})
        yield from comparison_results(table, str(context.partition_key))

    return comparison
