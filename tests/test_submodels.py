"""Step 5 on small hand-built cases: merging, splitting, refinement, cluster centres."""

import numpy as np
import pytest
from sklearn.base import clone

from pwa_pipeline import PWARX
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.pwa import DBSCANClustering, LocalLeastSquares, RefinedSubModels, SVMRegions
from pwa_pipeline.pwa.submodels import (
    _kmeans_start,
    least_squares,
    merge_indistinguishable,
    refine,
    refit,
    separable,
    split_gain,
    theta_shift,
)

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


def _four_percent_mode():
    """A 4 % mode (79 of 2000 samples) whose rows the clusters give to its neighbour: φ, y,
    the local models and those clusters."""
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
    return phi, target, local, absorbed


def test_a_four_percent_mode_merged_into_its_neighbour_is_found():
    """Clusters that give a 4 % mode's rows to its neighbour: step 5 splits them apart (the
    missed-mode search alone does not, as the rare rows are explained half-well)."""
    phi, target, local, absorbed = _four_percent_mode()
    found = RefinedSubModels().fit(phi, target, local, absorbed, SVMRegions())
    assert found.n_submodels_ == 3
    np.testing.assert_allclose(np.sort(found.thetas_[:, 0, 0]), [-0.4, 0.3, 0.5], atol=0.01)
    missed = RefinedSubModels(split_tol=None).fit(phi, target, local, absorbed, SVMRegions())
    assert missed.n_submodels_ == 2


def _curved_mode(seed: int = 1, n: int = 200):
    """One mode y = 0.5x + 0.06x² + e, σ = 0.05, φ = [x, 1]: not affine, yet no PWA split."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, n)
    phi = np.column_stack([x, np.ones(n)])
    y = (0.5 * x + 0.06 * x**2 + 0.05 * rng.normal(size=n))[:, None]
    return phi, y, LocalLeastSquares().fit(phi, y)


def test_a_slightly_curved_mode_is_not_split():
    """Two lines fit the curve better (a log-likelihood ratio of about 15) and predict
    apart by more than merge_tol, but by less than the penalty of a second sub-model and its
    hyperplane ((d·m + d + 1)·ln n ≈ 26): split_gain stays below split_tol = 1."""
    phi, y, local = _curved_mode()
    gain, halves = split_gain(phi, y, local.theta_, 8, 20, SVMRegions())
    assert 0.3 < gain < 1 and halves is not None  # finite: the halves predict apart
    clustering = DBSCANClustering().fit(local, y)
    model = RefinedSubModels().fit(phi, y, local, clustering, SVMRegions())
    assert model.n_submodels_ == 1 and model.n_split_ == 0
    lower_bar = RefinedSubModels(split_tol=0.1).fit(phi, y, local, clustering, SVMRegions())
    assert lower_bar.n_submodels_ == 2 and lower_bar.n_split_ == 1


def _wide(gap: float, n: int = 2400, d: int = 12, seed: int = 0):
    """y = θ_iᵀφ + e on φ = [10 uniform columns, 1] (σ = 0.05), mode 1 where φ_0 > 0.2, its
    θ three entries ``gap`` above mode 0's: a search on 2,000 × 12 of φ, above SCREEN_SIZE."""
    rng = np.random.default_rng(seed)
    phi = np.column_stack([rng.uniform(-1, 1, (n, d - 1)), np.ones(n)])
    mode = (phi[:, 0] > 0.2).astype(int)
    thetas = np.repeat(rng.uniform(-1, 1, (1, d, 1)), 2, axis=0)
    thetas[1, 1:4, 0] += gap
    y = np.einsum("nd,ndm->nm", phi, thetas[mode]) + SIGMA * rng.normal(size=(n, 1))
    return phi, y, mode, LocalLeastSquares().fit(phi, y)


def test_a_large_split_search_is_screened_with_a_loose_svm(monkeypatch):
    """A large search runs first with the SVM at tolerance SCREEN_TOL; one mode ends there,
    two modes go on to the full search, whose gain and split are those of an unscreened
    search."""
    from pwa_pipeline.pwa import submodels

    tols = []
    search = submodels._split_search
    monkeypatch.setattr(submodels, "_split_search",
                        lambda *a, **k: tols.append(k["regions"].tol) or search(*a, **k))
    phi, y, _, local = _wide(gap=0.0)
    assert phi[:2000].size > submodels.SCREEN_SIZE
    gain, halves = split_gain(phi, y, local.theta_, 24, 5, SVMRegions(), at_least=1.0)
    assert gain < 1 and halves is None and tols == [submodels.SCREEN_TOL]
    phi, y, mode, local = _wide(gap=0.1)
    tols.clear()
    gain, halves = split_gain(phi, y, local.theta_, 24, 5, SVMRegions(), at_least=1.0)
    assert gain > 2 and tols == [submodels.SCREEN_TOL, 1e-4]
    agree = np.mean(halves == mode)
    assert max(agree, 1 - agree) > 0.95
    unscreened = split_gain(phi, y, local.theta_, 24, 5, SVMRegions())
    assert unscreened[0] == gain and np.array_equal(unscreened[1], halves)


def test_a_row_set_is_split_searched_once_per_fit(monkeypatch):
    """Rows that come back unchanged (a missed-mode search whose clusters merged away, as on
    the robot) reuse their split search."""
    from pwa_pipeline.pwa import submodels

    u, y, _, mode = _close_modes()
    phi, target, labels = np.column_stack([y[:-1], u[:-1]]), y[1:], np.zeros(len(y) - 1, int)
    local = LocalLeastSquares().fit(phi, target)
    calls = []
    gain = submodels.split_gain
    monkeypatch.setattr(submodels, "split_gain",
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


def test_a_threshold_on_one_regressor_starts_a_split():
    """_axis_start finds the split at a threshold of one column of φ (y = θ_iᵀφ, mode 1
    where φ_1 > 0.2, predictions 4 σ apart)."""
    from pwa_pipeline.pwa.submodels import _axis_start

    rng = np.random.default_rng(0)
    n = 1000
    phi = np.column_stack([rng.uniform(-1, 1, (n, 3)), np.ones(n)])
    mode = (phi[:, 1] > 0.2).astype(int)
    thetas = np.array([[[0.5], [1.0], [-0.5], [0.0]], [[0.5], [1.0], [-0.5], [4 * SIGMA]]])
    y = np.einsum("nd,ndm->nm", phi, thetas[mode]) + SIGMA * rng.normal(size=(n, 1))
    start = _axis_start(phi, y, 8)
    assert np.mean(start == mode) > 0.97
    assert _axis_start(phi[:12], y[:12], 8) is None  # no side can keep 8 rows


def test_a_subsampled_split_is_extended_to_every_row_only_above_the_bar():
    u, y, _, mode = _close_modes()
    phi, target = np.column_stack([y[:-1], u[:-1]]), y[1:]
    local = LocalLeastSquares().fit(phi, target)
    gain, halves = split_gain(phi, target, local.theta_, 8, 5, SVMRegions(), max_rows=1000)
    assert gain > 2 and halves.shape == (len(phi),)
    agree = np.mean(halves == mode[1:])
    assert max(agree, 1 - agree) > 0.88
    above = split_gain(phi, target, local.theta_, 8, 5, SVMRegions(), max_rows=1000,
                       at_least=gain)
    assert above == (gain, None)  # the caller rejects it: not extended


def test_modes_three_noise_deviations_apart_are_split_from_the_threshold_start():
    """Local models blur the two modes of _two_modes(3): neither k-means of them nor the
    unexplained rows start a split that holds; the threshold start on φ_0 does."""
    phi, y, mode, _ = _two_modes(gap=3.0)
    local = LocalLeastSquares().fit(phi, y)
    gain, halves = split_gain(phi, y, local.theta_, 8, 5, SVMRegions())
    assert gain > 2
    agree = np.mean(halves == mode)
    assert max(agree, 1 - agree) > 0.9


def _axis_start_per_cut(phi, target, min_size, quantiles=np.linspace(0.1, 0.9, 9)):
    """_axis_start as a loop of least-squares fits per cut (the reference it must match)."""
    best, out = np.inf, None
    for j in np.flatnonzero(phi.std(axis=0) > 0):
        for cut in np.quantile(phi[:, j], quantiles):
            side = phi[:, j] > cut
            if min(side.sum(), (~side).sum()) < max(min_size, phi.shape[1] + 1):
                continue
            rss = sum(((target[r] - phi[r] @ least_squares(phi[r], target[r])) ** 2).sum(axis=0)
                      for r in (side, ~side))
            cost = float(np.log(rss).sum())
            if cost < best:
                best, out = cost, side.astype(int)
    return out


@pytest.mark.parametrize("case", ["white", "held", "ill-conditioned side"])
def test_the_threshold_start_equals_least_squares_per_cut(case):
    """_axis_start solves every cut's two sides from summed normal equations at once; the
    split is the one a least-squares fit per side and cut picks."""
    from pwa_pipeline.pwa.submodels import _axis_start

    rng = np.random.default_rng(4)
    n = 600
    x = rng.uniform(-1, 1, (n, 3))
    if case == "held":  # each value held 20 rows: many rows tie at a cut
        x = np.repeat(x[:n // 20], 20, axis=0)
    if case == "ill-conditioned side":  # columns 1 and 2 ~collinear where column 0 < 0
        x[:, 2] = np.where(x[:, 0] > 0, x[:, 2], x[:, 1] + 1e-9 * x[:, 2])
    phi = np.column_stack([x, np.ones(n)])
    mode = (0.6 * phi[:, 0] - phi[:, 1] > 0.1).astype(int)
    thetas = rng.normal(size=(2, 4, 2))
    y = np.einsum("nd,ndm->nm", phi, thetas[mode]) + 0.05 * rng.normal(size=(n, 2))
    for min_size in (8, 250):
        expected = _axis_start_per_cut(phi, y, min_size)
        assert expected is not None
        np.testing.assert_array_equal(_axis_start(phi, y, min_size), expected)


def test_memoised_sweeps_repeat_none_and_change_nothing(monkeypatch):
    """refine with a memo gives the result without one, bit for bit, with and without
    regions on one memo, and a repeated call fits no region SVM."""
    import pwa_pipeline.pwa.submodels as submodels

    phi, y, mode, _ = _two_modes(gap=3.0)  # overlapping: the sweeps do not settle at once
    start = (phi[:, 0] > 0.4).astype(int)
    plain = [refine(phi, y, start, 5, 20, regions) for regions in (None, SVMRegions())]
    memo = {}
    for _ in range(2):
        for regions, expected in zip((None, SVMRegions()), plain):
            got = refine(phi, y, start, 5, 20, regions, memo)
            for a, b in zip(got, expected):
                np.testing.assert_array_equal(a, b)
    assert plain[1][3] >= 2
    fits = []
    real = SVMRegions.fit
    monkeypatch.setattr(SVMRegions, "fit", lambda self, *a, **k: fits.append(1)
                        or real(self, *a, **k))
    submodels.refine(phi, y, start, 5, 20, SVMRegions(), memo)
    assert fits == []
    with pytest.raises(ValueError, match="memo holds sweeps of other data"):
        refine(phi.copy(), y, start, 5, 20, SVMRegions(), memo)


def test_sweeps_stop_when_few_rows_move_and_the_sub_models_are_kept():
    """refine's tol: a sweep that moves at most tol × n rows ends it, unless it changed the
    number of sub-models (a dropped one is re-assigned and the sweeps go on)."""
    phi, y, mode, _ = _two_modes(gap=40.0)
    start = (phi[:, 0] > 0.5).astype(int)
    assert refine(phi, y, start, 5, 20, SVMRegions(), tol=1.0)[3] == 1
    exact = refine(phi, y, start, 5, 20, SVMRegions())
    assert exact[3] >= 2  # the first sweep moved rows
    tiny = start.copy()
    tiny[:3] = 2  # a third sub-model of 3 rows, below min_size: the first sweep drops it
    dropped = refine(phi, y, tiny, 5, 20, SVMRegions(), tol=1.0)
    assert dropped[0].shape[0] == 2 and dropped[3] == 2


class _InOrder:
    """An executor that runs a submitted call only when its result is asked for (never when
    cancelled): the missed-mode search where the sequential loop ran it."""

    def __init__(self, workers: int):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def submit(self, fn, *args):
        class Deferred:
            def cancel(self):
                return True

            def result(self):
                return fn(*args)

        return Deferred()


def test_the_missed_mode_search_beside_the_split_search_changes_nothing(monkeypatch):
    """The search for missed modes runs in a second thread while the split search runs and is
    dropped when a split holds: the fit is the one that runs it afterwards, only when no
    split holds, to the last bit. Splits hold beside a search (the default), or never (a
    bar no split reaches, and the searches run)."""
    from pwa_pipeline.pwa import submodels

    phi, target, local, absorbed = _four_percent_mode()
    searches = []
    search = submodels._missed_mode_clusters
    monkeypatch.setattr(submodels, "_missed_mode_clusters",
                        lambda phi, *a: searches.append(len(phi)) or search(phi, *a))
    for split_tol, dropped in ((1.0, True), (1e6, False)):
        step = RefinedSubModels(split_tol=split_tol)
        with monkeypatch.context() as m:
            m.setattr(submodels, "ThreadPoolExecutor", _InOrder)
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


def test_theta_shift_is_in_standard_errors_on_each_sub_models_rows():
    """theta_shift: the root mean square over θ_i's d·m entries of its change, each in its
    least-squares standard error on sub-model i's rows (the largest over i)."""
    rng = np.random.default_rng(0)
    n, d, m = 400, 3, 2
    phi = rng.normal(size=(n, d))
    labels = (phi[:, 0] > 0).astype(int)
    sigma2 = np.array([0.01, 0.04])
    before = rng.normal(size=(2, d, m))
    after = before.copy()
    v = rng.normal(size=d)
    # output 1 of sub-model 1 moved along v so that Σ ‖Φ_1 Δθ‖² / σ² = 0.7² · d·m
    after[1, :, 1] += 0.7 * np.sqrt(d * m * sigma2[1]) / np.linalg.norm(phi[labels == 1] @ v) * v
    assert theta_shift(phi, before, after, labels, sigma2) == pytest.approx(0.7, rel=1e-12)
    after[0, :, 0] += 0.3 * np.sqrt(d * m * sigma2[0]) / np.linalg.norm(phi[labels == 0] @ v) * v
    assert theta_shift(phi, before, after, labels, sigma2) == pytest.approx(0.7, rel=1e-12)
    assert np.isnan(theta_shift(phi, before, after[:1], labels, sigma2))


def test_sweeps_stop_once_no_sub_model_moves_by_more_than_settle_standard_errors():
    """refine's settle: the re-assignment ends at the first sweep that keeps the number of
    sub-models and changes no θ_i by more than ``settle`` standard errors (theta_shift
    between the sub-models it starts from and those it ends with, σ̂² its own)."""
    import pwa_pipeline.pwa.submodels as submodels
    from pwa_pipeline._arrays import relabel_by_size

    phi, y, mode, _ = _two_modes(gap=3.0, seed=1)
    plain = refine(phi, y, mode, 5, 20, SVMRegions())
    settle = 0.5  # the sweeps' shifts: 49 (the first renumbers), 0.79, 0.25, 0.12, 0
    got = refine(phi, y, mode, 5, 20, SVMRegions(), settle=settle)
    labels = relabel_by_size(mode)
    thetas = refit(phi, y, labels, 2)
    for sweep in range(1, 21):
        new, after, sigma2 = submodels._sweep(phi, y, thetas, 5, SVMRegions())
        assert new.max() == labels.max()
        if theta_shift(phi, thetas, after, new, sigma2) <= settle:
            break
        labels, thetas = new, after
    assert 1 < sweep == got[3] < plain[3]
    np.testing.assert_array_equal(got[1], new)
    np.testing.assert_array_equal(got[0], after)
    # settle 0: only a sweep that moves no row ends it, as without the parameter
    for a, b in zip(refine(phi, y, mode, 5, 20, SVMRegions(), settle=0.0), plain):
        np.testing.assert_array_equal(a, b)


def test_rows_flipping_on_a_boundary_end_the_sweeps_once_the_sub_models_settle():
    """Modes 3 noise deviations apart: rows near the boundary flip between the sub-models in
    every sweep and the sweeps run to their limit, while the sub-models settle at once."""
    phi, y, mode, _ = _two_modes(gap=3.0, seed=3)
    plain = refine(phi, y, mode, 5, 20, SVMRegions())
    settled = refine(phi, y, mode, 5, 20, SVMRegions(), settle=0.3)
    assert plain[3] == 20 and settled[3] <= 3
    assert np.mean(settled[1] == plain[1]) > 0.99


def test_the_settle_tolerance_reaches_every_sweep_with_regions(monkeypatch, sim_30db):
    """RefinedSubModels(settle_tol=…) stops the re-assignments with the regions (steps 2–3
    and the split search) by it; those by residual alone run until no row moves."""
    import pwa_pipeline.pwa.submodels as submodels

    calls = []
    real = submodels.refine

    def spy(*args, **kwargs):
        regions = args[5] if len(args) > 5 else kwargs.get("regions")
        calls.append((regions is not None, kwargs.get("settle", 0.0)))
        return real(*args, **kwargs)

    monkeypatch.setattr(submodels, "refine", spy)
    PWARX.default(1, 1).set_params(submodels__settle_tol=0.7).fit(sim_30db.u, sim_30db.y)
    with_regions = {settle for has_regions, settle in calls if has_regions}
    alone = {settle for has_regions, settle in calls if not has_regions}
    assert with_regions == {0.7} and alone == {0.0}
    assert sum(has for has, _ in calls) > 2  # the split search's refines among them


@pytest.mark.parametrize("entries", [1 << 22, 100], ids=["at once", "in groups"])
def test_prediction_gaps_are_the_mean_over_each_pairs_rows(entries, monkeypatch):
    # The merge statistic of every pair at once, against the pair-by-pair definition; rows
    # labelled -1 (noise) belong to no pair. Also with the predictions in groups of
    # sub-models (a bound of 100 entries: one sub-model at a time for most labels).
    from pwa_pipeline.pwa import submodels
    from pwa_pipeline.pwa.submodels import _prediction_gaps

    monkeypatch.setattr(submodels, "_GAP_ENTRIES", entries)

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


def test_refit_takes_a_row_sets_fit_from_its_memo():
    # The memo is keyed by the rows, not the label: relabelled groups reuse their fits, and
    # what it returns is what a fresh refit gives, bit for bit.
    rng = np.random.default_rng(8)
    phi, target = rng.normal(size=(200, 3)), rng.normal(size=(200, 2))
    labels = rng.integers(0, 4, 200)
    memo = {}
    first = refit(phi, target, labels, 4, memo)
    assert len(memo) == 4
    swapped = np.array([1, 0, 2, 3])[labels]
    second = refit(phi, target, swapped, 4, memo)
    np.testing.assert_array_equal(second, first[[1, 0, 2, 3]])
    assert len(memo) == 4  # nothing refitted
    np.testing.assert_array_equal(second, refit(phi, target, swapped, 4))
    merged = np.where(labels == 3, 2, labels)
    refit(phi, target, merged, 3, memo)
    assert len(memo) == 5  # only the merged group is new


def test_the_k_means_start_places_rows_without_a_local_model_by_their_fit():
    # two modes far apart in θ: k-means on the estimated local models splits them, and a row
    # whose local model was not estimated (LocalLeastSquares.max_sets) joins the side whose
    # least-squares sub-model predicts it better
    phi, y, mode, thetas = _two_modes(gap=0.0, n=1500, seed=2)
    y = np.einsum("nd,ndm->nm", phi, np.array([[[0.5], [1.0], [0.0]],
                                                [[-0.5], [-1.0], [0.5]]])[mode])
    y += SIGMA * np.random.default_rng(2).normal(size=y.shape)
    every = LocalLeastSquares(n_rho=30, max_sets=None).fit(phi, y)
    some = LocalLeastSquares(n_rho=30, max_sets=300).fit(phi, y)
    far = np.abs(phi[:, 0]) > 0.2  # local sets across the boundary mix the modes

    def agreement(start):
        agree = np.mean(start[far] == mode[far])
        return max(agree, 1 - agree)

    assert agreement(_kmeans_start(phi, y, every.theta_, 3)) == 1.0
    part = _kmeans_start(phi, y, some.theta_, 3)
    # the same start from the θ_k read without spreading them, by mask and by index too
    np.testing.assert_array_equal(_kmeans_start(phi, y, some.local_thetas(), 3), part)
    rows = np.flatnonzero(far)[::-2]
    for select in (far, rows):
        np.testing.assert_array_equal(
            _kmeans_start(phi[select], y[select], some.local_thetas()[select], 3),
            _kmeans_start(phi[select], y[select], some.theta_[select], 3))
    assert agreement(part) > 0.95
    rest = far & ~some.estimated_
    agree = np.mean(part[rest] == mode[rest])
    assert max(agree, 1 - agree) > 0.95  # those without a local model too
    # too few estimated local models: no k-means start
    assert _kmeans_start(phi, y, np.where(np.arange(1500)[:, None, None] < 5, every.theta_,
                                          np.nan), 3) is None


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
    # local models of 1,500 of the samples: other local models; loaded from a pickle (kept
    # compact), the same entry, found without spreading their θ_k
    import pickle

    subset = LocalLeastSquares(max_sets=1500).fit(phi, target)
    plain = RefinedSubModels().fit(phi, target, subset, absorbed, SVMRegions())
    clone(plain).set_params(memory=str(tmp_path)).fit(phi, target, subset, absorbed,
                                                      SVMRegions())
    assert len(list(tmp_path.rglob("output.pkl"))) == 6
    restored = pickle.loads(pickle.dumps(subset, protocol=5))
    hit = clone(plain).set_params(memory=str(tmp_path)).fit(phi, target, restored, absorbed,
                                                            SVMRegions())
    assert len(list(tmp_path.rglob("output.pkl"))) == 6 and "theta_" not in vars(restored)
    np.testing.assert_array_equal(hit.thetas_, plain.thetas_)


def test_step_5_reads_the_local_models_of_a_fit_without_spreading_them(monkeypatch):
    """A local-model step fitted on a subset keeps its per-sample arrays on the estimated
    samples until read (as a loaded one does), and step 5's split search reads their θ_k
    through ``local_thetas``: the same sub-models as from the spread ``theta_``, and the step
    left compact."""
    from pwa_pipeline.pwa import submodels

    phi, target, _, absorbed = _four_percent_mode()
    subset = LocalLeastSquares(max_sets=1500).fit(phi, target)
    spread = {"theta_", "neighbours_", "residual_var_"}
    assert "_compact" in vars(subset) and not spread & set(vars(subset))
    read = []
    with_local_model = submodels._with_local_model

    def spy(local_theta):
        have, theta = with_local_model(local_theta)
        read.append((type(local_theta).__name__, have.all()))
        return have, theta

    monkeypatch.setattr(submodels, "_with_local_model", spy)
    lazy = RefinedSubModels().fit(phi, target, subset, absorbed, SVMRegions())
    assert not spread & set(vars(subset))
    assert ("LocalThetas", False) in read  # the k-means start ran on rows without one too
    monkeypatch.setattr(LocalLeastSquares, "local_thetas", lambda step: step.theta_)
    dense = RefinedSubModels().fit(phi, target, subset, absorbed, SVMRegions())
    assert lazy.n_split_ == dense.n_split_ >= 1
    for name in ("thetas_", "labels_", "weights_"):
        np.testing.assert_array_equal(getattr(lazy, name), getattr(dense, name))


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
