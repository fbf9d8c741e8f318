"""The baselines' fitted models (linear ARX, subspace), beside the PWA chain."""

import time

import dagster as dg
from sklearn.base import BaseEstimator, clone

from ...config import Configuration
from ...datasets import Dataset
from ...methods import Method
from ..caches import SignedMemory
from ..model_facts import constant_text
from ..reporting import (
    markdown,
    params_table,
    rounded,
)
from ..settings import PipelineSettings


def fitted_clone(estimator: BaseEstimator, u: list, y: list) -> BaseEstimator:
    """A clone of ``estimator`` fitted on the experiments ``u``, ``y`` (what the baseline
    assets cache)."""
    return clone(estimator).fit(u, y)


def baseline_model_asset(method: Method, partitions_def):
    @dg.asset(name=f"{method.name}_model", partitions_def=partitions_def, group_name="models",
              kinds={"scikit-learn"},
              description=f"The fitted {method.label} model, on the training experiments; "
                          f"cached across the sets of a data set (``cache_baselines``), "
                          f"whose baseline settings are usually the same."
                          + (" Its page says first whether it has a constant term "
                             "(`constant`): the sets' linear baselines differ in it."
                             if method.name == "linear_arx" else ""))
    def model(context: dg.AssetExecutionContext, settings: PipelineSettings,
              configuration: Configuration, raw_benchmark: Dataset) -> BaseEstimator:
        t0 = time.perf_counter()
        memory = SignedMemory(settings.cache_root(), "baselines", warn=context.log.warning)
        fit = memory.cache(fitted_clone) if settings.cache_baselines else fitted_clone
        fitted = fit(configuration.estimators[method.name], raw_benchmark.u_train,
                     raw_benchmark.y_train)
        cached = memory.hits > 0
        context.log.info(f"{method.label}: {'from the cache' if cached else 'fitted'} in "
                         f"{time.perf_counter() - t0:.1f} s")
        constant = constant_text(fitted)
        context.add_output_metadata(rounded({
            # (first: the linear baselines of two sets differ in it)
            **({"constant": constant} if constant else {}),
            "fit_seconds": time.perf_counter() - t0, "from_cache": cached,
            "resolved parameters": markdown(params_table(fitted.resolved_params()))}))
        return fitted

    return model
