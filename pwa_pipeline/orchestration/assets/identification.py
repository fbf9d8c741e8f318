"""The paper's chain as assets: configuration, raw_benchmark → regressors → local_models →
clusters → sub_models → svm_regions → output_error_refinement (a no-op unless the set asks
for it) → pwa_model; a set with a structure of its own is fitted whole by ``pwa_model``.

The chain is one multi-asset (``pwa_chain``): each step asset is drawn depending on the step
before it alone, so the graph reads as the paper's chain, while a step reads what it needs
of every earlier one (the clustering needs φ, the sub-models the local models) in memory.
Selecting some of its assets fits the steps before them again, unstored, the costly ones
from the store's caches."""

import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import dagster as dg
import pandas as pd
from sklearn.base import clone

from ..._validation import as_experiments
from ...config import Configuration
from ...datasets import Dataset
from ...methods import METHODS
from ...pwa import PWARX, STEPS
from ...pwa.arx import training_range
from ...pwa.search.search import SEARCH_LOG
from ...regressors import build_regressors
from ..caches import SignedMemory, cache_key, load_or_compute
from ..checks import (
    CLUSTER_CHECKS,
    SUB_MODEL_CHECKS,
    cluster_results,
    not_applicable,
    sub_model_results,
)
from ..figures import (
    draw_regions,
    draw_structured_switching,
    draw_switching,
    figures_fingerprint,
    parameter_clusters_figure,
    region_slice,
    structured_switching_inputs,
    switching_inputs,
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
    figure_context,
    ground_truth,
    phi_names,
    prediction_key,
    truth_metadata,
)

GROUP = "identification"
#: The assets of the PWA chain, in the paper's order: each is drawn depending on the one
#: before it alone (the steps read what they need of the earlier ones inside the chain).
CHAIN = ("regressors", "local_models", "clusters", "sub_models", "svm_regions",
         "output_error_refinement", "pwa_model")
#: The asset holding each fitted step of ``pwa_pipeline.pwa.STEPS``, and the refinement.
STEP_ASSETS = {**dict(zip(STEPS, CHAIN[1:5], strict=True)),
               "refinement": "output_error_refinement"}
#: Why the step assets hold nothing for a set with a structure of its own.
STRUCTURED_SKIP = ("not fitted: the set has a structure of its own or searches one (form, "
                   "outputs, scheduling, or preset auto), which pwa_model fits whole")
_DESCRIPTIONS = {
    "regressors": "φ(k) and y(k) of the training experiments (eq. 2–3), never spanning two "
                  "of them.",
    "local_models": "θ_k of the local sets of n_ρ neighbours (eq. 6–7; by default of at most "
                    "5,000 samples, `local_models.max_sets`), the fitted `local_models` "
                    "step; cached across sets whose later steps alone differ. Empty for a "
                    "set with a structure of its own (its steps are fitted per output group "
                    "inside `pwa_model`).",
    "clusters": "Extended DBSCAN on the Vθ distance of the local models (eq. 8–10), the "
                "fitted `clustering` step, with the local models drawn by cluster. Its "
                "noise check stops the chain when most local models are noise.",
    "sub_models": "One parameter matrix θ_i per cluster (step 5), the fitted `submodels` "
                  "step; its steps 2–4 are cached across sets whose clusterings consolidate "
                  "alike (`cache_sub_models`).",
    "svm_regions": "Regions H_i from a multi-class linear SVM on φ (step 6), the fitted "
                   "`regions` step, with its hyperplanes.",
    "output_error_refinement": "θ_i refined to minimise the free-run error on the training "
                               "experiments, regions kept (the fitted `refinement` step); "
                               "empty when the set configures no refinement.",
    "pwa_model": "The fitted PWARX model, joined from the steps above (or, for a set with a "
                 "structure of its own, fitted whole here); what `pwa_scores` scores and "
                 "MLflow registers. Its page shows its resolved parameters and two figure "
                 "entries: *switching*, the estimated region of each sample of the first "
                 "held-out experiment (for a structured set, each output's own region), and "
                 "*regions*, the regions in the 2-D slice of φ where they differ most (a "
                 "structured set's entry says why it has no such figure). The figures' "
                 "numbers are cached by what the model predicts with (`cache_scores`); each "
                 "set draws them titled with its own name.",
}


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


def _skipped(context: dg.AssetExecutionContext, asset: str) -> dg.Output:
    """The empty output of a step asset of a structured set, said once in the log (by the
    first step) for all four."""
    if asset == "local_models":
        context.log.info(f"local_models, clusters, sub_models, svm_regions: {STRUCTURED_SKIP}")
    return dg.Output(None, output_name=asset, metadata={"skipped": STRUCTURED_SKIP,
                                                         "seconds": 0.0})


def identification_assets(partitions_def) -> list:
    part = dict(partitions_def=partitions_def, group_name="data")

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
            "inputs": ", ".join(map(data.label, data.u_names)),
            "outputs": ", ".join(map(data.label, data.y_names)),
            "digest": data.digest,  # (computed once: stored with the data set)
        })
        return data

    kinds = {"regressors": "numpy", "sub_models": "numpy", "output_error_refinement": "scipy"}
    previous = {"regressors": {dg.AssetKey("configuration"), dg.AssetKey("raw_benchmark")},
                **{b: {dg.AssetKey(a)} for a, b in zip(CHAIN, CHAIN[1:])}}

    @dg.multi_asset(
        name="pwa_chain", partitions_def=partitions_def, can_subset=True,
        outs={name: dg.AssetOut(group_name="models" if name == "pwa_model" else GROUP,
                                kinds={kinds.get(name, "scikit-learn")}, is_required=False,
                                description=_DESCRIPTIONS[name]) for name in CHAIN},
        internal_asset_deps=previous, check_specs=[*CLUSTER_CHECKS, *SUB_MODEL_CHECKS])
    def pwa_chain(context: dg.AssetExecutionContext, settings: PipelineSettings,
                  configuration: Configuration, raw_benchmark: Dataset):
        """The paper's chain, one asset per step (see ``CHAIN``): the selected ones
        are stored, each as soon as it is fitted, and the steps before them are fitted
        again in memory (the local models and sub-models from their caches)."""
        selected = {key.to_user_string() for key in context.selected_asset_keys}
        checks = context.selected_asset_check_keys
        last = max(CHAIN.index(name) for name in selected)
        run = _ChainRun(context, settings, configuration, raw_benchmark)
        for name in CHAIN[:last + 1]:
            for event in _STEPS[name](run):
                if isinstance(event, dg.Output):
                    run.fitted[name] = event.value
                    if "seconds" in event.metadata:
                        run.seconds[name] = event.metadata["seconds"].value
                    if name in selected:
                        yield event
                elif dg.AssetCheckKey(event.asset_key, event.check_name) in checks:
                    yield event
                    if event.check_name == "noise_share_below_limit" and not event.passed:
                        return  # (a blocking check: the steps after it are not fitted)

    return [configuration, raw_benchmark, pwa_chain]


@dataclass
class _ChainRun:
    """What the steps of one run of the chain share: its context and inputs, the values
    fitted so far (by asset) and their seconds."""

    context: dg.AssetExecutionContext
    settings: PipelineSettings
    configuration: Configuration
    data: Dataset
    fitted: dict = field(default_factory=dict)
    seconds: dict = field(default_factory=dict)

    @property
    def partition(self) -> str:
        return str(self.context.partition_key)


def _regressors(run: _ChainRun):
    pwa = run.configuration.pwa
    reg = build_regressors(as_experiments(run.data.u_train, run.data.y_train), pwa.na,
                           pwa.nb, pwa.affine)
    yield dg.Output(reg, output_name="regressors", metadata={
        "rows": reg.phi.shape[0], "d": reg.phi.shape[1],
        "regressors": ", ".join(phi_names(pwa, run.data))})


def _local_models(run: _ChainRun):
    if run.configuration.pwa.structured:
        yield _skipped(run.context, "local_models")
        return
    regressors = run.fitted["regressors"]
    step = run.configuration.pwa.steps()["local_models"]
    t0 = time.perf_counter()
    key = cache_key(regressors.phi, regressors.target, step=type(step).__name__,
                    **step.get_params())
    root = run.settings.cache_root()
    path = inside(root, "local_models", f"{key}.pkl")
    local, cached = load_or_compute(
        path, root, lambda: run.configuration.pwa.fit_step("local_models", regressors),
        run.context.log.warning, "local-model cache entry", run.settings.cache_local_models)
    run.context.log.info(
        f"local models: {local.n_estimated_:,} of {local.estimated_.size:,} local sets of "
        f"n_rho = {local.n_rho_}{' from the cache' if cached else ''} "
        f"({local.n_degenerate_:,} degenerate) in {time.perf_counter() - t0:.1f} s")
    yield dg.Output(local, output_name="local_models", metadata=rounded({
        "n_rho": local.n_rho_, "from_cache": cached,
        "estimated_local_sets": local.n_estimated_,
        "degenerate_local_sets": local.n_degenerate_, "seconds": time.perf_counter() - t0,
        "cache_key": key}))


def _clusters(run: _ChainRun):
    if run.configuration.pwa.structured:
        yield _skipped(run.context, "clusters")
        yield from not_applicable(CLUSTER_CHECKS, run.partition, STRUCTURED_SKIP)
        return
    regressors, local_models = run.fitted["regressors"], run.fitted["local_models"]
    t0 = time.perf_counter()
    step = run.configuration.pwa.fit_step("clustering", regressors, local_models=local_models)
    run.context.log.info(f"clusters: {step.n_clusters_} with eps = {step.eps_:.4g}, "
                         f"MinPts = {step.min_pts_}, noise {step.noise_share_:.1%}, in "
                         f"{time.perf_counter() - t0:.1f} s")
    figure = parameter_clusters_figure(local_models, step, regressors.target,
                                       context=figure_context(run.partition,
                                                              METHODS["pwa"].label))
    yield dg.Output(step, output_name="clusters", metadata=rounded({
        "n_clusters": step.n_clusters_, "eps": step.eps_, "eps_from_data": step.eps_auto_,
        "min_pts": step.min_pts_, "noise_share": step.noise_share_,
        "seconds": time.perf_counter() - t0,
        "local models by cluster": dg.MetadataValue.md(to_markdown(figure))}))
    yield from cluster_results(step, run.partition)


def _sub_models(run: _ChainRun):
    if run.configuration.pwa.structured:
        yield _skipped(run.context, "sub_models")
        yield from not_applicable(SUB_MODEL_CHECKS, run.partition, STRUCTURED_SKIP)
        return
    t0 = time.perf_counter()
    pwa = run.configuration.pwa
    step = pwa.steps()["submodels"]
    params = step.get_params()
    memory = None
    if run.settings.cache_sub_models and "memory" in params and params["memory"] is None:
        memory = SignedMemory(run.settings.cache_root(), "sub_models",
                              warn=run.context.log.warning)
        pwa = clone(pwa).set_params(submodels=clone(step).set_params(memory=memory))
    step = pwa.fit_step("submodels", run.fitted["regressors"],
                        local_models=run.fitted["local_models"],
                        clustering=run.fitted["clusters"])
    cached = memory is not None and memory.hits > 0
    if memory is not None:
        step.set_params(memory=None)  # the stored step is the configured one
    run.context.log.info(f"sub-models: {step.n_submodels_} ({step.n_merged_} merges, "
                         f"{step.n_iter_} sweeps"
                         f"{', steps 2-4 from the cache' if cached else ''}) in "
                         f"{time.perf_counter() - t0:.1f} s")
    table = theta_table(step.thetas_, phi_names(run.configuration.pwa, run.data),
                        run.data.y_names)
    yield dg.Output(step, output_name="sub_models", metadata=rounded({
        "n_submodels": step.n_submodels_, "merged": step.n_merged_,
        "refinement_sweeps": step.n_iter_, "from_cache": cached,
        "seconds": time.perf_counter() - t0, "parameters": markdown(table)}))
    yield from sub_model_results(step, run.partition)


def _svm_regions(run: _ChainRun):
    if run.configuration.pwa.structured:
        yield _skipped(run.context, "svm_regions")
        return
    t0 = time.perf_counter()
    step = run.configuration.pwa.fit_step("regions", run.fitted["regressors"],
                                          submodels=run.fitted["sub_models"])
    table = regions_table(step, phi_names(run.configuration.pwa, run.data))
    yield dg.Output(step, output_name="svm_regions", metadata=rounded({
        "n_regions": step.n_regions_, "seconds": time.perf_counter() - t0,
        "hyperplanes": markdown(table)}))


def _refinement(run: _ChainRun):
    pwa = run.configuration.pwa
    if pwa.refinement is None or pwa.structured:
        yield dg.Output(None, output_name="output_error_refinement",
                        metadata={"refined": False, "seconds": 0.0})
        return
    fitted = run.fitted
    model = clone(pwa).assemble(fitted["regressors"], local_models=fitted["local_models"],
                                clustering=fitted["clusters"], submodels=fitted["sub_models"],
                                regions=fitted["svm_regions"])
    step = model.fit_refinement(as_experiments(run.data.u_train, run.data.y_train))
    run.context.log.info(f"refinement: training free-run MSE {step.cost_start_:.4g} → "
                         f"{step.cost_:.4g} in {step.n_iter_} steps, {step.seconds_:.1f} s "
                         f"({step.stop_})")
    yield dg.Output(step, output_name="output_error_refinement", metadata=rounded({
        "refined": True, "cost_start": step.cost_start_, "cost": step.cost_,
        "iterations": step.n_iter_, "stop": step.stop_, "seconds": step.seconds_}))


def _pwa_model(run: _ChainRun):
    if run.configuration.pwa.structured:
        yield structured_model(run.context, run.configuration, run.data,
                               figure_context(run.partition, METHODS["pwa"].label))
        return
    # the training range from the experiments, as fit records it (φ's rows miss some
    # samples of each experiment: PWARX.assemble): the model's data envelope
    model = clone(run.configuration.pwa).assemble(
        run.fitted["regressors"], local_models=run.fitted["local_models"],
        clustering=run.fitted["clusters"], submodels=run.fitted["sub_models"],
        regions=run.fitted["svm_regions"], refinement=run.fitted["output_error_refinement"],
        signal_range=training_range(as_experiments(run.data.u_train, run.data.y_train)))
    model.timings_ = {step: run.seconds[asset] for step, asset in STEP_ASSETS.items()}
    # the figures' numbers are cached (shared by the sets that end in this model), the
    # figures drawn from them here, titled with this partition's set
    memory = SignedMemory(run.settings.cache_root(), "model_figures",
                          warn=run.context.log.warning, salt=figures_fingerprint())
    compute = memory.cache(model_figure_inputs, ignore=["model", "data", "phi"]) \
        if run.settings.cache_scores else model_figure_inputs
    inputs = compute(model, run.data, run.fitted["regressors"].phi, model.labels_,
                     prediction_key(model, run.data))
    figures = model_figures(inputs, model, run.data,
                            figure_context(run.partition, METHODS["pwa"].label))
    yield dg.Output(model, output_name="pwa_model", metadata=rounded({
        "n_submodels": model.n_submodels_, "fit_seconds": sum(model.timings_.values()),
        "resolved parameters": markdown(params_table(model.resolved_params())),
        **truth_metadata(model, run.data), "figures_from_cache": memory.hits > 0,
        **{name: dg.MetadataValue.md(text) for name, text in figures.items()}}))


_STEPS = {"regressors": _regressors, "local_models": _local_models, "clusters": _clusters,
          "sub_models": _sub_models, "svm_regions": _svm_regions,
          "output_error_refinement": _refinement, "pwa_model": _pwa_model}


def structured_model(context: dg.AssetExecutionContext, configuration: Configuration,
                     data: Dataset, title: str = "") -> dg.Output:
    """Fit the structured PWARX model on the training experiments, with the metadata that
    says which training experiments (indices from 0) were held out to choose its structure
    and refinement iterate, and each candidate's held-out free-run error, one narrow table
    (a column per candidate, named as the structures are). Its figure is the switching
    figure of each output's own regions on the first held-out experiment
    (``draw_structured_switching``), titled ``title`` (data set, set, method); a regions
    figure is not drawn and the metadata says why: each output has its own regions, over
    its own regressors, so no one slice of φ shows them."""
    t0 = time.perf_counter()
    if (search := configuration.pwa.search) is not None:
        context.log.info(f"structure search: orders up to ({configuration.pwa.na}, "
                         f"{configuration.pwa.nb}), at most {search.max_seconds:g} s "
                         f"(search.max_seconds)")
    with forwarded(SEARCH_LOG, context.log):  # the search's progress, a line per stage
        model = clone(configuration.pwa).fit(data.u_train, data.y_train)
    fit = model.structure_fit_
    table = pd.DataFrame({"output": [data.label(y) for y in data.y_names],
                          "structure": model.structure_.structures,
                          "regions": model.structure_.n_regions})
    report = getattr(model, "structure_search_", None)
    if report is not None:  # what the search chose, per output, in place of the kind alone
        table["structure"] = report.structures
    kinds = {k for costs in fit.validation_cost.values() for k in costs}
    for kind in sorted(kinds, key=["linear", "offset", "all", "clustered"].index):
        table[kind] = [fit.validation_cost[j].get(kind, float("nan"))
                       for j in range(len(data.y_names))]
    seconds = time.perf_counter() - t0
    shapes = zip(data.y_names, model.structure_.structures, model.structure_.n_regions,
                 strict=True)
    context.log.info("structured PWA model: " + ", ".join(
        f"{data.label(y)} {s} ({n} region{'s' if n > 1 else ''})" for y, s, n in shapes)
        + f" in {seconds:.1f} s")
    if report is not None:
        context.log.info(f"structure search: {len(report.table)} candidates in "
                         f"{report.seconds:.1f} s. {report.choice}")
    switching = structured_switching_inputs(model, data.u_test[0], data.y_test[0],
                                            data.y_names, data.u_names)
    structure = markdown(table.set_index("output"))
    if kinds:
        structure = dg.MetadataValue.md(
            "Held-out free-run MSE of each candidate structure (in the output's unit "
            "squared); the kept one is under *structure*.\n\n" + structure.value)
    found = {}
    if report is not None:
        # the rows that decided, without the row numbers (the CSV has none), missing
        # errors (a skipped candidate) shown as a dash
        rows = report.summary().rename(columns={"validation_nrmse": "held-out NRMSE",
                                                "seconds": "elapsed (s)"})
        rows["held-out NRMSE"] = rows["held-out NRMSE"].astype(object).where(
            rows["held-out NRMSE"].notna(), None)
        found = {"structure chosen": dg.MetadataValue.md(report.choice),
                 "structure search": dg.MetadataValue.md(
                     f"{len(report.table)} candidates tried in {report.seconds:.1f} s; those "
                     f"kept, refined and chosen (every candidate is in the MLflow run's "
                     f"`structure_search.csv`):\n\n"
                     f"{rows.to_markdown(index=False, floatfmt='.4g', missingval='–')}")}
    held_out = ", ".join(map(str, fit.validation_experiments)) or (
        "none: one record, split in time" if report is not None else "none")
    return dg.Output(model, output_name="pwa_model", metadata=rounded({
        "n_submodels": model.n_submodels_, "fit_seconds": seconds,
        "validation_experiments": held_out,
        **found,
        "structure per output": structure,
        "resolved parameters": markdown(params_table(model.resolved_params())),
        SWITCHING: dg.MetadataValue.md(to_markdown(
            draw_structured_switching(switching, data.y_names, title))),
        REGIONS: dg.MetadataValue.md(STRUCTURED_REGIONS)}))


#: The figure keys of the ``pwa_model`` page.
SWITCHING, REGIONS = "switching (first held-out experiment)", "regions"
#: The ``regions`` entry of a structured set's ``pwa_model`` page, in place of the figure.
STRUCTURED_REGIONS = (
    "No regions figure for a model with a structure of its own: each output has its own "
    "regions (the sign of its scheduling variable, or clusters of its own regressors), over "
    "its own regressors, so no single 2-D slice of φ shows them. The switching figure above "
    "shows each output's region over time; *structure per output* lists them.")


def model_figure_inputs(model: PWARX, data: Dataset, phi, labels, key: tuple[str, str]
                        ) -> dict:
    """The numbers of the PWA model's switching and regions figures (``switching_inputs``
    on the first held-out experiment, with the ground truth when comparable, and
    ``region_slice``): what ``pwa_model`` caches, keyed by ``key`` (``prediction_key``) and
    the rows' ``labels`` (the regions figure colours the rows by them) in place of the
    model, the data and ``phi`` (the data's regressors at the model's orders). No title or
    unit is cached: the sets sharing an entry each draw their own (``model_figures``)."""
    truth = ground_truth(model, data)
    return {"switching": switching_inputs(
                model, data.u_test[0], data.y_test[0],
                true_modes=truth.modes_test[0] if truth else None,
                true_thetas=truth.thetas if truth else None),
            "regions": region_slice(model, phi)}


def model_figures(inputs: dict, model: PWARX, data: Dataset, title: str) -> dict[str, str]:
    """The switching and regions figures drawn from ``model_figure_inputs``, titled
    ``title`` (data set, set, method), the axes in the data's units, as Markdown images
    (``pwa_model``'s metadata)."""
    return {SWITCHING: to_markdown(draw_switching(inputs["switching"], title)),
            REGIONS: to_markdown(draw_regions(inputs["regions"], phi_names(model, data), title,
                                              data.units))}
