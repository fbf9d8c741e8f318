"""Each fitted model scored on held-out data (one MLflow run each), and the methods side
by side."""

import time

import dagster as dg
import pandas as pd

from ...config import Configuration
from ...datasets import Dataset
from ...methods import METHODS, Method
from ...pwa import PWARX
from ...scoring.comparison import mean_scores
from ...scoring.evaluation import Evaluation, evaluate
from ..caches import SignedMemory
from ..checks import (
    COMPARISON_CHECKS,
    comparison_results,
)
from ..figures import (
    figures_fingerprint,
    png_markdown,
    prediction_figure,
    to_png,
)
from ..mlflow_models import (
    ModelToLog,
    Simulator,
    example_table,
    training_dataset,
)
from ..partitions import split_key
from ..reporting import (
    markdown,
    nrmse_summary,
    rounded,
    score_metrics,
    theta_table,
)
from ..settings import PipelineSettings
from ..tracking import MLflowTracker
from .model_facts import latest_metadata, phi_names, prediction_key, truth_metadata


def scored(model, data: Dataset, warmup: int, title: str, key: tuple[str, str]
            ) -> tuple[Evaluation, bytes]:
    """``model`` scored on ``data``'s held-out experiments by the evaluation protocol, and
    its prediction figure rendered as PNG: what the scores assets cache (``cache_scores``),
    keyed by ``key`` (:func:`prediction_key`) in place of the model and the data."""
    ev = evaluate(model, data.u_test, data.y_test, warmup=warmup, output_names=data.y_names)
    return ev, to_png(prediction_figure(data, ev, title, warmup))


def scores_asset(method: Method, partitions_def):
    @dg.asset(name=f"{method.name}_scores", partitions_def=partitions_def, group_name="scores",
              kinds={"pandas", "mlflow"}, ins={"model": dg.AssetIn(f"{method.name}_model")},
              description=f"The {method.label} model scored on held-out data by the "
                          f"evaluation protocol (one-step and free run), tracked in MLflow; "
                          f"the scores and figure cached by what the model predicts with "
                          f"(``cache_scores``), the same for every set whose model predicts "
                          f"alike.")
    def scores(context: dg.AssetExecutionContext, mlflow: MLflowTracker,
               settings: PipelineSettings, configuration: Configuration,
               raw_benchmark: Dataset, model) -> pd.DataFrame:
        data = raw_benchmark
        dataset, hparams = split_key(context.partition_key)
        # titled by data set: sets whose models predict alike share the scores and figure
        title = f"{method.label} | {dataset}"
        memory = SignedMemory(settings.cache_root(), "scores", warn=context.log.warning,
                              salt=figures_fingerprint())
        score = memory.cache(scored, ignore=["model", "data"]) if settings.cache_scores \
            else scored
        ev, png = score(model, data, configuration.warmup, title,
                        prediction_key(model, data))
        context.log.info(f"{method.label}: one-step NRMSE {ev.mean('one_step'):.4g}, free run "
                         f"{ev.mean('free_run'):.4g}{' (diverged)' if ev.diverged() else ''}")
        fit_seconds = latest_metadata(context, f"{method.name}_model", "fit_seconds")
        extra_metrics, artifacts = {"fit_seconds": fit_seconds}, {}
        if isinstance(model, PWARX) and model.structured:
            extra_metrics.update(n_submodels=model.n_submodels_)
            artifacts["structure.json"] = {
                "outputs": data.y_names, "structure": model.structure_.structures,
                "regressors": [o.names for o in model.structure_.outputs],
                "parameters": [o.p.tolist() for o in model.structure_.outputs]}
        elif isinstance(model, PWARX):
            extra_metrics.update(n_submodels=model.n_submodels_,
                                 noise_share=model.clustering_.noise_share_,
                                 eps=model.clustering_.eps_,
                                 **{k: v for k, v in truth_metadata(model, data).items()
                                    if not isinstance(v, str)})
            thetas = theta_table(model.thetas_, phi_names(model, data), data.y_names)
            artifacts["parameter_matrices.json"] = {
                "regressors": list(thetas.index), "theta": model.thetas_.tolist(),
                "outputs": data.y_names}
        t0 = time.perf_counter()
        run = mlflow.log_run(
            dataset=dataset, hparams=hparams, method=method.name,
            params={**configuration.params(method.name), **model.resolved_params()},
            metrics={**score_metrics(ev.table), **extra_metrics},
            tags={"dagster_run_id": context.run.run_id, "partition": str(context.partition_key)},
            artifacts={"scores.csv": ev.table, "prediction.png": png, **artifacts},
            model=ModelToLog(
                simulator=Simulator(model, data.u_names, data.y_names),
                input_example=example_table(data.u_test[0], data.y_test[0], data.u_names,
                                            data.y_names, configuration.warmup),
                training=training_dataset(data)))
        log_seconds = time.perf_counter() - t0
        context.add_output_metadata(rounded({
            "prediction": dg.MetadataValue.md(png_markdown(png, title)),
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
