"""Step 5 on small hand-built cases: merging, splitting, refinement, cluster centres."""

import numpy as np
import pytest

from pwa_pipeline import PWARX
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.pwa import DBSCANClustering, LocalLeastSquares, RefinedSubModels, SVMRegions
from pwa_pipeline.pwa.submodels import (least_squares, merge_indistinguishable, refine, refit,
                                       separable, split_gain)

SIGMA = 0.05


def _two_modes(gap: float, n: int = 1200, seed: int = 0):
    """y = θ_iᵀ[x1, x2, 1] + e, mode 1 where x1 > 0; the affine terms differ by ``gap`` noise
    standard deviations, so the predictions of the two modes differ by exactly that."""
    rng = np.random.default_rng(seed)
    phi = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.ones(n)])
    mode = (phi[:, 0] > 0).astype(int)
    thetas = np.array([[[0.5], [1.0], [0.0]], [[0.5], [1.0], [gap * SIGMA]]])
    y = np.einsum("nd,ndm->nm", phi, thetas[mode]) + SIGMA * rng.normal(size=(n, 1))
    return phi, y, mode, thetas


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


def test_refinement_recovers_from_a_wrong_split():
    phi, y, mode, thetas = _two_modes(gap=40.0)
    wrong = (phi[:, 0] > 0.5).astype(int)  # a quarter of the rows on the wrong side
    assert np.mean(wrong == mode) < 0.8
    est, labels, margin, sweeps = refine(phi, y, wrong, min_size=5, n_iter=20,
                                         regions=SVMRegions(C=10.0))
    # labels are renumbered by size; match them to the true modes first
    flip = np.mean(labels == mode) < 0.5
    labels = 1 - labels if flip else labels
    est = est[::-1] if flip else est
    assert np.mean(labels == mode) > 0.99 and sweeps >= 2
    np.testing.assert_allclose(est, thetas, atol=0.05)  # a wrong split errs by ~1
    assert margin.shape == (len(y),) and np.median(margin) > 4


def test_paper_sub_models_are_the_cluster_means(sim_30db):
    model = HParamsFile().configuration("paper", "hure_vasak").pwa.fit(sim_30db.u, sim_30db.y)
    theta, labels = model.local_models_.theta_, model.clustering_.labels_
    assert model.n_submodels_ == labels.max() + 1 >= 2
    for i in range(model.n_submodels_):
        members = theta[labels == i]
        np.testing.assert_allclose(model.thetas_[i], members.sum(axis=0) / len(members),
                                   rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(model.labels_, labels)


def test_default_sub_models_are_refitted_on_their_rows(sim_30db, default_30db):
    """Step 5's θ_i are least squares on their rows; the model's are step 6's, refitted
    with the regions (ResidualRegions)."""
    model = default_30db
    phi = np.column_stack([sim_30db.y[:-1], sim_30db.u[:-1]])
    for i in range(model.n_submodels_):
        rows = model.labels_ == i
        ls = np.linalg.lstsq(phi[rows], sim_30db.y[1:][rows], rcond=None)[0]
        np.testing.assert_allclose(model.submodels_.thetas_[i], ls, atol=1e-10)
    assert model.thetas_ is model.regions_.thetas_


def test_merging_many_clusters_tests_few_pairs(monkeypatch):
    """Separability is asked for pairs closer than the first mergeable one, once per pair of
    row sets: linear in the clusters (testing every pair at every merge was cubic)."""
    import pwa_pipeline.pwa.submodels as submodels

    phi, y, mode, _ = _two_modes(gap=3.0, n=3000)
    rng = np.random.default_rng(5)
    labels = mode * 15 + rng.integers(0, 15, len(y))  # each mode split into 15 copies
    calls = []
    real = submodels.separable
    monkeypatch.setattr(submodels, "separable", lambda *a: calls.append(1) or real(*a))
    merged, n = merge_indistinguishable(phi, y, labels, tol=1.0, copy_tol=25.0,
                                        regions=SVMRegions())
    assert len(set(merged)) == 2 and n == 28
    assert len({(a, b) for a, b in zip(merged, mode, strict=True)}) == 2  # the true modes
    assert len(calls) <= 60  # the previous scan made one per pair per merge: ~4,000


def test_least_squares_equals_lstsq_well_conditioned_or_not():
    rng = np.random.default_rng(3)
    # columns of very different sizes (the normal matrix is solved after scaling them)
    phi = rng.normal(size=(2000, 6)) * np.array([1e-3, 1.0, 1e4, 5.0, 1.0, 1.0])
    phi[:, 4] += 3 * phi[:, 5]  # correlated, still well conditioned
    target = phi @ rng.normal(size=(6, 2)) + 0.1 * rng.normal(size=(2000, 2))
    ref = np.linalg.lstsq(phi, target, rcond=None)[0]
    # each θ_j times its column's size: what a coefficient contributes to the prediction
    size = np.sqrt((phi**2).mean(axis=0))[:, None]
    got = least_squares(phi, target)
    np.testing.assert_allclose(got * size, ref * size, rtol=0,
                               atol=1e-10 * np.abs(ref * size).max())
    # refit: every row under one label; rows by label, −1 left out, a label with < d rows NaN
    thetas = refit(phi, target, np.zeros(2000, int), 1)
    np.testing.assert_allclose(thetas[0] * size, ref * size, rtol=0,
                               atol=1e-10 * np.abs(ref * size).max())
    labels = np.zeros(2000, int)
    labels[::7], labels[-300:], labels[:4], labels[4:50] = 1, 2, 3, -1
    thetas = refit(phi, target, labels, 4)
    for i in range(3):
        rows = labels == i
        one = np.linalg.lstsq(phi[rows], target[rows], rcond=None)[0]
        np.testing.assert_allclose(thetas[i] * size, one * size, rtol=0,
                                   atol=1e-10 * np.abs(one * size).max())
    assert np.isnan(thetas[3]).all()
    # rank deficient (a repeated column) and a zero column: lstsq's minimum-norm solution
    for bad in (np.column_stack([phi, phi[:, 1]]), np.column_stack([phi, np.zeros(2000)])):
        ref = np.linalg.lstsq(bad, target, rcond=None)[0]
        np.testing.assert_allclose(least_squares(bad, target), ref, rtol=1e-12, atol=1e-12)


def _close_modes(n=1500, seed=0, gap=0.15, sigma=0.05):
    """y(k) = a·y(k−1) + u(k−1), a = 0.5 where y(k−1) ≤ 0.2, 0.5 + gap above: the modes'
    predictions differ by 1–3 noise standard deviations, their rows split by a hyperplane."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, (n, 1))
    y = np.zeros((n, 1))
    mode = np.zeros(n, int)
    thetas = np.array([[[0.5], [1.0]], [[0.5 + gap], [1.0]]])
    for k in range(1, n):
        mode[k] = int(y[k - 1, 0] > 0.2)
        y[k] = np.r_[y[k - 1], u[k - 1]] @ thetas[mode[k]]
    return u, y + sigma * rng.normal(size=y.shape), thetas, mode


def test_modes_a_few_noise_sigmas_apart_but_separable_stay_apart():
    """DBSCAN merges the two; the split search (split_gain) parts them again."""
    u, y, thetas, _ = _close_modes()
    model = PWARX(na=1, nb=1).fit(u, y)
    assert model.n_submodels_ == 2 and model.submodels_.n_split_ >= 1
    np.testing.assert_allclose(np.sort(model.thetas_, axis=0), thetas, atol=0.03)
    merged = PWARX.default(1, 1).set_params(submodels__split_tol=None).fit(u, y)
    assert merged.n_submodels_ == 1


def test_split_gain_tells_two_modes_from_one():
    u, y, _, mode = _close_modes()
    phi, target, mode = np.column_stack([y[:-1], u[:-1]]), y[1:], mode[1:]
    local = LocalLeastSquares().fit(phi, target)
    gain, halves = split_gain(phi, target, local.theta_, 8, 20, SVMRegions())
    assert gain > 2
    agree = np.mean(halves == mode)
    assert max(agree, 1 - agree) > 0.88  # the halves are the two modes, up to the boundary
    one = mode == 0
    gain_one, _ = split_gain(phi[one], target[one], local.theta_[one], 8, 20, SVMRegions())
    assert gain_one < 0.5


def test_a_four_percent_mode_merged_into_its_neighbour_is_found():
    """Clusters that give a 4 % mode's rows to its neighbour: step 5 splits them apart (the
    missed-mode search alone does not, as the rare rows are explained half-well)."""
    import copy

    thetas = np.array([[[0.5], [1.0]], [[-0.4], [1.0]], [[0.3], [2.0]]])
    rng = np.random.default_rng(0)
    n = 2000
    u = rng.uniform(-1, 1, (n, 1))
    y = np.zeros((n, 1))
    mode = np.zeros(n, int)
    for k in range(1, n):  # mode 2 where y(k−1) ≤ −0.8: 79 of 2000 samples
        mode[k] = 0 if y[k - 1, 0] > 0 else (1 if y[k - 1, 0] > -0.8 else 2)
        y[k] = np.r_[y[k - 1], u[k - 1]] @ thetas[mode[k]]
    y += 0.03 * rng.normal(size=y.shape)
    phi, target, mode = np.column_stack([y[:-1], u[:-1]]), y[1:], mode[1:]
    assert 0.03 < np.mean(mode == 2) < 0.05
    local = LocalLeastSquares().fit(phi, target)
    clustering = DBSCANClustering().fit(local, target)
    absorbed = copy.copy(clustering)
    absorbed.labels_ = np.where(clustering.labels_ >= 0, np.minimum(mode, 1), -1)
    found = RefinedSubModels().fit(phi, target, local, absorbed, SVMRegions())
    assert found.n_submodels_ == 3
    np.testing.assert_allclose(np.sort(found.thetas_[:, 0, 0]), [-0.4, 0.3, 0.5], atol=0.01)
    missed = RefinedSubModels(split_tol=None).fit(phi, target, local, absorbed, SVMRegions())
    assert missed.n_submodels_ == 2
