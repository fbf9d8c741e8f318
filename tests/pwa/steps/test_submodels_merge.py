"""Merging sub-models that predict alike or are copies of one mode (pwa.submodels.merge)."""

import numpy as np
import pytest

from pwa_pipeline.pwa import SVMRegions
from pwa_pipeline.pwa.steps.submodels import merge
from pwa_pipeline.pwa.steps.submodels.merge import _prediction_gaps, merge_indistinguishable, separable

from ..._submodel_cases import _two_modes


def test_a_random_split_of_one_mode_merges():
    phi, y, _, _ = _two_modes(gap=0.0)
    labels = np.random.default_rng(1).integers(0, 2, len(y))
    merged, n = merge_indistinguishable(phi, y, labels, tol=1.0, copy_tol=25.0,
                                        regions=SVMRegions())
    assert n == 1 and set(merged) == {0}


def test_copies_split_along_the_noise_merge_though_their_predictions_differ():
    phi, y, _, _ = _two_modes(gap=0.0)
    # a residual-based split: the rows above and below the one true model, as a wrong
    # assignment leaves them; their fits differ by ~1.6 σ in the constant term (stat ≈ 2.5)
    labels = (y[:, 0] > phi @ np.array([0.5, 1.0, 0.0])).astype(int)
    assert merge_indistinguishable(phi, y, labels, tol=1.0, copy_tol=None)[1] == 0
    merged, n = merge_indistinguishable(phi, y, labels, tol=1.0, copy_tol=25.0,
                                        regions=SVMRegions())
    assert n == 1 and set(merged) == {0}


def test_separable_modes_a_few_noise_deviations_apart_stay_apart():
    phi, y, mode, _ = _two_modes(gap=3.0)  # statistic ≈ 9: above tol, below copy_tol
    assert separable(phi, mode == 0, SVMRegions())
    merged, n = merge_indistinguishable(phi, y, mode, tol=1.0, copy_tol=25.0,
                                        regions=SVMRegions())
    assert n == 0 and len(set(merged)) == 2
    # the same modes merge when the tolerance says they predict alike
    assert merge_indistinguishable(phi, y, mode, tol=20.0, copy_tol=None)[1] == 1


def test_copies_need_a_region_estimator():
    phi, y, mode, _ = _two_modes(gap=3.0)
    with pytest.raises(ValueError, match="copy_tol.*needs a region estimator"):
        merge_indistinguishable(phi, y, mode, tol=1.0, copy_tol=25.0)


def test_merging_many_clusters_tests_few_pairs(monkeypatch):
    """Separability is asked for pairs closer than the first mergeable one, once per pair of
    row sets: linear in the clusters (testing every pair at every merge was cubic)."""
    phi, y, mode, _ = _two_modes(gap=3.0, n=3000)
    rng = np.random.default_rng(5)
    labels = mode * 15 + rng.integers(0, 15, len(y))  # each mode split into 15 copies
    calls = []
    real = merge.separable
    monkeypatch.setattr(merge, "separable", lambda *a: calls.append(1) or real(*a))
    merged, n = merge_indistinguishable(phi, y, labels, tol=1.0, copy_tol=25.0,
                                        regions=SVMRegions())
    assert len(set(merged)) == 2 and n == 28
    assert len({(a, b) for a, b in zip(merged, mode, strict=True)}) == 2  # the true modes
    assert len(calls) <= 60  # the previous scan made one per pair per merge: ~4,000


@pytest.mark.parametrize("entries", [1 << 22, 100], ids=["at once", "in groups"])
def test_prediction_gaps_are_the_mean_over_each_pairs_rows(entries, monkeypatch):
    # The merge statistic of every pair at once, against the pair-by-pair definition; rows
    # labelled -1 (noise) belong to no pair. Also with the predictions in groups of
    # sub-models (a bound of 100 entries: one sub-model at a time for most labels).
    monkeypatch.setattr(merge, "_GAP_ENTRIES", entries)

    rng = np.random.default_rng(4)
    phi = rng.normal(size=(300, 3))
    thetas = rng.normal(size=(5, 3, 2))
    labels = rng.integers(-1, 5, 300)
    sigma2 = np.array([0.5, 2.0])
    gaps = _prediction_gaps(phi, thetas, labels, sigma2)
    for i in range(5):
        for j in range(5):
            both = (labels == i) | (labels == j)
            diff = phi[both] @ (thetas[i] - thetas[j])
            assert gaps[i, j] == pytest.approx(np.mean((diff ** 2 / sigma2).sum(axis=1)),
                                               rel=1e-12, abs=1e-300)
