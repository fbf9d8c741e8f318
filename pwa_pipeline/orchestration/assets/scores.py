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
from ...scoring.evaluation import Evaluation, evaluate, score_text
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
from ..model_facts import model_note, prediction_key
from ..reporting import (
    mean_scores_markdown,
    nrmse_summary,
    rounded,
)
from ..run_records import method_run
from ..settings import PipelineSettings
from ..tracking import MLflowTracker
from .control import ControlModel
from .identification import REUSED


def scored(model, data: Dataset, warmup: int, key: tuple[str, str]) -> Evaluation:
    """``model`` scored on ``data``'s held-out experiments by the evaluation protocol: what
    the scores assets cache (``cache_scores``), keyed by ``key`` (``prediction_key``) in
    place of the model and the data. Numbers only: the prediction figure is drawn from them
    by each set, with its own title and the data's units, which a shared entry could not
    hold (the sets sharing it differ in name, and units are not in the data's digest)."""
    return evaluate(model, data.u_test, data.y_test, warmup=warmup, output_names=data.y_names)


def fitted_in_run(context: dg.AssetExecutionContext, method: str) -> bool:
    """Whether this run fitted the model it scores: the latest materialisation of
    ``<method>_model`` for this partition is of this run and neither reused the fitted
    model (`REUSED`) nor took it from the cache (``from_cache``). Read from the instance,
    so that steps on dask workers tell it alike."""
    records = context.instance.fetch_materializations(
        dg.AssetRecordsFilter(asset_key=dg.AssetKey(f"{method}_model"),
                              asset_partitions=[str(context.partition_key)]), limit=1).records
    if not records or records[0].run_id != context.run.run_id:
        return False
    meta = records[0].asset_materialization.metadata
    value = lambda key: getattr(meta.get(key), "value", None)  # noqa: E731
    return value("fit") != REUSED and value("from_cache") is not True


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
                          f"set, set and method. Its table's column ``model`` says what the "
                          f"model is when the method's name does not (a structure search "
                          f"that kept the linear model), for the leaderboard.")
    def scores(context: dg.AssetExecutionContext, mlflow: MLflowTracker,
               settings: PipelineSettings, configuration: Configuration,
               raw_benchmark: Dataset, model, **control: ControlModel | None
               ) -> pd.DataFrame:
        began = time.time()
        data = raw_benchmark
        # the scores are cached (shared by the sets whose models predict alike), the figure
        # drawn from them for this partition: its set in the title, the data's units
        memory = SignedMemory(settings.cache_root(), "scores", warn=context.log.warning)
        score = memory.cache(scored, ignore=["model", "data"]) if settings.cache_scores \
            else scored
        ev = score(model, data, configuration.warmup, prediction_key(model, data))
        figure = PredictionDisplay.from_evaluation(
            ev, data, configuration.warmup, context=context_title(
                configuration.dataset, configuration.hparams, method.label)).figure_
        png = to_png(figure)
        context.log.info(f"{method.label}: one-step NRMSE {ev.mean('one_step'):.4g}, free run "
                         f"{score_text(ev.mean('free_run'), 'nrmse', ev.diverged())}")
        record = method_run(configuration, method.name, model, ev, data,
                            control=control.get("control_model"),
                            tags={"dagster_run_id": context.run.run_id,
                                  "partition": str(context.partition_key)})
        t0 = time.perf_counter()
        run = mlflow.log_run(
            dataset=record.dataset, hparams=record.hparams, method=record.method,
            params=record.params, metrics=record.metrics, description=record.description,
            # the run spans the fit it scores, when this run fitted it (a model reused or
            # from the cache was fitted by an earlier run: the run starts now)
            started=began - (record.fit_seconds if np.isfinite(record.fit_seconds)
                             and fitted_in_run(context, method.name) else 0.0),
            tags=record.tags, artifacts={**record.artifacts, "prediction.png": png},
            model=ModelToLog(
                simulator=Simulator(model, data.u_names, data.y_names),
                input_example=example_table(data.u_test[0], data.y_test[0], data.u_names,
                                            data.y_names, configuration.warmup),
                training=training_dataset(data)))
        log_seconds = time.perf_counter() - t0
        note = model_note(model)
        context.add_output_metadata(rounded({
            **({"model": note} if note else {}),
            "prediction": dg.MetadataValue.md(png_markdown(png, figure.get_suptitle())),
            "scores_from_cache": memory.hits > 0,
            "mlflow_run_id": run.run_id, "mlflow_run": dg.MetadataValue.url(mlflow.run_url(run)),
            "mlflow_log_seconds": log_seconds,
            "free_run_diverged": ev.diverged(), **nrmse_summary(ev.table)}))
        return ev.table.assign(model=note)

    return scores


def comparison_asset(partitions_def):
    @dg.asset(partitions_def=partitions_def, group_name="comparison", kinds={"pandas"},
              check_specs=COMPARISON_CHECKS,
              ins={name: dg.AssetIn(f"{name}_scores") for name in METHODS})
    def comparison(context: dg.AssetExecutionContext, **scores: pd.DataFrame):
        """Every method's scores side by side (one-step and free run)."""
        table = pd.concat([scores[name].assign(method=name) for name in METHODS],
                          ignore_index=True)
        yield dg.Output(table, metadata={
            "mean_scores": dg.MetadataValue.md(mean_scores_markdown(table))})
        yield from comparison_results(table, str(context.partition_key))

    return comparison
