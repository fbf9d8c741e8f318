"""Blocked exact k nearest neighbours (pwa_pipeline.pwa.steps.neighbours) against references."""

import platform

import numpy as np
import pytest
from scipy.spatial import cKDTree
from sklearn.neighbors import NearestNeighbors

from pwa_pipeline.pwa.kernels.knn import sq_distance
from pwa_pipeline.pwa.steps import neighbours
from pwa_pipeline.pwa.steps.neighbours import nearest_neighbours


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


@pytest.mark.parametrize("duplicates", [0, 80])
def test_same_distances_as_an_exact_kd_tree_with_ties(duplicates):
    rng = np.random.default_rng(11)
    grid = rng.integers(-2, 3, size=(150, 16)) * 0.25  # distances exact and tying often
    grid = grid[np.unique(grid, axis=0, return_index=True)[1]]
    x = np.vstack([grid, grid[rng.integers(0, len(grid), duplicates)],
                   rng.normal(size=(100, 16))])
    x = x[rng.permutation(len(x))]  # duplicates spread over the indices
    for k in (1, 9, 50):
        got = nearest_neighbours(x, k)
        dist = cKDTree(x).query(x, k)[0].reshape(len(x), k)  # its own order at ties
        ours = np.sqrt(((x[got] - x[:, None, :]) ** 2).sum(axis=2))
        np.testing.assert_allclose(ours, dist, rtol=1e-12, atol=0)
        np.testing.assert_array_equal(got, reference(x, k))


def test_near_ties_float32_cannot_rank_are_ranked_exactly():
    # A shell of radii 1 + j·1e-6 around the origin, and a far cluster that puts the
    # centred points at norms ~500: float32's rounding (~1 on these squared distances)
    # ranks nothing in the shell, float64 ranks all of it.
    rng = np.random.default_rng(4)
    u = rng.normal(size=(300, 20))
    shell = u / np.linalg.norm(u, axis=1, keepdims=True) * (1 + rng.permutation(300)[:, None]
                                                             * 1e-6)
    x = np.vstack([np.zeros((1, 20)), shell, 1e3 + rng.normal(size=(200, 20))])
    for k in (40, 150):
        np.testing.assert_array_equal(nearest_neighbours(x, k), reference(x, k))


@pytest.mark.skipif(platform.machine() != "x86_64", reason="numpy's einsum order on x86-64")
def test_exact_distances_are_numpys_einsum_bit_for_bit():
    # The kernels rank on the values numpy's einsum gave the search before them.
    rng = np.random.default_rng(3)
    for d in (1, 7, 8, 13, 24, 40):
        x = rng.normal(size=(300, d)) * 10.0 ** rng.uniform(-3, 3, size=(300, 1))
        p, q = rng.integers(0, 300, size=(2, 1000))
        diff = x[p] - x[q]
        got = np.array([sq_distance(x, a, b) for a, b in zip(p, q)])
        np.testing.assert_array_equal(got, np.einsum("ij,ij->i", diff, diff))


def test_k_out_of_range():
    with pytest.raises(ValueError, match="1 <= k <= n"):
        nearest_neighbours(np.zeros((5, 20)), 6)


def test_non_finite_points():
    x = np.zeros((5, 20))
    x[2, 3] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite"):
        nearest_neighbours(x, 2)


def test_an_interrupted_map_drops_the_tasks_not_started():
    # Ctrl-C while the search's threads work: the waiting thread gets KeyboardInterrupt, and
    # leaving the pool must not first run every block still queued.
    import threading
    import time
    from concurrent.futures import ThreadPoolExecutor

    from pwa_pipeline._threads import map_in_threads

    ran, lock = [], threading.Lock()

    def task(i):
        if i == 0:
            raise KeyboardInterrupt
        time.sleep(0.05)
        with lock:
            ran.append(i)

    with pytest.raises(KeyboardInterrupt):
        with ThreadPoolExecutor(1) as pool:
            map_in_threads(pool, task, range(20))
    assert len(ran) <= 2  # the one that started while the interrupt reached the caller
    with ThreadPoolExecutor(2) as pool:
        assert map_in_threads(pool, lambda i: i * i, range(5)) == [0, 1, 4, 9, 16]


@pytest.mark.parametrize("duplicates", [0, 120])
def test_queried_rows_get_the_neighbours_of_the_full_search(duplicates):
    # a subset of rows (any order, spread over the spatial order) searched against every row
    rng = np.random.default_rng(8)
    x = rng.normal(size=(600, 20)) @ rng.normal(size=(20, 20))
    x = np.vstack([x, x[rng.integers(0, 600, duplicates)]])[rng.permutation(600 + duplicates)]
    full = nearest_neighbours(x, 40)
    for q in (rng.choice(len(x), 150, replace=False), np.array([len(x) - 1, 3, 3])):
        got = nearest_neighbours(x, 40, queries=q)
        assert got.shape == (len(q), 40)
        np.testing.assert_array_equal(got, full[q])
        np.testing.assert_array_equal(got, reference(x, 40)[q])
