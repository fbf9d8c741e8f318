"""Blocked exact k nearest neighbours (pwa_pipeline.pwa.neighbours) against references."""

import numpy as np
import pytest
from sklearn.neighbors import NearestNeighbors

from pwa_pipeline.pwa import neighbours
from pwa_pipeline.pwa.neighbours import nearest_neighbours


def reference(x: np.ndarray, k: int) -> np.ndarray:
    """The k smallest Σ_j (x_pj − x_qj)² of each row, equal distances by index."""
    sq = ((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2)
    idx = np.broadcast_to(np.arange(len(x)), sq.shape)
    return np.lexsort((idx, sq), axis=1)[:, :k]


@pytest.fixture(autouse=True)
def small_blocks(monkeypatch):
    # many blocks, tiles and windows even on a few hundred points
    monkeypatch.setattr(neighbours, "_BLOCK", 64)
    monkeypatch.setattr(neighbours, "_WINDOW", 96)


@pytest.mark.parametrize(("n", "dims", "k"), [(700, 24, 72), (500, 16, 1), (300, 40, 300),
                                              (90, 13, 30), (650, 20, 7)])
def test_same_neighbours_as_sklearn_brute_force(n, dims, k):
    rng = np.random.default_rng(n + dims)
    x = rng.normal(size=(n, dims)) @ rng.normal(size=(dims, dims)) + 100  # correlated, offset
    got = nearest_neighbours(x, k)
    ref = NearestNeighbors(n_neighbors=k, algorithm="brute").fit(x).kneighbors(
        x, return_distance=False)
    np.testing.assert_array_equal(np.sort(got, axis=1), np.sort(ref, axis=1))
    np.testing.assert_array_equal(got, reference(x, k))  # each point first, nearest first


@pytest.mark.parametrize("seed", range(3))
def test_ties_go_to_the_lower_index(seed):
    # Points on a coarse grid: distances are exact in float64 and tie everywhere.
    rng = np.random.default_rng(seed)
    x = rng.integers(-3, 4, size=(400, 14)) * 0.5
    x = x[np.unique(x, axis=0, return_index=True)[1]]  # distinct points
    np.testing.assert_array_equal(nearest_neighbours(x, 25), reference(x, 25))


def test_coinciding_points_are_searched_once_with_their_multiplicity():
    rng = np.random.default_rng(5)
    base = rng.integers(-2, 3, size=(150, 18)).astype(float)
    x = base[rng.integers(0, 150, 600)]  # every point several times, shuffled
    for k in (1, 4, 40, 600):
        np.testing.assert_array_equal(nearest_neighbours(x, k), reference(x, k))


def test_a_far_outlier_and_a_tight_cluster():
    rng = np.random.default_rng(2)
    x = np.vstack([rng.normal(size=(300, 20)) * 1e-3, rng.normal(size=(300, 20)) * 50,
                   np.full((1, 20), 1e4)])
    np.testing.assert_array_equal(nearest_neighbours(x, 20), reference(x, 20))


def test_k_out_of_range():
    with pytest.raises(ValueError, match="1 <= k <= n"):
        nearest_neighbours(np.zeros((5, 20)), 6)
