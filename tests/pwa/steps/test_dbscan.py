"""Blocked DBSCAN (pwa_pipeline.pwa.steps.dbscan) against scikit-learn's DBSCAN."""

import numpy as np
import pytest
from sklearn.cluster import DBSCAN
from sklearn.neighbors import NearestNeighbors

from pwa_pipeline.pwa.steps.dbscan import _dbscan, dbscan


def blobs_and_noise(seed: int, dims: int, n_blobs: int, n_noise: int, duplicates: int = 0,
                    size: int = 200) -> np.ndarray:
    """Gaussian blobs of 20 to ``size`` points, uniform noise, some rows repeated, shuffled."""
    rng = np.random.default_rng(seed)
    parts = [rng.normal(rng.uniform(-10, 10, dims), rng.uniform(0.3, 2.0),
                        (int(rng.integers(20, size)), dims)) for _ in range(n_blobs)]
    x = np.vstack([*parts, rng.uniform(-15, 15, (n_noise, dims))])
    x = np.vstack([x, x[rng.integers(0, len(x), duplicates)]])
    return x[rng.permutation(len(x))]


def assert_as_sklearn(x: np.ndarray, eps: float, min_pts: int, block: int | None = None):
    """scikit-learn's labels (cluster numbers and border points included) and core points."""
    labels, core = _dbscan(x, eps, min_pts, block)
    sk = DBSCAN(eps=eps, min_samples=min_pts).fit(x)
    sk_core = np.zeros(len(x), bool)
    sk_core[sk.core_sample_indices_] = True
    np.testing.assert_array_equal(core, sk_core)
    np.testing.assert_array_equal(labels, sk.labels_)
    return labels, core


@pytest.mark.parametrize(("seed", "dims", "n_blobs", "n_noise", "dup", "eps", "min_pts"), [
    (0, 2, 3, 100, 0, 1.0, 5),
    (1, 2, 4, 200, 30, 0.5, 1),
    (2, 5, 3, 150, 0, 2.0, 2),
    (3, 10, 4, 300, 40, 3.0, 10),
    (4, 20, 3, 100, 0, 8.0, 22),
    (5, 3, 5, 50, 20, 1.5, 3),
    (6, 15, 3, 400, 0, 8.0, 15),
])
def test_same_clustering_as_sklearn(seed, dims, n_blobs, n_noise, dup, eps, min_pts):
    x = blobs_and_noise(seed, dims, n_blobs, n_noise, dup)
    labels, _ = assert_as_sklearn(x, eps, min_pts)
    assert labels.max() >= 1  # several clusters


@pytest.mark.parametrize("block", [None, 50])
def test_cluster_larger_than_a_block_of_columns(block):
    # The largest certified cluster is compared with the rest 256 columns at a time.
    x = blobs_and_noise(10, 6, 3, 300, 10, size=1500)
    labels, _ = assert_as_sklearn(x, 4.0, 20, block)
    assert np.bincount(labels[labels >= 0]).max() > 3 * 256


def test_no_cluster_is_all_noise():
    x = blobs_and_noise(7, 8, 2, 200)
    labels, core = assert_as_sklearn(x, 0.05, 5)
    assert not core.any() and (labels == -1).all()


def test_duplicated_points_count_as_neighbours():
    x = np.repeat(np.eye(3), [4, 3, 1], axis=0)  # 4, 3 and 1 copies of three far points
    labels, core = assert_as_sklearn(x, 0.1, 4)
    np.testing.assert_array_equal(core, [True] * 4 + [False] * 4)
    np.testing.assert_array_equal(labels, [0] * 4 + [-1] * 4)


def test_point_at_exactly_eps_is_a_neighbour():
    # (0, 0)–(3, 4) is exactly 5 apart, like scikit-learn's radius test `<=`.
    x = np.array([[0.0, 0.0], [3.0, 4.0], [20.0, 20.0], [0.0, -5.0], [40.0, 0.0]])
    labels, core = assert_as_sklearn(x, 5.0, 2)
    np.testing.assert_array_equal(labels, [0, 0, -1, 0, -1])
    assert (dbscan(x, np.nextafter(5.0, 0.0), 2) == -1).all()


@pytest.mark.parametrize("seed", range(6))
def test_eps_equal_to_a_k_distance_as_sklearn(seed):
    # ε a k-distance, as k_distance_eps chooses it: the pair that defines it lies at ε up to
    # rounding, and scikit-learn's k-d tree (up to 15 dimensions) decides it in its own
    # arithmetic; points on a 0.1 grid give many more such ties.
    rng = np.random.default_rng(seed)
    dims = (1, 2, 3, 5, 10, 15)[seed]
    x = rng.normal(size=(400, dims)) * 30 + 50
    if seed % 2:
        x = np.round(x, 1)
    for k in (2, 5, 12):
        dist = NearestNeighbors(n_neighbors=k).fit(x).kneighbors(x)[0][:, -1]
        for q in (0.2, 0.5, 0.8):
            assert_as_sklearn(x, float(np.quantile(dist, q, method="lower")), k)


def test_distances_within_float32_rounding_of_eps():
    # Pairs 1e-7 · eps inside or outside eps, far from the origin: float32 cannot tell.
    rng = np.random.default_rng(9)
    eps, pairs = 3.7, []
    for k in range(12):
        centre = rng.normal(size=10) * 300
        step = rng.normal(size=10)
        pairs += [centre, centre + step / np.linalg.norm(step) * eps * (1 + (-1) ** k * 1e-7)]
    labels, _ = assert_as_sklearn(np.array(pairs), eps, 2)
    np.testing.assert_array_equal(labels[1::2] >= 0, [k % 2 == 1 for k in range(12)])


def test_block_size_does_not_change_labels():
    x = blobs_and_noise(8, 6, 4, 300, 25)
    expected = dbscan(x, 2.5, 8)
    assert expected.max() >= 1
    for block in (1, 7, 64):
        np.testing.assert_array_equal(dbscan(x, 2.5, 8, block=block), expected)
        assert_as_sklearn(x, 2.5, 8, block)


def test_border_point_joins_the_first_cluster_in_index_order():
    # Two clusters of core points, 0 … 9 and 27 … 36 (eps 10, MinPts 4); the border points
    # 17, 18 and 19 are within eps of both (17 nearer 9, 19 nearer 27). As in scikit-learn,
    # the cluster whose lowest-indexed core point comes first takes them, whatever is nearer.
    a, b = [0.0, 3.0, 6.0, 9.0], [27.0, 30.0, 33.0, 36.0]
    for first in (a + b, b + a):
        for border in (17.0, 18.0, 19.0):
            labels, core = assert_as_sklearn(np.array([*first, border])[:, None], 10.0, 4)
            assert core[:8].all() and not core[8]
            np.testing.assert_array_equal(labels, [0] * 4 + [1] * 4 + [0])


def test_rejects_non_positive_eps_and_min_pts():
    with pytest.raises(ValueError, match="eps > 0"):
        dbscan(np.zeros((3, 2)), 0.0, 2)
    with pytest.raises(ValueError, match="min_pts >= 1"):
        dbscan(np.zeros((3, 2)), 1.0, 0)
