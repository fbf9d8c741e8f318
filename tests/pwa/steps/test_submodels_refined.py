"""The library default's step 5 as a whole (pwa.submodels.refined.RefinedSubModels)."""

import numpy as np
import pytest
from sklearn.base import clone

from pwa_pipeline import PWARX
from pwa_pipeline.pwa import DBSCANClustering, LocalLeastSquares, RefinedSubModels, SVMRegions
from pwa_pipeline.pwa.steps.submodels import refined, split_search

from ..._submodel_cases import _close_modes, _four_percent_mode, _InOrder


def test_default_sub_models_are_refitted_on_their_rows(sim_30db, default_30db):
    """Step 5's θ_i are least squares on their rows; the model's are step 6's, refitted
    with the regions (ResidualRegions)."""
    model = default_30db
    phi = np.column_stack([sim_30db.y_train[0][:-1], sim_30db.u_train[0][:-1]])
    for i in range(model.n_submodels_):
        rows = model.steps_["submodels"].labels_ == i
        ls = np.linalg.lstsq(phi[rows], sim_30db.y_train[0][1:][rows], rcond=None)[0]
        np.testing.assert_allclose(model.steps_["submodels"].thetas_[i], ls, atol=1e-10)
    assert model.thetas_ is model.regions_.thetas_


def test_modes_a_few_noise_sigmas_apart_but_separable_stay_apart():
    """DBSCAN merges the two; the split search (split_gain) parts them again."""
    u, y, thetas, _ = _close_modes()
    model = PWARX(na=1, nb=1).fit(u, y)
    assert model.n_submodels_ == 2 and model.steps_["submodels"].n_split_ >= 1
    np.testing.assert_allclose(np.sort(model.thetas_, axis=0), thetas, atol=0.03)
    merged = PWARX.default(1, 1).set_params(submodels__split_tol=None).fit(u, y)
    assert merged.n_submodels_ == 1


def test_a_four_percent_mode_merged_into_its_neighbour_is_found():
    """Clusters that give a 4 % mode's rows to its neighbour: step 5 splits them apart (the
    missed-mode search alone does not, as the rare rows are explained half-well)."""
    phi, target, local, absorbed = _four_percent_mode()
    found = RefinedSubModels().fit(phi, target, local, absorbed, SVMRegions())
    assert found.n_submodels_ == 3
    np.testing.assert_allclose(np.sort(found.thetas_[:, 0, 0]), [-0.4, 0.3, 0.5], atol=0.01)
    missed = RefinedSubModels(split_tol=None).fit(phi, target, local, absorbed, SVMRegions())
    assert missed.n_submodels_ == 2


def test_a_row_set_is_split_searched_once_per_fit(monkeypatch):
    """Rows that come back unchanged (a missed-mode search whose clusters merged away, as on
    the robot) reuse their split search."""
    u, y, _, mode = _close_modes()
    phi, target, labels = np.column_stack([y[:-1], u[:-1]]), y[1:], np.zeros(len(y) - 1, int)
    local = LocalLeastSquares().fit(phi, target)
    calls = []
    gain = refined.split_gain
    monkeypatch.setattr(refined, "split_gain",
                        lambda phi, *a, **k: calls.append(len(phi)) or gain(phi, *a, **k))
    est, searched, split_once = RefinedSubModels(), {}, set()
    first = est._best_split(phi, target, labels, local.theta_, 8, SVMRegions(), searched,
                            split_once)
    again = est._best_split(phi, target, labels, local.theta_, 8, SVMRegions(), searched,
                            set())
    assert calls == [len(phi)] and len(searched) == 1
    np.testing.assert_array_equal(first, again)
    agree = np.mean(first == mode[1:])
    assert max(agree, 1 - agree) > 0.88  # the split found is the two modes
    # the same rows back after their split (the refinement undid it): not split again
    assert len(split_once) == 1
    assert est._best_split(phi, target, labels, local.theta_, 8, SVMRegions(), searched,
                           split_once) is None


def test_the_missed_mode_search_beside_the_split_search_changes_nothing(monkeypatch):
    """The search for missed modes runs in a second thread while the split search runs and is
    dropped when a split holds: the fit is the one that runs it afterwards, only when no
    split holds, to the last bit. Splits hold beside a search (the default), or never (a
    bar no split reaches, and the searches run)."""
    phi, target, local, absorbed = _four_percent_mode()
    searches = []
    search = refined._missed_mode_clusters
    monkeypatch.setattr(refined, "_missed_mode_clusters",
                        lambda phi, *a: searches.append(len(phi)) or search(phi, *a))
    for split_tol, dropped in ((1.0, True), (1e6, False)):
        step = RefinedSubModels(split_tol=split_tol)
        with monkeypatch.context() as m:
            m.setattr(refined, "ThreadPoolExecutor", _InOrder)
            in_order = clone(step).fit(phi, target, local, absorbed, SVMRegions())
        n_in_order = len(searches)
        beside = clone(step).fit(phi, target, local, absorbed, SVMRegions())
        n_beside = len(searches) - n_in_order
        searches.clear()
        assert (n_beside > n_in_order) == dropped and n_beside >= 1
        assert (beside.n_split_ > 0) == dropped
        for name in ("thetas_", "labels_", "weights_"):
            np.testing.assert_array_equal(getattr(beside, name), getattr(in_order, name))
        assert (beside.n_submodels_, beside.n_merged_, beside.n_iter_) == (
            in_order.n_submodels_, in_order.n_merged_, in_order.n_iter_)


def test_the_settle_tolerance_reaches_every_sweep_with_regions(monkeypatch, sim_30db):
    """RefinedSubModels(settle_tol=…) stops the re-assignments with the regions (steps 2–3
    and the split search) by it; those by residual alone run until no row moves."""
    calls = []
    real = refined.refine

    def spy(*args, **kwargs):
        regions = args[5] if len(args) > 5 else kwargs.get("regions")
        calls.append((regions is not None, kwargs.get("settle", 0.0)))
        return real(*args, **kwargs)

    monkeypatch.setattr(refined, "refine", spy)
    monkeypatch.setattr(split_search, "refine", spy)
    PWARX.default(1, 1).set_params(submodels__settle_tol=0.7).fit(sim_30db.u_train[0], sim_30db.y_train[0])
    with_regions = {settle for has_regions, settle in calls if has_regions}
    alone = {settle for has_regions, settle in calls if not has_regions}
    assert with_regions == {0.7} and alone == {0.0}
    assert sum(has for has, _ in calls) > 2  # the split search's refines among them


def test_steps_2_to_4_are_cached_by_their_consolidated_state(tmp_path):
    """RefinedSubModels(memory=...) fits steps 2–4 once per consolidated state (step 1's
    labels, MinPts), parameters and local models: a clustering with more noise rows that
    consolidates alike takes them from the cache; another state, MinPts, parameter or local
    models fits them again; every result is the uncached fit's, bit for bit."""
    import copy

    phi, target, local, absorbed = _four_percent_mode()
    noisier = copy.copy(absorbed)  # as at a smaller ε: some clustered rows become noise
    noisier.labels_ = absorbed.labels_.copy()
    noisier.labels_[np.flatnonzero(absorbed.labels_ >= 0)[::7]] = -1
    own = DBSCANClustering().fit(local, target)  # the modes as DBSCAN finds them
    more_pts = copy.copy(noisier)
    more_pts.min_pts_ = 100  # more than the 4 % mode's rows
    other = LocalLeastSquares().fit(phi, target * (1 + 1e-9))  # other θ_k, same parameters
    cases = ((local, absorbed, {}, 1), (local, noisier, {}, 1), (local, own, {}, 2),
             (local, more_pts, {}, 3), (local, absorbed, {"split_tol": None}, 4),
             (other, absorbed, {}, 5))
    for local_models, clustering, params, entries in cases:
        plain = RefinedSubModels(**params).fit(phi, target, local_models, clustering,
                                               SVMRegions())
        cached = clone(plain).set_params(memory=str(tmp_path)).fit(phi, target, local_models,
                                                                  clustering, SVMRegions())
        assert len(list(tmp_path.rglob("output.pkl"))) == entries
        for name in ("thetas_", "labels_", "weights_"):
            np.testing.assert_array_equal(getattr(cached, name), getattr(plain, name))
        assert [getattr(cached, a) for a in ("n_submodels_", "n_merged_", "n_iter_",
                                            "n_split_")] == [
            getattr(plain, a) for a in ("n_submodels_", "n_merged_", "n_iter_", "n_split_")]
    assert cached.memory == str(tmp_path)
    # local models of 1,500 of the samples: other local models; loaded from a pickle, the
    # same entry
    import pickle

    subset = LocalLeastSquares(max_sets=1500).fit(phi, target)
    plain = RefinedSubModels().fit(phi, target, subset, absorbed, SVMRegions())
    clone(plain).set_params(memory=str(tmp_path)).fit(phi, target, subset, absorbed,
                                                      SVMRegions())
    assert len(list(tmp_path.rglob("output.pkl"))) == 6
    restored = pickle.loads(pickle.dumps(subset, protocol=5))
    hit = clone(plain).set_params(memory=str(tmp_path)).fit(phi, target, restored, absorbed,
                                                            SVMRegions())
    assert len(list(tmp_path.rglob("output.pkl"))) == 6
    np.testing.assert_array_equal(hit.thetas_, plain.thetas_)


def test_a_memory_without_a_cache_method_is_refused_by_name():
    """RefinedSubModels(memory=...) takes None, a folder or an object with cache()."""
    from sklearn.utils._param_validation import InvalidParameterError

    phi, target, local, absorbed = _four_percent_mode()
    with pytest.raises(InvalidParameterError,
                       match="'memory' parameter of RefinedSubModels must be None, an instance "
                             "of 'str' or an object implementing 'cache'"):
        RefinedSubModels(memory=3).fit(phi, target, local, absorbed, SVMRegions())


def test_array_digest_tells_apart_values_shapes_types_and_order():
    """The digest caches key on in place of arrays (step 5's local models, the local-model
    cache's regressors, a data set's experiments)."""
    from pwa_pipeline._arrays import array_digest

    a = np.arange(12.0).reshape(3, 4)
    b = np.ones(2)
    key = array_digest(a, b)
    assert array_digest(np.asfortranarray(a), b.copy()) == key  # the same values, any layout
    assert array_digest(a.T.copy().T, b) == key
    edited = a.copy()
    edited[2, 3] += 1e-12
    others = [array_digest(edited, b), array_digest(a.reshape(4, 3), b),
              array_digest(a.view(np.int64), b), array_digest(b, a), array_digest(a)]
    assert len({key, *others}) == 1 + len(others)
