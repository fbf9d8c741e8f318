"""The PWA model as assets: configuration, raw_benchmark → the fitted model and the fitted
steps it shows.

One multi-asset (``pwa_fit``) fits the partition's PWARX once, by its ``fit``, and stores the
model (``pwa_model``, what the scores score and MLflow registers), the training regressors
(``regressors``, eq. 2–3, which its figures read) and each fitted step of the paper's chain
that built it (``local_models`` → ``clusters`` → ``sub_models`` → ``svm_regions`` →
``output_error_refinement``), taken from the fitted model: the graph reads as the paper's
chain, the checks guard the clusters and sub-models, and the estimator runs its own loop.
The costly steps are cached across sets through the steps' own ``memory=`` (the store's
caches), as scikit-learn's estimators take one. A model whose regions come from elsewhere
(scheduling variables, a structure search that kept no clusters) has no such step, and its
step assets say so."""

import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager

import dagster as dg
import numpy as np
import pandas as pd
from sklearn.base import clone

from ..._validation import as_experiments
from ...config import Configuration
from ...datasets import Dataset
from ...methods import METHODS
from ...plotting import (
    ParameterClustersDisplay,
    RegionsDisplay,
    SwitchingDisplay,
    context_title,
)
from ...pwa import PWARX
from ...pwa.output_error import numbered
from ...pwa.search import SEARCH_LOG
from ...regressors import build_regressors
from ..caches import SignedMemory, versions
from ..checks import (
    CLUSTER_CHECKS,
    SUB_MODEL_CHECKS,
    cluster_results,
    not_applicable,
    sub_model_results,
)
from ..images import figures_fingerprint, to_markdown
from ..model_facts import (
    ground_truth,
    held_outputs,
    model_names,
    model_note,
    phi_names,
    prediction_key,
    shown_params,
    truth_metadata,
)
from ..partitions import PartitionKey
from ..reporting import markdown, params_table, regions_table, rounded, theta_table
from ..settings import PipelineSettings

GROUP = "identification"
#: The fitted steps the multi-asset shows, in the paper's order, by asset: the step's name in
#: an output group's ``steps`` (`OutputGroup`).
STEP_ASSETS = {"local_models": "local_models", "clusters": "clustering",
               "sub_models": "submodels", "svm_regions": "regions",
               "output_error_refinement": "refinement"}
#: The assets of ``pwa_fit``, each drawn depending on the one before it.
CHAIN = ("regressors", *STEP_ASSETS, "pwa_model")
_DESCRIPTIONS = {
    "regressors": "φ(k) and y(k) of the training experiments (eq. 2–3) at the model's lags, "
                  "never spanning two of them: what the model's regions figure slices.",
    "local_models": "θ_k of the local sets of n_ρ neighbours (eq. 6–7; by default of at most "
                    "5,000 samples, `local_models.max_sets`): the fitted `local_models` step "
                    "of the PWA model, cached across sets whose later steps alone differ.",
    "clusters": "Extended DBSCAN on the Vθ distance of the local models (eq. 8–10): the "
                "fitted `clustering` step, with the local models drawn by cluster. Its "
                "noise check holds the model back when most local models are noise.",
    "sub_models": "One parameter matrix θ_i per cluster (step 5): the fitted `submodels` "
                  "step, cached across sets whose clusterings consolidate alike.",
    "svm_regions": "Regions H_i from a multi-class linear SVM on φ (step 6): the fitted "
                   "`regions` step, with its hyperplanes.",
    "output_error_refinement": "θ_i refined to minimise the free-run error on the training "
                               "experiments, regions kept (the fitted `refinement` step).",
    "pwa_model": "The fitted PWARX model, what `pwa_scores` scores and MLflow registers. Its "
                 "page shows what the model is when a structure search built it (`model`: "
                 "e.g. the linear model kept, and whether its budget or time limit "
                 "stopped it), whether it switches (`switching`, for a model that does "
                 "not), the parameters it ran with (the paper's steps left out, and why, "
                 "when the search ran none), each output's structure, the ground truth on "
                 "a simulated system, and two figures: *switching*, the region of each "
                 "sample of the first held-out experiment (one lane per output group; a "
                 "model that never switches says so instead), and *regions*, the regions "
                 "in the 2-D slice of φ where they differ most.",
}
#: How the ``pwa_model`` page, the run's log and the command line's summary say that a
#: rerun took the fitted model from the cache (`fit_model`).
REUSED = "reused: unchanged data and settings"
#: The figure keys of the ``pwa_model`` page.
SWITCHING, REGIONS = "switching (first held-out experiment)", "regions"


@contextmanager
def forwarded(logger_name: str, log) -> Iterator[None]:
    """Send the INFO records of the standard-library logger ``logger_name`` (a core step's
    progress, e.g. the structure search's stages) to ``log`` (Dagster's ``context.log``)
    while the block runs."""

    class Forward(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            log.info(record.getMessage())

    logger, handler = logging.getLogger(logger_name), Forward(logging.INFO)
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


def with_caches(pwa: PWARX, settings: PipelineSettings, warn) -> tuple[PWARX, dict]:
    """A clone of ``pwa`` whose costly steps keep their results in the store's caches (the
    steps' ``memory=``, where the settings ask for it and the step takes one), and the
    caches by parameter name, to count their hits and take them off again."""
    model, caches = clone(pwa), {}
    for name, use, folder in (("local_models", settings.cache_local_models, "local_models"),
                              ("submodels", settings.cache_sub_models, "sub_models")):
        params = model.step_objects()[name].get_params()
        if use and "memory" in params and params["memory"] is None:
            caches[f"{name}__memory"] = SignedMemory(settings.cache_root(), folder, warn=warn)
    return model.set_params(**caches), caches


def fit_model(context: dg.AssetExecutionContext, settings: PipelineSettings,
              configuration: Configuration, data: Dataset) -> tuple[PWARX, set[str], bool]:
    """The partition's PWARX fitted on the training experiments (`fitted`), or the one a
    run with the same data, hyper-parameters and versions (`versions`) fitted before
    (``cache_models``: a rerun repeats no structure search). Returns it with the steps a
    cache answered and whether the whole fitted model was reused."""
    answered: set[str] = set()

    def fit(pwa: PWARX, data_digest: str) -> PWARX:
        model, steps = fitted(context, settings, pwa, data)
        answered.update(steps)
        return model

    if not settings.cache_models:
        return fit(configuration.pwa, data.digest), answered, False
    memory = SignedMemory(settings.cache_root(), "models", warn=context.log.warning,
                          salt=versions())
    model = memory.cache(fit)(configuration.pwa, data.digest)
    return model, answered, memory.hits > 0


def fitted(context: dg.AssetExecutionContext, settings: PipelineSettings, pwa: PWARX,
           data: Dataset) -> tuple[PWARX, set[str]]:
    """``pwa`` fitted on the training experiments (the steps' caches on, the search's
    progress in the run's log); returns it with the caches taken off its steps (the stored
    model is the configured one), and the steps a cache answered."""
    if (search := pwa.search) is not None:
        context.log.info(f"structure search: orders up to ({pwa.na}, {pwa.nb}), at most "
                         f"{search.max_candidates} candidates (search.max_candidates; "
                         f"{search.max_seconds:g} s as a safety net)")
    model, caches = with_caches(pwa, settings, context.log.warning)
    with forwarded(SEARCH_LOG, context.log):
        model.fit(data.u_train, data.y_train)
    model.set_params(**dict.fromkeys(caches))
    for group in model.groups_:
        for step in group.steps.values():
            if step.get_params().get("memory") is not None:
                step.set_params(memory=None)
    return model, {key.removesuffix("__memory") for key, c in caches.items() if c.hits}


def on_phi(model: PWARX) -> bool:
    """Whether the model's steps ran on eq. (3)'s φ itself (the paper's route), so that φ's
    names label their parameters and hyperplanes."""
    return (model.search is None and model.scheduling is None and model.form == "level"
            and model.outputs == "joint")


def shown_steps(model: PWARX) -> tuple[dict, tuple[int, ...]]:
    """The fitted steps the step assets show (those of the first output group that has
    them) and that group's outputs."""
    group = next((g for g in model.groups_ if g.steps), None)
    return ({}, ()) if group is None else (group.steps, group.outputs)


def identification_assets(partitions_def) -> list:
    part = dict(partitions_def=partitions_def, group_name="data")

    @dg.asset(**part, kinds={"python"})
    def configuration(context: dg.AssetExecutionContext,
                      settings: PipelineSettings) -> Configuration:
        """Every estimator of the partition, built from the hyper-parameter file once."""
        part = PartitionKey.parse(context.partition_key)
        cfg = settings.configuration(part.hparams, part.dataset)
        context.add_output_metadata({
            "source": dg.MetadataValue.path(str(cfg.source)), "warmup": cfg.warmup,
            **{f"{m} parameters": markdown(params_table(cfg.params(m))) for m in METHODS}})
        return cfg

    @dg.asset(**part, kinds={"numpy"})
    def raw_benchmark(context: dg.AssetExecutionContext, settings: PipelineSettings,
                      configuration: Configuration) -> Dataset:
        """Training and held-out experiments of the partition's data set."""
        data = settings.dataset(configuration.dataset)
        context.add_output_metadata({
            "train_samples": data.n_train, "test_samples": data.n_test,
            "train_experiments": len(data.u_train), "test_experiments": len(data.u_test),
            "inputs": ", ".join(map(data.label, data.u_names)),
            "outputs": ", ".join(map(data.label, data.y_names)),
            "digest": data.digest,  # (computed once: stored with the data set)
        })
        return data

    kinds = {"regressors": "numpy", "sub_models": "numpy", "output_error_refinement": "scipy"}
    previous = {"regressors": {dg.AssetKey("configuration"), dg.AssetKey("raw_benchmark")},
                **{b: {dg.AssetKey(a)} for a, b in zip(CHAIN, CHAIN[1:])}}

    @dg.multi_asset(
        name="pwa_fit", partitions_def=partitions_def, can_subset=True,
        outs={name: dg.AssetOut(group_name="models" if name == "pwa_model" else GROUP,
                                kinds={kinds.get(name, "scikit-learn")}, is_required=False,
                                description=_DESCRIPTIONS[name]) for name in CHAIN},
        internal_asset_deps=previous, check_specs=[*CLUSTER_CHECKS, *SUB_MODEL_CHECKS])
    def pwa_fit(context: dg.AssetExecutionContext, settings: PipelineSettings,
                configuration: Configuration, raw_benchmark: Dataset):
        """The PWA model fitted once, then stored with the fitted steps that built it
        (those selected), each with its page and checks."""
        selected = {key.to_user_string() for key in context.selected_asset_keys}
        checks = context.selected_asset_check_keys
        partition = str(context.partition_key)
        pwa, data = configuration.pwa, raw_benchmark
        reg = build_regressors(as_experiments(data.u_train, data.y_train), pwa.output_lags_,
                               pwa.nb, pwa.affine)
        if "regressors" in selected:
            yield dg.Output(reg, output_name="regressors", metadata={
                "rows": reg.phi.shape[0], "d": reg.phi.shape[1],
                "regressors": ", ".join(phi_names(pwa, data))})
        t0 = time.perf_counter()
        model, cached, reused = fit_model(context, settings, configuration, raw_benchmark)
        described = "; ".join(_described(model, raw_benchmark))
        context.log.info(
            f"PWA model {REUSED} (fitted before in {sum(model.timings_.values()):.1f} s; no "
            f"structure search or step ran): {described}" if reused else
            f"PWA model: {described} in {time.perf_counter() - t0:.1f} s"
            + (f" ({', '.join(sorted(cached))} from the cache)" if cached else ""))
        steps, outputs = shown_steps(model)
        for asset, name in STEP_ASSETS.items():
            events = _step_events(asset, steps.get(name), model, raw_benchmark, outputs,
                                  partition, reused or name in cached, configuration)
            for event in events:
                if isinstance(event, dg.Output):
                    if asset in selected:
                        yield event
                elif dg.AssetCheckKey(event.asset_key, event.check_name) in checks:
                    yield event
                    if event.check_name == "noise_share_below_limit" and not event.passed:
                        return  # (a blocking check: the model is not stored)
        if "pwa_model" in selected:
            yield model_output(context, settings, configuration, model, raw_benchmark, cached,
                               reg.phi, reused)

    return [configuration, raw_benchmark, pwa_fit]


def _title(configuration: Configuration) -> str:
    """The first line of the PWA model's figures: data set, set and method."""
    return context_title(configuration.dataset, configuration.hparams, METHODS["pwa"].label)


def _described(model: PWARX, data: Dataset) -> list[str]:
    """Each output's structure, named: ``q1: velocity (2, 2), linear``."""
    return [f"{data.label(y)}: {s}" for y, s in zip(data.y_names, model.structures_,
                                                    strict=True)]


def _regions_per_group(model: PWARX) -> str:
    """``"4, 4, 1, 3: the model as one PWA map (eq. 1) has their product, 48 modes"``."""
    sizes = [g.n_regions for g in model.groups_]
    return (f"{', '.join(map(str, sizes))}: the model as one PWA map (eq. 1) has their "
            f"product, {model.n_submodels_} modes (n_submodels)")


def switching_note(model) -> str | None:
    """What the page says of a model that never switches (one sub-model: a linear model,
    e.g. the one a structure search kept), beside its switching figure, which says so
    too (with the outputs' limits, where they are held); None for a model that switches."""
    if model.n_submodels_ != 1:
        return None
    held = held_outputs(model)
    return "none: one mode (a single linear model)" + (
        f", held at its limits ({held}) where it reaches them" if held else "")


def _not_fitted(model: PWARX, asset: str) -> str:
    """Why a model has no fitted step for ``asset``."""
    if asset == "output_error_refinement":
        if model.search is not None:
            return "not fitted: the structure search refines the structures it compares itself"
        if model.refinement is None:
            return "not fitted: the set configures no refinement"
        return "not fitted: the structured fit refines each output group itself"
    if model.scheduling is not None:
        return "not fitted: the model's regions are the signs of its scheduling variables"
    return f"not fitted: the structure search kept no clustered regions ({'; '.join(model.structures_)})"


def _step_events(asset: str, step, model: PWARX, data: Dataset, outputs: tuple[int, ...],
                 partition: str, cached: bool, configuration: Configuration):
    """The output of one step asset (the fitted step, or None and why; ``cached``: its
    cache answered) and its checks."""
    checks = {"clusters": CLUSTER_CHECKS, "sub_models": SUB_MODEL_CHECKS}.get(asset, [])
    if step is None:
        reason = _not_fitted(model, asset)
        yield dg.Output(None, output_name=asset, metadata={"fitted": False, "reason": reason})
        yield from not_applicable(checks, partition, reason)
        return
    where = {} if on_phi(model) else {"outputs": ", ".join(data.y_names[j] for j in outputs),
                                      "regressors": "each output group's own ψ"}
    if asset == "local_models":
        meta = {"n_rho": step.n_rho_, "estimated_local_sets": step.n_estimated_,
                "degenerate_local_sets": step.n_degenerate_}
    elif asset == "clusters":
        reg = build_regressors(as_experiments(data.u_train, data.y_train), model.na, model.nb,
                               model.affine)
        local = next(g.steps["local_models"] for g in model.groups_ if g.steps)
        figure = None if where else ParameterClustersDisplay.from_steps(
            local, step, reg.target, context=_title(configuration)
        ).figure_
        meta = {"n_clusters": step.n_clusters_, "eps": step.eps_,
                "eps_from_data": step.eps_auto_, "min_pts": step.min_pts_,
                "noise_share": step.noise_share_,
                **({} if figure is None else {
                    "local models by cluster": dg.MetadataValue.md(to_markdown(figure))})}
    elif asset == "sub_models":
        names = phi_names(model, data) if not where else None
        meta = {"n_submodels": step.n_submodels_, "merged": step.n_merged_,
                "refinement_sweeps": step.n_iter_,
                **({} if names is None else {
                    "parameters": markdown(theta_table(step.thetas_, names, data.y_names))})}
    elif asset == "svm_regions":
        meta = {"n_regions": step.n_regions_, **({} if where else {
            "hyperplanes": markdown(regions_table(step, phi_names(model, data)))})}
    else:
        meta = {"cost_start": step.cost_start_, "cost": step.cost_, "iterations": step.n_iter_,
                "stop": step.stop_}
    if asset in ("local_models", "sub_models"):
        meta["from_cache"] = cached
    yield dg.Output(step, output_name=asset, metadata=rounded(
        {"fitted": True, **where, "seconds": model.timings_.get(STEP_ASSETS[asset], 0.0),
         **meta}))
    if asset == "clusters":
        yield from cluster_results(step, partition)
    elif asset == "sub_models":
        yield from sub_model_results(step, partition)


def model_output(context: dg.AssetExecutionContext, settings: PipelineSettings,
                 configuration: Configuration, model: PWARX, data: Dataset, cached: set[str],
                 phi: np.ndarray, reused: bool = False) -> dg.Output:
    """``pwa_model`` with its page: what the model is (the structure search's verdict,
    first), whether it switches (`switching_note`), whether it was fitted or
    reused (`REUSED`), the parameters it ran with
    (`shown_params`), each output's structure, the structure search's report
    or the structured fit's candidates, the ground truth when comparable, and the
    switching and regions figures (their numbers cached by what the model predicts with,
    drawn titled with this partition's set)."""
    title = _title(configuration)
    memory = SignedMemory(settings.cache_root(), "model_figures",
                          warn=context.log.warning, salt=figures_fingerprint())
    compute = memory.cache(model_figure_inputs, ignore=["model", "data", "phi"]) \
        if settings.cache_scores else model_figure_inputs
    inputs = compute(model, data, phi, prediction_key(model, data))
    structure = pd.DataFrame({"output": [data.label(y) for y in data.y_names],
                              "structure": model.structures_,
                              "group": [next(i + 1 for i, g in enumerate(model.groups_)
                                             if j in g.outputs)
                                        for j in range(model.n_outputs_)]})
    found = {}
    fit = getattr(model, "structure_fit_", None)
    if fit is not None:
        # numbered from 1, as the search's report numbers them (the library's are indices)
        held = fit.validation_experiments
        found["validation_experiments"] = numbered(held, len(data.u_train)) if held \
            else "none: one record, split in time"
        kinds = {k for costs in fit.validation_cost.values() for k in costs}
        if kinds:
            costs = pd.DataFrame({kind: [fit.validation_cost[j].get(kind, float("nan"))
                                         for j in range(model.n_outputs_)]
                                  for kind in sorted(kinds, key=["linear", "offset", "all",
                                                                 "continuous",
                                                                 "clustered"].index)},
                                 index=[data.label(y) for y in data.y_names])
            found["candidates"] = dg.MetadataValue.md(
                "Held-out free-run MSE of each candidate structure (in the output's unit "
                "squared):\n\n" + costs.to_markdown(floatfmt=".4g"))
    report = getattr(model, "structure_search_", None)
    if report is not None:
        context.log.info(f"structure search{' (reused, not run again)' if reused else ''}: "
                         f"{report.n_candidates} candidates measured in "
                         f"{report.seconds:.1f} s. {report.choice}")
        # the rows that decided, without the row numbers (the CSV has none), missing
        # errors (a skipped candidate) shown as a dash
        rows = report.summary().rename(columns={"validation_nrmse": "held-out NRMSE",
                                                "seconds": "elapsed (s)"})
        rows["held-out NRMSE"] = rows["held-out NRMSE"].astype(object).where(
            rows["held-out NRMSE"].notna(), None)
        stop = " (its time limit: stopped there)" if report.time_limited else \
            " (its budget: stopped there)" if report.budget_spent else ""
        found |= {"structure chosen": dg.MetadataValue.md(report.choice),
                  "structure search": dg.MetadataValue.md(
                      f"{report.n_candidates} candidates measured in {report.seconds:.1f} s"
                      f"{stop}; those "
                      f"kept, refined and chosen (every candidate is in the MLflow run's "
                      f"`structure_search.csv`):\n\n"
                      f"{rows.to_markdown(index=False, floatfmt='.4g', missingval='–')}")}
    figures = model_figures(inputs, model, data, title)
    params, params_note = shown_params(model)
    return dg.Output(model, output_name="pwa_model", metadata=rounded({
        # what the model is, first: the search's verdict (e.g. the linear model kept) and
        # its outputs' limits, the line of its leaderboard row
        **({} if report is None else {"model": model_note(model)}),
        "n_submodels": model.n_submodels_,
        **({} if (note := switching_note(model)) is None else {"switching": note}),
        "output_groups": len(model.groups_),
        # n_submodels counts the modes of the model as one map (eq. 1): the product of the
        # groups' regions, which the figures and the structures show group by group
        **({"regions per output group": _regions_per_group(model)}
           if len(model.groups_) > 1 else {}),
        "fit": REUSED if reused else "fitted",
        "fit_seconds": sum(model.timings_.values()),
        "steps_from_cache": "all (the fitted model reused)" if reused
        else ", ".join(sorted(cached)) or "none",
        "structure per output": markdown(structure.set_index("output")),
        # the structures, the search's report and the limits name the channels y1…, u1…
        **({"names in the structures": names} if (names := model_names(data)) else {}),
        **found,
        "resolved parameters": dg.MetadataValue.md(
            "\n\n".join(filter(None, [params_note, params_table(params).to_markdown(
                floatfmt=".4g")]))),
        **truth_metadata(model, data), "figures_from_cache": memory.hits > 0,
        **{name: dg.MetadataValue.md(text) for name, text in figures.items()}}))


def model_figure_inputs(model: PWARX, data: Dataset, phi: np.ndarray, key: tuple[str, str]
                        ) -> dict:
    """The numbers of the PWA model's switching figure on the first held-out experiment
    (with the ground truth when comparable) and of its regions figure on the training
    regressors ``phi`` (at the model's lags): what ``pwa_model`` caches, keyed by ``key``
    (``prediction_key``) in place of the model, the data and ``phi``. No title or unit is
    cached: the sets sharing an entry each draw their own (``model_figures``)."""
    truth = ground_truth(model, data)
    one = len(model.groups_) == 1
    switching = SwitchingDisplay.compute(
        model, data.u_test[0], data.y_test[0], y_names=data.y_names, u_names=data.u_names,
        true_modes=truth.modes_test[0] if truth and one else None,
        true_thetas=truth.thetas if truth and one else None)
    steps, _ = shown_steps(model)
    labels = steps["submodels"].labels_ if one and on_phi(model) and "submodels" in steps \
        else None
    return {"switching": switching, "regions": RegionsDisplay.compute(model, phi, labels)}


def model_figures(inputs: dict, model: PWARX, data: Dataset, title: str) -> dict[str, str]:
    """The switching and regions figures drawn from ``model_figure_inputs``, titled
    ``title`` (data set, set, method), the axes in the data's units, as Markdown images
    (``pwa_model``'s metadata)."""
    return {SWITCHING: to_markdown(inputs["switching"].plot(title).figure_),
            REGIONS: to_markdown(inputs["regions"].plot(phi_names(model, data), title,
                                                        data.units).figure_)}
