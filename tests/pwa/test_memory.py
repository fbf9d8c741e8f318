"""The memory guard: a fit that cannot fit in memory fails at once, saying what to change."""

import numpy as np
import pytest

from pwa_pipeline import PWARX, make_hure_vasak
from pwa_pipeline.pwa import LocalLeastSquares, memory
from pwa_pipeline.pwa.memory import FitMemoryError, available_memory, fit_memory


def test_a_fit_beyond_the_available_memory_fails_before_any_step(monkeypatch):
    data = make_hure_vasak(n_samples=600, snr_db=None, seed=0)  # 599 rows, d = 4, m = 2
    need = fit_memory(599, 4, 2, PWARX.default().step_objects())
    # the largest step fits, not with the regressors (599 × (4 + 2) floats) on top
    monkeypatch.setattr(memory, "available_memory", lambda: max(need.values()))

    def never(*args, **kwargs):
        raise AssertionError("a step ran")

    monkeypatch.setattr(LocalLeastSquares, "fit", never)
    with pytest.raises(FitMemoryError, match=r"needs an estimated \d+\.\d\d GiB") as err:
        PWARX().fit(data.u_train[0], data.y_train[0])
    assert "available" in str(err.value) and "lower " in str(err.value)
    assert isinstance(err.value, MemoryError)


def test_the_message_names_the_setting_of_the_largest_step(monkeypatch):
    monkeypatch.setattr(memory, "available_memory", lambda: 1)
    est = PWARX.paper(2, 2, n_rho=61, eps=8.0, min_pts=22).set_params(
        clustering__embedding="literal")  # every local model clustered, 864 dimensions
    need = fit_memory(10**6, 24, 6, est.step_objects())
    assert max(need, key=need.get) == "clustering"
    with pytest.raises(FitMemoryError, match="clustering__max_clustered"):
        memory.check_fit_memory(10**6, 24, 6, est.step_objects())
    default = PWARX.default(2, 2).set_params(regions__max_rows=None, local_models__n_rho=200,
                                             local_models__max_sets=None)
    need = fit_memory(10**6, 24, 6, default.step_objects())
    assert max(need, key=need.get) == "local_models"
    with pytest.raises(FitMemoryError, match="local_models__n_rho"):
        memory.check_fit_memory(10**6, 24, 6, default.step_objects())


def test_enough_memory_fits_as_usual(monkeypatch):
    data = make_hure_vasak(n_samples=600, snr_db=None, seed=0)
    usual = PWARX().fit(data.u_train[0], data.y_train[0])
    need = max(fit_memory(599, 4, 2, PWARX.default().step_objects()).values()) + 599 * 6 * 8
    monkeypatch.setattr(memory, "available_memory", lambda: need)  # just enough
    np.testing.assert_array_equal(PWARX().fit(data.u_train[0], data.y_train[0]).thetas_, usual.thetas_)


def test_estimates_grow_with_the_record_and_the_machine_reports_memory():
    small = fit_memory(10_000, 24, 6, PWARX.default().step_objects())
    large = fit_memory(100_000, 24, 6, PWARX.default().step_objects())
    assert all(large[k] > small[k] for k in small)
    avail = available_memory()
    assert avail is None or avail > 0
    assert np.isfinite(sum(small.values()))


def test_the_search_counts_only_the_local_sets_estimated():
    every = PWARX.default(2, 2).set_params(local_models__max_sets=None).step_objects()
    some = PWARX.default(2, 2).step_objects()  # at most 5,000 local models
    assert fit_memory(4_000, 24, 6, some) == fit_memory(4_000, 24, 6, every)
    saved = (fit_memory(400_000, 24, 6, every)["local_models"]
             - fit_memory(400_000, 24, 6, some)["local_models"])
    assert saved == (400_000 - 5_000) * 6 * 72 * 12  # the candidates of the rows not searched


def test_step_5_refines_at_most_max_rows_rows_however_long_the_record():
    steps = PWARX.default().step_objects()
    kept = {n: fit_memory(n, 4, 1, steps)["submodels"] - fit_memory(n, 4, 1, steps)["regions"]
            for n in (500_000, 5_000_000, 50_000_000)}  # step 5's own arrays, beyond kept
    assert kept[500_000] == kept[5_000_000] == kept[50_000_000] > 0
    every = PWARX.default().set_params(submodels__max_rows=None).step_objects()
    need = fit_memory(5_000_000, 4, 1, every)
    assert need["submodels"] - need["regions"] > 9.9 * kept[500_000]  # every row: 10 times
    with pytest.raises(FitMemoryError, match="submodels__max_rows"):
        memory.check_fit_memory(5_000_000, 4, 1, every, base=available_memory() or 2**50)


def test_step_5_on_a_subset_keeps_the_clustered_rows_and_leaves_the_others_out():
    data = make_hure_vasak(n_samples=1500, snr_db=None, seed=0)
    model = PWARX(1, 1).set_params(submodels__max_rows=1200).fit(data.u_train[0],
                                                               data.y_train[0])
    subs, clusters = model.steps_["submodels"], model.steps_["clustering"]
    assert model.n_submodels_ == 4
    kept = subs.labels_ >= 0
    assert kept.sum() == 1200 and kept[clusters.labels_ >= 0].all()
    assert (subs.weights_[~kept] == 0).all() and (subs.weights_[kept] > 0).any()
    rows = subs.rows(clusters.labels_)
    np.testing.assert_array_equal(rows, np.flatnonzero(kept))
    assert subs.rows(clusters.labels_[:1200]) is None  # up to max_rows: every row
