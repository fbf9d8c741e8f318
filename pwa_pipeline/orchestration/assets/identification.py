"""The paper's chain as assets: configuration, raw_benchmark → regressors → local_models →
clusters → sub_models → svm_regions → output_error_refinement (a no-op unless the set asks
for it) → pwa_model; a set with a structure of its own is fitted whole by ``pwa_model``."""

import time

import dagster as dg
import pandas as pd
from sklearn.base import BaseEstimator, clone

from ..._validation import as_experiments
from ...config import Configuration
from ...datasets import Dataset
from ...methods import METHODS
from ...pwa import PWARX, STEPS
from ...pwa.regressors import Regressors, build_regressors
from ..caches import SignedMemory, cache_key, load_or_compute
from ..checks import (
    CLUSTER_CHECKS,
    SUB_MODEL_CHECKS,
    cluster_results,
    not_applicable,
    sub_model_results,
)
from ..figures import (
    figures_fingerprint,
    parameter_clusters_figure,
    regions_figure,
    switching_figure,
    to_markdown,
)
from ..files import inside
from ..partitions import split_key
from ..reporting import (
    markdown,
    params_table,
    regions_table,
    rounded,
    theta_table,
)
from ..settings import PipelineSettings
from .model_facts import (
    ground_truth,
    latest_metadata,
    phi_names,
    prediction_key,
    truth_metadata,
)

GROUP = "identification"


#: The asset holding each fitted step of :data:`pwa_pipeline.pwa.STEPS`, and the refinement.
STEP_ASSETS = {**dict(zip(STEPS, ("local_models", "clusters", "sub_models", "svm_regions"),
                          strict=True)), "refinement": "output_error_refinement"}


#: Why the step assets hold nothing for a set with a structure of its own.
STRUCTURED_SKIP = ("not fitted: the set has a structure of its own (form, outputs or scheduling), "
                   "whose steps pwa_model fits per output group")


def skipped_metadata(context: dg.AssetExecutionContext, configuration: Configuration) -> dict | None:
    """The metadata of a step asset skipped for this partition (a structured set), said in
    the log too; None when the step is fitted."""
    if not configuration.pwa.structured:
        return None
    context.log.info(f"{context.asset_key.to_user_string()}: {STRUCTURED_SKIP}")
    return {"skipped": STRUCTURED_SKIP, "seconds": 0.0}


def identification_assets(partitions_def) -> list:
    part = dict(partitions_def=partitions_def, group_name=GROUP)

    @dg.asset(**part, kinds={"python"})
    def configuration(context: dg.AssetExecutionContext,
                      settings: PipelineSettings) -> Configuration:
        """Every estimator of the partition, built from the hyper-parameter file once."""
        dataset, hparams = split_key(context.partition_key)
        cfg = settings.configuration(hparams, dataset)
        context.add_output_metadata({
            "source": dg.MetadataValue.path(str(cfg.source)), "warmup": cfg.warmup,
            **{f"{m} parameters": markdown(params_table(cfg.params(m))) for m in METHODS}})
        return cfg

    @dg.asset(**part, kinds={"numpy"})
    def raw_benchmark(context: dg.AssetExecutionContext, settings: PipelineSettings) -> Dataset:
        """Training and held-out experiments of the partition's data set."""
        dataset, _ = split_key(context.partition_key)
        data = settings.dataset(dataset)
        context.add_output_metadata({
            "train_samples": data.n_train, "test_samples": data.n_test,
            "train_experiments": len(data.u_train), "test_experiments": len(data.u_test),
            "inputs": ", ".join(data.u_names), "outputs": ", ".join(data.y_names),
            "digest": data.digest,  # (computed once: stored with the data set)
        })
        return data

    @dg.asset(**part, kinds={"numpy"})
    def regressors(context: dg.AssetExecutionContext, configuration: Configuration,
                   raw_benchmark: Dataset) -> Regressors:
        """φ(k) and y(k) of the training experiments (eq. 2–3), never spanning two of them."""
        pwa = configuration.pwa
        reg = build_regressors(as_experiments(raw_benchmark.u_train, raw_benchmark.y_train),
                               pwa.na, pwa.nb, pwa.affine)
        context.add_output_metadata({"rows": reg.phi.shape[0], "d": reg.phi.shape[1],
                                     "regressors": ", ".join(phi_names(pwa, raw_benchmark))})
        return reg

    @dg.asset(**part, kinds={"scikit-learn"})
    def local_models(context: dg.AssetExecutionContext, settings: PipelineSettings,
                     configuration: Configuration, regressors: Regressors) -> BaseEstimator | None:
        """θ_k of the local sets of n_ρ neighbours (eq. 6–7; by default of at most 5,000
        samples, ``local_models.max_sets``), the fitted ``local_models`` step; cached across
        sets whose later steps alone differ. None for a structured set (this and the next
        steps are then fitted per output group inside ``pwa_model``)."""
        if (skipped := skipped_metadata(context, configuration)) is not None:
            context.add_output_metadata(skipped)
            return None
        step = configuration.pwa.steps()["local_models"]
        t0 = time.perf_counter()
        key = cache_key(regressors.phi, regressors.target, step=type(step).__name__,
                        **step.get_params())
        root = settings.cache_root()
        path = inside(root, "local_models", f"{key}.pkl")
        local, cached = load_or_compute(
            path, root, lambda: configuration.pwa.fit_step("local_models", regressors),
            context.log.warning, "local-model cache entry", settings.cache_local_models)
        context.log.info(
            f"local models: {local.n_estimated_:,} of {local.estimated_.size:,} local sets of "
            f"n_rho = {local.n_rho_}{' from the cache' if cached else ''} "
            f"({local.n_degenerate_:,} degenerate) in {time.perf_counter() - t0:.1f} s")
        context.add_output_metadata(rounded({
            "n_rho": local.n_rho_, "from_cache": cached,
            "estimated_local_sets": local.n_estimated_,
            "degenerate_local_sets": local.n_degenerate_, "seconds": time.perf_counter() - t0,
            "cache_key": key}))
        return local

    @dg.asset(**part, kinds={"scikit-learn"}, check_specs=CLUSTER_CHECKS)
    def clusters(context: dg.AssetExecutionContext, configuration: Configuration,
                 regressors: Regressors, local_models: BaseEstimator | None):
        """Extended DBSCAN on the Vθ distance of the local models (eq. 8–10), the fitted
        ``clustering`` step; None for a structured set, whose check then passes as not
        applicable."""
        if (skipped := skipped_metadata(context, configuration)) is not None:
            yield dg.Output(None, metadata=skipped)
            yield from not_applicable(CLUSTER_CHECKS, str(context.partition_key), STRUCTURED_SKIP)
            return
        t0 = time.perf_counter()
        step = configuration.pwa.fit_step("clustering", regressors, local_models=local_models)
        context.log.info(f"clusters: {step.n_clusters_} with eps = {step.eps_:.4g}, MinPts = "
                         f"{step.min_pts_}, noise {step.noise_share_:.1%}, in "
                         f"{time.perf_counter() - t0:.1f} s")
        figure = parameter_clusters_figure(local_models, step, regressors.target)
        yield dg.Output(step, metadata=rounded({
            "n_clusters": step.n_clusters_, "eps": step.eps_, "eps_from_data": step.eps_auto_,
            "min_pts": step.min_pts_, "noise_share": step.noise_share_,
            "seconds": time.perf_counter() - t0,
            "local models by cluster": dg.MetadataValue.md(to_markdown(figure))}))
        yield from cluster_results(step, str(context.partition_key))

    @dg.asset(**part, kinds={"numpy"}, check_specs=SUB_MODEL_CHECKS)
    def sub_models(context: dg.AssetExecutionContext, settings: PipelineSettings,
                   configuration: Configuration, raw_benchmark: Dataset,
                   regressors: Regressors, local_models: BaseEstimator | None,
                   clusters: BaseEstimator | None):
        """One parameter matrix θ_i per cluster (step 5), the fitted ``submodels`` step; None
        for a structured set, whose checks then pass as not applicable. A step with a
        ``memory`` parameter (``RefinedSubModels``) left None caches its steps 2–4 in the
        store's cache (``cache_sub_models``): sets whose clusterings consolidate alike share
        them."""
        if (skipped := skipped_metadata(context, configuration)) is not None:
            yield dg.Output(None, metadata=skipped)
            yield from not_applicable(SUB_MODEL_CHECKS, str(context.partition_key),
                                      STRUCTURED_SKIP)
            return
        t0 = time.perf_counter()
        pwa = configuration.pwa
        step = pwa.steps()["submodels"]
        params = step.get_params()
        memory = None
        if settings.cache_sub_models and "memory" in params and params["memory"] is None:
            memory = SignedMemory(settings.cache_root(), "sub_models", warn=context.log.warning)
            pwa = clone(pwa).set_params(submodels=clone(step).set_params(memory=memory))
        step = pwa.fit_step("submodels", regressors, local_models=local_models,
                            clustering=clusters)
        cached = memory is not None and memory.hits > 0
        if memory is not None:
            step.set_params(memory=None)  # the stored step is the configured one
        context.log.info(f"sub-models: {step.n_submodels_} ({step.n_merged_} merges, "
                         f"{step.n_iter_} sweeps{', steps 2-4 from the cache' if cached else ''})"
                         f" in {time.perf_counter() - t0:.1f} s")
        table = theta_table(step.thetas_, phi_names(configuration.pwa, raw_benchmark),
                            raw_benchmark.y_names)
        yield dg.Output(step, metadata=rounded({
            "n_submodels": step.n_submodels_, "merged": step.n_merged_,
            "refinement_sweeps": step.n_iter_, "from_cache": cached,
            "seconds": time.perf_counter() - t0,
            "parameters": markdown(table)}))
        yield from sub_model_results(step, str(context.partition_key))

    @dg.asset(**part, kinds={"scikit-learn"})
    def svm_regions(context: dg.AssetExecutionContext, configuration: Configuration,
                    raw_benchmark: Dataset, regressors: Regressors,
                    sub_models: BaseEstimator | None) -> BaseEstimator | None:
        """Regions H_i from a multi-class linear SVM on φ (step 6), the fitted ``regions``
        step; None for a structured set."""
        if (skipped := skipped_metadata(context, configuration)) is not None:
            context.add_output_metadata(skipped)
            return None
        t0 = time.perf_counter()
        step = configuration.pwa.fit_step("regions", regressors, submodels=sub_models)
        table = regions_table(step, phi_names(configuration.pwa, raw_benchmark))
        context.add_output_metadata(rounded({"n_regions": step.n_regions_,
                                             "seconds": time.perf_counter() - t0,
                                             "hyperplanes": markdown(table)}))
        return step

    @dg.asset(**part, kinds={"scipy"})
    def output_error_refinement(context: dg.AssetExecutionContext,
                                configuration: Configuration, raw_benchmark: Dataset,
                                regressors: Regressors, local_models: BaseEstimator | None,
                                clusters: BaseEstimator | None,
                                sub_models: BaseEstimator | None,
                                svm_regions: BaseEstimator | None) -> BaseEstimator | None:
        """θ_i refined to minimise the free-run error on the training experiments, regions
        kept (the fitted ``refinement`` step); None when the set configures no refinement, or
        a structure of its own (``pwa_model`` then fits and refines it whole)."""
        pwa = configuration.pwa
        if pwa.refinement is None or pwa.structured:
            context.add_output_metadata({"refined": False, "seconds": 0.0})
            return None
        model = clone(pwa).assemble(regressors, local_models=local_models, clustering=clusters,
                                    submodels=sub_models, regions=svm_regions)
        step = model.fit_refinement(as_experiments(raw_benchmark.u_train,
                                                   raw_benchmark.y_train))
        context.log.info(f"refinement: training free-run MSE {step.cost_start_:.4g} → "
                         f"{step.cost_:.4g} in {step.n_iter_} steps, {step.seconds_:.1f} s "
                         f"({step.stop_})")
        context.add_output_metadata(rounded({
            "refined": True, "cost_start": step.cost_start_, "cost": step.cost_,
            "iterations": step.n_iter_, "stop": step.stop_, "seconds": step.seconds_}))
        return step

    @dg.asset(partitions_def=partitions_def, group_name="models", kinds={"scikit-learn"})
    def pwa_model(context: dg.AssetExecutionContext, settings: PipelineSettings,
                  configuration: Configuration, raw_benchmark: Dataset, regressors: Regressors,
                  local_models: BaseEstimator | None, clusters: BaseEstimator | None,
                  sub_models: BaseEstimator | None, svm_regions: BaseEstimator | None,
                  output_error_refinement: BaseEstimator | None) -> PWARX:
        """The fitted PWARX model, joined from its fitted steps; what ``pwa_scores`` scores.
        Its switching and regions figures are cached by what it predicts with
        (``cache_scores``), shared by the sets that end in the same model. A set with a
        structure of its own (form, outputs, scheduling: the structured route of
        :mod:`pwa_pipeline.pwa.structure_fit`) is fitted here whole."""
        if configuration.pwa.structured:
            return structured_model(context, configuration, raw_benchmark)
        model = clone(configuration.pwa).assemble(
            regressors, local_models=local_models, clustering=clusters, submodels=sub_models,
            regions=svm_regions, refinement=output_error_refinement)
        model.timings_ = {name: latest_metadata(context, asset, "seconds")
                          for name, asset in STEP_ASSETS.items()}
        data = raw_benchmark
        memory = SignedMemory(settings.cache_root(), "model_figures", warn=context.log.warning,
                              salt=figures_fingerprint())
        draw = memory.cache(model_figures, ignore=["model", "data", "phi"]) \
            if settings.cache_scores else model_figures
        figures = draw(model, data, regressors.phi, model.labels_,
                       prediction_key(model, data))
        context.add_output_metadata(rounded({
            "n_submodels": model.n_submodels_, "fit_seconds": sum(model.timings_.values()),
            "resolved parameters": markdown(params_table(model.resolved_params())),
            **truth_metadata(model, data), "figures_from_cache": memory.hits > 0,
            **{name: dg.MetadataValue.md(text) for name, text in figures.items()}}))
        return model

    return [configuration, raw_benchmark, regressors, local_models, clusters, sub_models,
            svm_regions, output_error_refinement, pwa_model]


def structured_model(context: dg.AssetExecutionContext, configuration: Configuration,
                      data: Dataset) -> PWARX:
    """Fit the structured PWARX model on the training experiments, with the metadata that
    says which training experiments (indices from 0) were held out to choose its structure
    and refinement iterate, and each candidate's free-run error on them."""
    t0 = time.perf_counter()
    model = clone(configuration.pwa).fit(data.u_train, data.y_train)
    fit = model.structure_fit_
    table = pd.DataFrame({"output": data.y_names, "structure": model.structure_.structures,
                          "regions": model.structure_.n_regions})
    for kind in sorted({k for costs in fit.validation_cost.values() for k in costs}):
        table[f"held-out MSE {kind}"] = [fit.validation_cost[j].get(kind, float("nan"))
                                         for j in range(len(data.y_names))]
    context.log.info(f"structured PWA model: {', '.join(model.structure_.structures)} in "
                     f"{time.perf_counter() - t0:.1f} s")
    context.add_output_metadata(rounded({
        "n_submodels": model.n_submodels_, "fit_seconds": time.perf_counter() - t0,
        "validation_experiments": ", ".join(map(str, fit.validation_experiments)),
        "structure per output": markdown(table.set_index("output")),
        "resolved parameters": markdown(params_table(model.resolved_params()))}))
    return model


def model_figures(model: PWARX, data: Dataset, phi, labels, key: tuple[str, str]
                   ) -> dict[str, str]:
    """The PWA model's switching and regions figures as Markdown images (``pwa_model``'s
    metadata), cached like :func:`scored`: keyed by ``key`` (:func:`prediction_key`) and
    the rows' ``labels`` (the regions figure colours the rows by them) in
    place of the model, the data and ``phi`` (the data's regressors at the model's
    orders)."""
    truth = ground_truth(model, data)
    switching = switching_figure(
        model, data.u_test[0], data.y_test[0],
        true_modes=truth.modes_test[0] if truth else None,
        true_thetas=truth.thetas if truth else None)
    regions = regions_figure(model, phi, phi_names(model, data))
    return {"switching (first held-out experiment)": to_markdown(switching),
            "regions": to_markdown(regions)}
