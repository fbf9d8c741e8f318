"""The search for two modes inside one sub-model (pwa.submodels.split_search)."""

import numpy as np
import pytest

from pwa_pipeline.pwa import DBSCANClustering, LocalLeastSquares, RefinedSubModels, SVMRegions
from pwa_pipeline.pwa.steps.submodels import split_search
from pwa_pipeline.pwa.steps.submodels.least_squares import least_squares
from pwa_pipeline.pwa.steps.submodels.split_search import _axis_start, _kmeans_start, split_gain

from ..._submodel_cases import SIGMA, _close_modes, _curved_mode, _two_modes, _wide


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


def test_a_large_split_search_is_screened_with_a_loose_svm(monkeypatch):
    """A large search runs first with the SVM at tolerance SCREEN_TOL; one mode ends there,
    two modes go on to the full search, whose gain and split are those of an unscreened
    search."""
    tols = []
    search = split_search._split_search
    monkeypatch.setattr(split_search, "_split_search",
                        lambda *a, **k: tols.append(k["regions"].tol) or search(*a, **k))
    phi, y, _, local = _wide(gap=0.0)
    assert phi[:2000].size > split_search.SCREEN_SIZE
    gain, halves = split_gain(phi, y, local.theta_, 24, 5, SVMRegions(), at_least=1.0)
    assert gain < 1 and halves is None and tols == [split_search.SCREEN_TOL]
    phi, y, mode, local = _wide(gap=0.1)
    tols.clear()
    gain, halves = split_gain(phi, y, local.theta_, 24, 5, SVMRegions(), at_least=1.0)
    assert gain > 2 and tols == [split_search.SCREEN_TOL, 1e-4]
    agree = np.mean(halves == mode)
    assert max(agree, 1 - agree) > 0.95
    unscreened = split_gain(phi, y, local.theta_, 24, 5, SVMRegions())
    assert unscreened[0] == gain and np.array_equal(unscreened[1], halves)


def test_a_threshold_on_one_regressor_starts_a_split():
    """_axis_start finds the split at a threshold of one column of φ (y = θ_iᵀφ, mode 1
    where φ_1 > 0.2, predictions 4 σ apart)."""
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
    assert agreement(part) > 0.95
    rest = far & ~some.estimated_
    agree = np.mean(part[rest] == mode[rest])
    assert max(agree, 1 - agree) > 0.95  # those without a local model too
    # too few estimated local models: no k-means start
    assert _kmeans_start(phi, y, np.where(np.arange(1500)[:, None, None] < 5, every.theta_,
                                          np.nan), 3) is None
