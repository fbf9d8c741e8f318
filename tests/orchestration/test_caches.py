"""Caches in the store: keyed by inputs and the core's source; bad entries recomputed."""

import pickle

import dagster as dg
import numpy as np
import pytest
from sklearn.base import clone

from pwa_pipeline.definitions import defs
from pwa_pipeline.orchestration import caches
from pwa_pipeline.orchestration.caches import SignedMemory
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.settings import PipelineSettings

from .._planted import Planted
from .._results import holding, materialization

IDENTIFICATION = ["configuration", "raw_benchmark", "regressors", "local_models"]


ALL = holding(defs.assets, ["configuration", "raw_benchmark", "pwa_model"])


@pytest.fixture()
def settings(tmp_path):
    # the fitted model's own cache off: a rerun is to reach the steps' caches
    return PipelineSettings(cache_dir=str(tmp_path / "cache"), cache_models=False)


@pytest.mark.parametrize(("asset", "partition", "fitted"), [
    ("local_models", "hure_vasak|paper", "theta_"),
    ("sub_models", "hure_vasak|default", "thetas_")])
def test_bad_cache_entries_are_recomputed_with_a_warning(tmp_path, settings, asset, partition,
                                                         fitted):
    """A planted or truncated entry of the local-model or step-5 cache is never unpickled:
    the run recomputes it, says so, and gives the same result; the next run reads it."""
    resources = {"io_manager": PartitionedFileIOManager(base_dir=str(tmp_path / "store")),
                 "settings": settings}
    instance = dg.DagsterInstance.ephemeral()
    names = IDENTIFICATION + (["clusters", "sub_models"] if asset == "sub_models" else [])
    first = dg.materialize(ALL, selection=names, partition_key=partition,
                           resources=resources, instance=instance)
    [entry] = (tmp_path / "cache" / asset).glob("*.pkl")
    reference = getattr(first.asset_value(asset), fitted)
    marker = tmp_path / "marker"
    for damage in (lambda: entry.write_bytes(pickle.dumps(Planted(marker))),
                   lambda: entry.write_bytes(entry.read_bytes()[:100])):
        damage()
        result = dg.materialize(ALL, selection=names, partition_key=partition,
                                resources=resources, instance=instance)
        meta = materialization(result, asset).metadata
        assert result.success and not meta["from_cache"].value
        logged = [e.user_message for e in instance.all_logs(result.run_id)]
        assert any(f"cache entry {entry} unusable" in m for m in logged)
        assert not marker.exists()
        np.testing.assert_array_equal(getattr(result.asset_value(asset), fitted), reference)
    again = dg.materialize(ALL, selection=names, partition_key=partition,
                           resources=resources)
    assert materialization(again, asset).metadata["from_cache"].value
    np.testing.assert_array_equal(getattr(again.asset_value(asset), fitted), reference)


def test_signed_memory_keys_results_on_the_arguments_and_the_cores_source(tmp_path,
                                                                          monkeypatch):
    """SignedMemory computes a call once per function, arguments and numerical-core source,
    and reads it back signed; a step holding it clones to the same handle."""
    import copy

    from sklearn.base import clone

    from pwa_pipeline.pwa import RefinedSubModels

    calls = []

    def scaled(a, factor=1.0):
        calls.append(factor)
        return np.asarray(a) * factor

    memory = SignedMemory(tmp_path, "m")
    cached = memory.cache(scaled)
    for factor, computed in ((1.0, 1), (1.0, 1), (2.0, 2), (1.0, 2)):
        np.testing.assert_array_equal(cached(np.arange(3.0), factor=factor),
                                      np.arange(3.0) * factor)
        assert len(calls) == computed
    assert (memory.hits, memory.misses) == (2, 2)
    np.testing.assert_array_equal(cached(np.arange(4.0)), np.arange(4.0))  # other data
    monkeypatch.setattr(caches, "core_fingerprint", lambda: "other code")
    cached(np.arange(3.0), factor=1.0)
    assert len(calls) == 4 and len(list((tmp_path / "m").glob("*.pkl"))) == 4
    salted = SignedMemory(tmp_path, "m", salt="other figures").cache(scaled)
    salted(np.arange(3.0), factor=1.0)  # the same call, another salt: computed again
    assert len(calls) == 5 and len(list((tmp_path / "m").glob("*.pkl"))) == 5
    assert copy.deepcopy(memory) is memory
    assert clone(RefinedSubModels(memory=memory)).memory is memory



def test_a_rerun_reuses_the_fitted_model_until_data_settings_or_versions_change(
        tmp_path, monkeypatch):
    """The partition's PWA model is fitted once for unchanged data, hyper-parameters and
    versions (`fit_model` says it reused it, and gives an equal model); a changed
    hyper-parameter, data set or version fits again; without `cache_models` nothing is
    reused or written. (The fit itself is a linear ARX model here, to be quick.)"""
    import dataclasses

    from pwa_pipeline import LinearARX
    from pwa_pipeline.config import BUNDLED_HPARAMS
    from pwa_pipeline.datasets import make_hure_vasak
    from pwa_pipeline.orchestration.assets import identification

    fits = []

    def fitted(context, settings, pwa, data):
        fits.append(pwa)
        return LinearARX(na=1, nb=1).fit(data.u_train, data.y_train), set()

    monkeypatch.setattr(identification, "fitted", fitted)
    settings = PipelineSettings(cache_dir=str(tmp_path / "cache"),
                                hparams_path=str(BUNDLED_HPARAMS))
    config = settings.configuration("default", "hure_vasak")
    data = make_hure_vasak(n_samples=300, seed=3)
    context = dg.build_asset_context()

    def fit(config=config, data=data, settings=settings) -> tuple:
        model, _, reused = identification.fit_model(context, settings, config, data)
        return model, reused

    (first, reused_first), (again, reused) = fit(), fit()
    assert (reused_first, reused, len(fits)) == (False, True, 1)
    np.testing.assert_array_equal(again.theta_, first.theta_)
    other = dataclasses.replace(config, estimators={  # one hyper-parameter changed
        **config.estimators, "pwa": clone(config.pwa).set_params(clustering__min_pts=9)})
    assert fit(config=other)[1] is False and len(fits) == 2
    assert fits[1].clustering.min_pts == 9
    assert fit(data=make_hure_vasak(n_samples=300, seed=4))[1] is False and len(fits) == 3
    monkeypatch.setattr(identification, "versions", lambda: "pwa-pipeline 9.9")
    assert [fit()[1] for _ in range(2)] == [False, True] and len(fits) == 4
    off = PipelineSettings(cache_dir=str(tmp_path / "off"), cache_models=False,
                           hparams_path=str(BUNDLED_HPARAMS))
    assert [fit(settings=off)[1] for _ in range(2)] == [False, False] and len(fits) == 6
    assert not (tmp_path / "off" / "models").exists()
    assert len(list((tmp_path / "cache" / "models").glob("*.pkl"))) == 4
