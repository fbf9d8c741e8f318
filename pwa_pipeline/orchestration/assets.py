"""The identification pipeline as software-defined assets.

configuration, raw_benchmark → regressors → local_models → clusters → sub_models →
svm_regions → output_error_refinement (a no-op unless the set asks for it) → pwa_model;
linear_arx_model and subspace_model beside it; each model scored by ``<method>_scores``
(the evaluation protocol, one MLflow run each); ``comparison`` puts them side by side.
Every asset is partitioned by data set × hyper-parameter set, and every partition's
configuration is resolved once, by the ``configuration`` asset; only ``leaderboard`` is
not: it ranks the stored scores of every partition. Methods come from
:data:`pwa_pipeline.methods.METHODS`.
"""

import time

import dagster as dg
import pandas as pd
from sklearn.base import BaseEstimator, clone

from .._validation import as_experiments
from ..config import Configuration
from ..datasets import Dataset
from ..datasets.registry import GroundTruth
from ..methods import METHODS, Method
from ..pwa import PWARX, STEPS
from ..pwa.regressors import Regressors, build_regressors, regressor_names
from ..scoring.comparison import leaderboard as leaderboard_table
from ..scoring.comparison import mean_scores
from ..scoring.evaluation import Evaluation, evaluate
from ..scoring.truth import ground_truth_scores
from .caches import SignedMemory, cache_key, load_or_compute
from .checks import (
    CLUSTER_CHECKS,
    COMPARISON_CHECKS,
    SUB_MODEL_CHECKS,
    cluster_results,
    comparison_results,
    not_applicable,
    sub_model_results,
)
from .figures import (
    figures_fingerprint,
    parameter_clusters_figure,
    png_markdown,
    prediction_figure,
    regions_figure,
    switching_figure,
    to_markdown,
    to_png,
)
from .files import inside
from .io_manager import ALL_PARTITIONS
from .jobs import LEADERBOARD
from .mlflow_models import (
    ModelToLog,
    Simulator,
    example_table,
    predictor_fingerprint,
    training_dataset,
)
from .partitions import split_key
from .reporting import (
    leaderboard_markdown,
    markdown,
    nrmse_summary,
    params_table,
    regions_table,
    rounded,
    score_metrics,
    theta_table,
)
from .settings import PipelineSettings
from .tracking import MLflowTracker

GROUP = "identification"
#: The asset holding each fitted step of :data:`pwa_pipeline.pwa.STEPS`, and the refinement.
STEP_ASSETS = {**dict(zip(STEPS, ("local_models", "clusters", "sub_models", "svm_regions"),
                          strict=True)), "refinement": "output_error_refinement"}


def _phi_names(pwa: PWARX, data: Dataset) -> list[str]:
    return regressor_names(data.y_names, data.u_names, pwa.na, pwa.nb, pwa.affine)


def _truth(model: PWARX, data: Dataset) -> GroundTruth | None:
    """The data set's ground truth when it has one and the model has its structure."""
    truth = data.truth
    if truth is None or model.structured or (model.na, model.nb, model.affine) != (
            truth.na, truth.nb, truth.affine):
        return None
    return truth


def _truth_metadata(model: PWARX, data: Dataset) -> dict:
    """Parameter error and region accuracy on the held-out data against the true system
    (simulated data sets), or why they are not given."""
    if data.truth is None:
        return {}
    truth = _truth(model, data)
    if truth is None:
        t = data.truth
        if model.structured:
            return {"ground_truth": "not comparable: the model has a structure of its own "
                                    "(form, outputs or scheduling)"}
        return {"ground_truth": f"not comparable: the model's (na, nb, affine) = "
                                f"{(model.na, model.nb, model.affine)}, the system's "
                                f"{(t.na, t.nb, t.affine)}"}
    return ground_truth_scores(model, truth.thetas, data.u_test, data.y_test, truth.modes_test)


#: Why the step assets hold nothing for a set with a structure of its own.
STRUCTURED_SKIP = ("not fitted: the set has a structure of its own (form, outputs or scheduling), "
                   "whose steps pwa_model fits per output group")


def _skipped(context: dg.AssetExecutionContext, configuration: Configuration) -> dict | None:
    """The metadata of a step asset skipped for this partition (a structured set), said in
    the log too; None when the step is fitted."""
    if not configuration.pwa.structured:
        return None
    context.log.info(f"{context.asset_key.to_user_string()}: {STRUCTURED_SKIP}")
    return {"skipped": STRUCTURED_SKIP, "seconds": 0.0}


def _latest_metadata(context: dg.AssetExecutionContext, asset: str, key: str) -> float:
    """``key`` of the latest materialisation of ``asset`` for this partition (NaN if none)."""
    result = context.instance.fetch_materializations(
        dg.AssetRecordsFilter(asset_key=dg.AssetKey(asset),
                              asset_partitions=[context.partition_key]), limit=1)
    if not result.records:
        return float("nan")
    value = result.records[0].asset_materialization.metadata.get(key)
    return float("nan") if value is None else float(value.value)


def _identification_assets(partitions_def) -> list:
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
                                     "regressors": ", ".join(_phi_names(pwa, raw_benchmark))})
        return reg

    @dg.asset(**part, kinds={"scikit-learn"})
    def local_models(context: dg.AssetExecutionContext, settings: PipelineSettings,
                     configuration: Configuration, regressors: Regressors) -> BaseEstimator | None:
        """θ_k of the local sets of n_ρ neighbours (eq. 6–7; by default of at most 5,000
        samples, ``local_models.max_sets``), the fitted ``local_models`` step; cached across
        sets whose later steps alone differ. None for a structured set (this and the next
        steps are then fitted per output group inside ``pwa_model``)."""
        if (skipped := _skipped(context, configuration)) is not None:
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
        if (skipped := _skipped(context, configuration)) is not None:
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
        if (skipped := _skipped(context, configuration)) is not None:
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
        table = theta_table(step.thetas_, _phi_names(configuration.pwa, raw_benchmark),
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
        if (skipped := _skipped(context, configuration)) is not None:
            context.add_output_metadata(skipped)
            return None
        t0 = time.perf_counter()
        step = configuration.pwa.fit_step("regions", regressors, submodels=sub_models)
        table = regions_table(step, _phi_names(configuration.pwa, raw_benchmark))
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
            return _structured_model(context, configuration, raw_benchmark)
        model = clone(configuration.pwa).assemble(
            regressors, local_models=local_models, clustering=clusters, submodels=sub_models,
            regions=svm_regions, refinement=output_error_refinement)
        model.timings_ = {name: _latest_metadata(context, asset, "seconds")
                          for name, asset in STEP_ASSETS.items()}
        data = raw_benchmark
        memory = SignedMemory(settings.cache_root(), "model_figures", warn=context.log.warning,
                              salt=figures_fingerprint())
        draw = memory.cache(_model_figures, ignore=["model", "data", "phi"]) \
            if settings.cache_scores else _model_figures
        figures = draw(model, data, regressors.phi, model.labels_,
                       _prediction_key(model, data))
        context.add_output_metadata(rounded({
            "n_submodels": model.n_submodels_, "fit_seconds": sum(model.timings_.values()),
            "resolved parameters": markdown(params_table(model.resolved_params())),
            **_truth_metadata(model, data), "figures_from_cache": memory.hits > 0,
            **{name: dg.MetadataValue.md(text) for name, text in figures.items()}}))
        return model

    return [configuration, raw_benchmark, regressors, local_models, clusters, sub_models,
            svm_regions, output_error_refinement, pwa_model]


def _structured_model(context: dg.AssetExecutionContext, configuration: Configuration,
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


def _fitted(estimator: BaseEstimator, u: list, y: list) -> BaseEstimator:
    """A clone of ``estimator`` fitted on the experiments ``u``, ``y`` (what the baseline
    assets cache)."""
    return clone(estimator).fit(u, y)


def _baseline_model_asset(method: Method, partitions_def):
    @dg.asset(name=f"{method.name}_model", partitions_def=partitions_def, group_name="models",
              kinds={"scikit-learn"},
              description=f"The fitted {method.label} model, on the training experiments; "
                          f"cached across the sets of a data set (``cache_baselines``), "
                          f"whose baseline settings are usually the same.")
    def model(context: dg.AssetExecutionContext, settings: PipelineSettings,
              configuration: Configuration, raw_benchmark: Dataset) -> BaseEstimator:
        t0 = time.perf_counter()
        memory = SignedMemory(settings.cache_root(), "baselines", warn=context.log.warning)
        fit = memory.cache(_fitted) if settings.cache_baselines else _fitted
        fitted = fit(configuration.estimators[method.name], raw_benchmark.u_train,
                     raw_benchmark.y_train)
        cached = memory.hits > 0
        context.log.info(f"{method.label}: {'from the cache' if cached else 'fitted'} in "
                         f"{time.perf_counter() - t0:.1f} s")
        context.add_output_metadata(rounded({
            "fit_seconds": time.perf_counter() - t0, "from_cache": cached,
            "resolved parameters": markdown(params_table(fitted.resolved_params()))}))
        return fitted

    return model


def _prediction_key(model, data: Dataset) -> tuple[str, str]:
    """What the scores and figure caches key on in place of ``model`` and ``data``: the
    model's :func:`predictor_fingerprint` and the data's :attr:`~Dataset.digest` (the same
    model on edited held-out data is scored again)."""
    return predictor_fingerprint(model, data.u_names, data.y_names), data.digest


def _scored(model, data: Dataset, warmup: int, title: str, key: tuple[str, str]
            ) -> tuple[Evaluation, bytes]:
    """``model`` scored on ``data``'s held-out experiments by the evaluation protocol, and
    its prediction figure rendered as PNG: what the scores assets cache (``cache_scores``),
    keyed by ``key`` (:func:`_prediction_key`) in place of the model and the data."""
    ev = evaluate(model, data.u_test, data.y_test, warmup=warmup, output_names=data.y_names)
    return ev, to_png(prediction_figure(data, ev, title, warmup))


def _model_figures(model: PWARX, data: Dataset, phi, labels, key: tuple[str, str]
                   ) -> dict[str, str]:
    """The PWA model's switching and regions figures as Markdown images (``pwa_model``'s
    metadata), cached like :func:`_scored`: keyed by ``key`` (:func:`_prediction_key`) and
    the rows' ``labels`` (the regions figure colours the rows by them) in
    place of the model, the data and ``phi`` (the data's regressors at the model's
    orders)."""
    truth = _truth(model, data)
    switching = switching_figure(
        model, data.u_test[0], data.y_test[0],
        true_modes=truth.modes_test[0] if truth else None,
        true_thetas=truth.thetas if truth else None)
    regions = regions_figure(model, phi, _phi_names(model, data))
    return {"switching (first held-out experiment)": to_markdown(switching),
            "regions": to_markdown(regions)}


def _scores_asset(method: Method, partitions_def):
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
        score = memory.cache(_scored, ignore=["model", "data"]) if settings.cache_scores \
            else _scored
        ev, png = score(model, data, configuration.warmup, title,
                        _prediction_key(model, data))
        context.log.info(f"{method.label}: one-step NRMSE {ev.mean('one_step'):.4g}, free run "
                         f"{ev.mean('free_run'):.4g}{' (diverged)' if ev.diverged() else ''}")
        fit_seconds = _latest_metadata(context, f"{method.name}_model", "fit_seconds")
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
                                 **{k: v for k, v in _truth_metadata(model, data).items()
                                    if not isinstance(v, str)})
            thetas = theta_table(model.thetas_, _phi_names(model, data), data.y_names)
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


def _comparison_asset(partitions_def):
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


def _leaderboard_asset(partitions_def):
    @dg.asset(name=LEADERBOARD, group_name="comparison", kinds={"pandas", "mlflow"},
              ins={f"{name}_scores": dg.AssetIn(metadata={ALL_PARTITIONS: True})
                   for name in METHODS})
    def leaderboard(context: dg.AssetExecutionContext, mlflow: MLflowTracker,
                    **scores: dict) -> pd.DataFrame:
        """Every data set × hyper-parameter set × method, one-step and free run, ranked by
        free-run NRMSE within each data set: read from the stored ``<method>_scores`` of
        every partition materialised so far (the others are listed as missing), shown here
        and logged to MLflow (``leaderboard.csv`` and ``.md``, one run per data set in its
        experiment)."""
        keys = [str(k) for k in
                partitions_def.get_partition_keys(dynamic_partitions_store=context.instance)]
        stacked, missing = [], {}
        for key in keys:
            dataset, hparams = split_key(key)
            absent = [m for m in METHODS if key not in scores[f"{m}_scores"]]
            if absent:
                missing[key] = absent
            stacked += [scores[f"{m}_scores"][key].assign(dataset=dataset, hparams=hparams,
                                                          method=m)
                        for m in METHODS if m not in absent]
        if not stacked:
            context.log.warning("leaderboard: no partition has scores yet")
            table = leaderboard_table(pd.DataFrame(columns=[
                "dataset", "hparams", "method", "mode", "output", "nrmse", "r2", "diverged"]))
        else:
            table = leaderboard_table(pd.concat(stacked, ignore_index=True))
        text = leaderboard_markdown(table, missing)
        links = {}
        for dataset, rows in table.groupby("dataset", sort=False):
            scored = rows[~rows["free_run_diverged"]]["free_run_nrmse"]
            run = mlflow.log_run(
                dataset=dataset, hparams="all", method=LEADERBOARD, run_name=LEADERBOARD,
                params={"partitions": ", ".join(dict.fromkeys(
                    f"{dataset}|{h}" for h in rows["hparams"]))},
                metrics={"rows": len(rows), "best_free_run_nrmse":
                         float(scored.min()) if len(scored) else None},
                tags={"dagster_run_id": context.run.run_id},
                artifacts={"leaderboard.csv": rows.reset_index(drop=True),
                           "leaderboard.md": leaderboard_markdown(rows)})
            links[f"mlflow_run {dataset}"] = dg.MetadataValue.url(mlflow.run_url(run))
        context.log.info(f"leaderboard: {len(table)} rows from {len(keys) - len(missing)} of "
                         f"{len(keys)} partitions ({len(missing)} not (fully) materialised)")
        context.add_output_metadata({
            "leaderboard": dg.MetadataValue.md(text), "rows": len(table),
            "partitions_scored": len(keys) - len(missing), "partitions_missing": len(missing),
            "missing": ", ".join(missing) or "none", **links})
        return table

    return leaderboard


def build_assets(partitions_def: dg.PartitionsDefinition) -> list[dg.AssetsDefinition]:
    """Every asset of the pipeline on ``partitions_def``: the partitioned ones, then the
    unpartitioned ``leaderboard``."""
    baselines = [m for m in METHODS.values() if m.name != "pwa"]
    return [*_identification_assets(partitions_def),
            *(_baseline_model_asset(m, partitions_def) for m in baselines),
            *(_scores_asset(m, partitions_def) for m in METHODS.values()),
            _comparison_asset(partitions_def), _leaderboard_asset(partitions_def)]
