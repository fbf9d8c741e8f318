"""The identification pipeline as software-defined assets, one per step of the method.

raw_benchmark → regressors → local_models → clusters → sub_models → svm_regions →
validation_metrics, beside linear_baseline and subspace_baseline; comparison puts them side
by side. Every asset is partitioned by data set × hyper-parameter set.
"""

import time

import dagster as dg
import pandas as pd

from .._validation import as_experiments
from ..clustering import Clustering
from ..comparison import mean_scores
from ..datasets import Dataset
from ..evaluation import evaluate
from ..identification import PWARX
from ..local_models import LocalModels
from ..regions import Regions
from ..regressors import Regressors, build_regressors, regressor_names
from ..submodels import SubModels
from .checks import (
    CLUSTER_CHECKS,
    COMPARISON_CHECKS,
    SUB_MODEL_CHECKS,
    cluster_results,
    comparison_results,
    sub_model_results,
)
from .partitions import partitions_def, split_key
from .reporting import (
    nrmse_summary,
    prediction_figure,
    regions_table,
    score_metrics,
    theta_table,
)
from .resources import MLflowTracker, PipelineConfig
from .storage import cache_key, load_object, save_object

GROUP = "identification"


def _hparams(context: dg.AssetExecutionContext, config: PipelineConfig):
    dataset, hparams = split_key(context.partition_key)
    return dataset, hparams, config.hparams(hparams, dataset)


def _settings(context, config, regressors: Regressors):
    _, _, hp = _hparams(context, config)
    model = hp.pwa_model()
    return model, model.resolve_settings(regressors.phi.shape[1])


def _phi_names(hp, data: Dataset) -> list[str]:
    p = hp.pwarx
    return regressor_names(data.y_names, data.u_names, p.get("na", 1), p.get("nb", 1),
                           p.get("affine", False))


@dg.asset(partitions_def=partitions_def, group_name=GROUP, kinds={"numpy"})
def raw_benchmark(context: dg.AssetExecutionContext, config: PipelineConfig) -> Dataset:
    """Training and held-out experiments of the partition's data set."""
    dataset, _ = split_key(context.partition_key)
    data = config.dataset(dataset)
    context.add_output_metadata({
        "train_samples": data.n_train, "test_samples": data.n_test,
        "train_experiments": len(data.u_train), "test_experiments": len(data.u_test),
        "inputs": ", ".join(data.u_names), "outputs": ", ".join(data.y_names),
    })
    return data


@dg.asset(partitions_def=partitions_def, group_name=GROUP, kinds={"numpy"})
def regressors(context: dg.AssetExecutionContext, config: PipelineConfig,
               raw_benchmark: Dataset) -> Regressors:
    """φ(k) and y(k) of the training experiments (eq. 2–3), never spanning two of them."""
    _, _, hp = _hparams(context, config)
    p = hp.pwarx
    reg = build_regressors(as_experiments(raw_benchmark.u_train, raw_benchmark.y_train),
                           p.get("na", 1), p.get("nb", 1), p.get("affine", False))
    context.add_output_metadata({"rows": reg.phi.shape[0], "d": reg.phi.shape[1],
                                 "regressors": ", ".join(_phi_names(hp, raw_benchmark))})
    return reg


@dg.asset(partitions_def=partitions_def, group_name=GROUP, kinds={"scikit-learn"})
def local_models(context: dg.AssetExecutionContext, config: PipelineConfig,
                 regressors: Regressors) -> LocalModels:
    """θ_k of every local set of n_ρ neighbours (eq. 6–7), cached across sets that differ only
    in ε or MinPts."""
    _, cfg = _settings(context, config, regressors)
    t0 = time.perf_counter()
    key = cache_key(regressors.phi, regressors.target, n_rho=cfg.n_rho,
                    standardize=cfg.standardize, ridge=cfg.ridge)
    path = config.cache_root() / "local_models" / f"{key}.pkl"
    cached = config.cache_local_models and path.is_file()
    if cached:
        local = load_object(path)
    else:
        local = PWARX.fit_local_models(regressors, cfg)
        if config.cache_local_models:
            save_object(path, local)
    context.add_output_metadata({"n_rho": cfg.n_rho, "from_cache": cached,
                                 "seconds": time.perf_counter() - t0, "cache_key": key})
    return local


@dg.asset(partitions_def=partitions_def, group_name=GROUP, kinds={"scikit-learn"},
          check_specs=CLUSTER_CHECKS)
def clusters(context: dg.AssetExecutionContext, config: PipelineConfig,
             regressors: Regressors, local_models: LocalModels):
    """Extended DBSCAN on the Vθ distance of the local models (eq. 8–10)."""
    _, cfg = _settings(context, config, regressors)
    t0 = time.perf_counter()
    result = PWARX.fit_clusters(regressors, local_models, cfg)
    yield dg.Output(result, metadata={
        "n_clusters": result.n_clusters, "eps": result.eps, "eps_from_data": result.eps_auto,
        "min_pts": result.min_pts, "noise_share": result.noise_share,
        "seconds": time.perf_counter() - t0})
    yield from cluster_results(result)


@dg.asset(partitions_def=partitions_def, group_name=GROUP, kinds={"numpy"},
          check_specs=SUB_MODEL_CHECKS)
def sub_models(context: dg.AssetExecutionContext, config: PipelineConfig,
               raw_benchmark: Dataset, regressors: Regressors, local_models: LocalModels,
               clusters: Clustering):
    """One parameter matrix θ_i per cluster (step 5)."""
    _, _, hp = _hparams(context, config)
    _, cfg = _settings(context, config, regressors)
    t0 = time.perf_counter()
    subs = PWARX.fit_submodels(regressors, local_models, clusters, cfg)
    table = theta_table(subs.thetas, _phi_names(hp, raw_benchmark), raw_benchmark.y_names)
    yield dg.Output(subs, metadata={
        "n_submodels": subs.thetas.shape[0], "merged": subs.n_merged,
        "refinement_sweeps": subs.n_iter, "seconds": time.perf_counter() - t0,
        "parameters": dg.MetadataValue.md(table.to_markdown(floatfmt=".4g"))})
    yield from sub_model_results(subs)


@dg.asset(partitions_def=partitions_def, group_name=GROUP, kinds={"scikit-learn"})
def svm_regions(context: dg.AssetExecutionContext, config: PipelineConfig,
                raw_benchmark: Dataset, regressors: Regressors, sub_models: SubModels) -> Regions:
    """Regions H_i from a multi-class linear SVM on φ (step 6)."""
    _, _, hp = _hparams(context, config)
    _, cfg = _settings(context, config, regressors)
    t0 = time.perf_counter()
    regions = PWARX.fit_regions(regressors, sub_models, cfg)
    table = regions_table(regions, _phi_names(hp, raw_benchmark))
    context.add_output_metadata({
        "n_regions": regions.n_regions, "seconds": time.perf_counter() - t0,
        "hyperplanes": dg.MetadataValue.md(table.to_markdown(floatfmt=".4g"))})
    return regions


def _fit_seconds(context: dg.AssetExecutionContext, names: list[str]) -> float:
    """Sum of the ``seconds`` metadata of this partition's upstream materialisations."""
    total = 0.0
    for name in names:
        result = context.instance.fetch_materializations(
            dg.AssetRecordsFilter(asset_key=dg.AssetKey(name),
                                  asset_partitions=[context.partition_key]), limit=1)
        if not result.records:
            return float("nan")
        total += float(result.records[0].asset_materialization.metadata["seconds"].value)
    return total


def _track(context, mlflow: MLflowTracker, hp, method: str, data: Dataset, ev,
           extra_metrics: dict, artifacts: dict) -> str:
    dataset, hparams = split_key(context.partition_key)
    figure = prediction_figure(data, ev.predictions, f"{method} | {context.partition_key}",
                               hp.warmup)
    return mlflow.log_run(
        dataset=dataset, hparams=hparams, method=method, params=hp.as_params(),
        metrics={**score_metrics(ev.table), **extra_metrics},
        tags={"dagster_run_id": context.run.run_id, "partition": str(context.partition_key)},
        artifacts={"scores.csv": ev.table, "prediction.png": figure, **artifacts})


@dg.asset(partitions_def=partitions_def, group_name=GROUP, kinds={"pandas", "mlflow"})
def validation_metrics(context: dg.AssetExecutionContext, config: PipelineConfig,
                       mlflow: MLflowTracker, raw_benchmark: Dataset, regressors: Regressors,
                       local_models: LocalModels, clusters: Clustering, sub_models: SubModels,
                       svm_regions: Regions) -> pd.DataFrame:
    """The PWA model scored on held-out data by the evaluation protocol, tracked in MLflow."""
    mlflow.check_reachable()
    _, _, hp = _hparams(context, config)
    model, cfg = _settings(context, config, regressors)
    data = raw_benchmark
    model.assemble(list(zip(data.u_train, data.y_train, strict=True)), regressors,
                   local_models, clusters, sub_models, svm_regions, cfg)
    ev = evaluate(model, data.u_test, data.y_test, warmup=hp.warmup, output_names=data.y_names)
    fit_seconds = _fit_seconds(context, ["local_models", "clusters", "sub_models",
                                         "svm_regions"])
    thetas = theta_table(model.thetas_, _phi_names(hp, data), data.y_names)
    run_id = _track(context, mlflow, hp, "pwa", data, ev,
                    {"n_submodels": model.n_submodels_, "noise_share": model.noise_share_,
                     "eps": model.eps_, "fit_seconds": fit_seconds},
                    {"parameter_matrices.json": {"regressors": list(thetas.index),
                                                 "theta": model.thetas_.tolist(),
                                                 "outputs": data.y_names}})
    context.add_output_metadata({"mlflow_run_id": run_id, "n_submodels": model.n_submodels_,
                                 "free_run_diverged": ev.diverged(),
                                 **nrmse_summary(ev.table)})
    return ev.table


def _baseline(context, config, mlflow, data: Dataset, method: str) -> pd.DataFrame:
    mlflow.check_reachable()
    _, _, hp = _hparams(context, config)
    t0 = time.perf_counter()
    model = hp.linear_model() if method == "linear_arx" else hp.subspace_model()
    model.fit(data.u_train, data.y_train)
    fit_seconds = time.perf_counter() - t0
    ev = evaluate(model, data.u_test, data.y_test, warmup=hp.warmup, output_names=data.y_names)
    if method == "linear_arx":
        matrices = {"theta": model.theta_.tolist()}
    else:
        matrices = {k: getattr(model, f"{k}_").tolist() for k in "ABCDK"}
    run_id = _track(context, mlflow, hp, method, data, ev, {"fit_seconds": fit_seconds},
                    {"parameter_matrices.json": matrices})
    context.add_output_metadata({"mlflow_run_id": run_id, "fit_seconds": fit_seconds,
                                 "free_run_diverged": ev.diverged(),
                                 **nrmse_summary(ev.table)})
    return ev.table


@dg.asset(partitions_def=partitions_def, group_name="baselines", kinds={"pandas", "mlflow"})
def linear_baseline(context: dg.AssetExecutionContext, config: PipelineConfig,
                    mlflow: MLflowTracker, raw_benchmark: Dataset) -> pd.DataFrame:
    """Linear ARX with the PWA model's regressors, scored by the same protocol."""
    return _baseline(context, config, mlflow, raw_benchmark, "linear_arx")


@dg.asset(partitions_def=partitions_def, group_name="baselines", kinds={"pandas", "mlflow"})
def subspace_baseline(context: dg.AssetExecutionContext, config: PipelineConfig,
                      mlflow: MLflowTracker, raw_benchmark: Dataset) -> pd.DataFrame:
    """Subspace state-space model (the benchmark's baseline), scored by the same protocol."""
    return _baseline(context, config, mlflow, raw_benchmark, "subspace")


@dg.asset(partitions_def=partitions_def, group_name="comparison", kinds={"pandas"},
          check_specs=COMPARISON_CHECKS)
def comparison(context: dg.AssetExecutionContext, validation_metrics: pd.DataFrame,
               linear_baseline: pd.DataFrame, subspace_baseline: pd.DataFrame):
    """PWA, linear ARX and subspace scores side by side (one-step and free-run)."""
    table = pd.concat([
        validation_metrics.assign(method="pwa"),
        linear_baseline.assign(method="linear_arx"),
        subspace_baseline.assign(method="subspace"),
    ], ignore_index=True)
    yield dg.Output(table, metadata={
        "mean_scores": dg.MetadataValue.md(mean_scores(table).to_markdown(floatfmt=".4g"))})
    yield from comparison_results(table)


ASSETS = [raw_benchmark, regressors, local_models, clusters, sub_models, svm_regions,
          validation_metrics, linear_baseline, subspace_baseline, comparison]
