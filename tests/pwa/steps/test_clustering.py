import numpy as np
import pytest
from sklearn.cluster import DBSCAN
from sklearn.neighbors import NearestNeighbors
from sklearn.utils._param_validation import InvalidParameterError

from pwa_pipeline._arrays import relabel_by_size
from pwa_pipeline.pwa import DBSCANClustering, LocalLeastSquares
from pwa_pipeline.pwa.steps import clustering
from pwa_pipeline.pwa.steps.clustering import (
    cluster_local_models,
    confident_models,
    dbscan_cluster_counts,
    k_distance_eps,
    k_distances,
)


def _blobs(seed=0, spread=0.05):
    rng = np.random.default_rng(seed)
    centres = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    pts = np.concatenate([c + spread * rng.normal(size=(n, 2)) for c, n in zip(centres, (300, 60, 30))])
    return pts.reshape(-1, 2, 1)


class _Local:
    """A stand-in fitted local-model step: θ_k given, every residual alike, unit scales."""

    def __init__(self, theta):
        self.theta_ = theta
        self.residual_var_ = np.ones((len(theta), theta.shape[2]))
        self.phi_scale_ = np.ones(theta.shape[1])
        self.degenerate_ = np.zeros(len(theta), bool)
        self.n_degenerate_ = 0
        self.estimated_ = np.ones(len(theta), bool)
        self.original_ = np.arange(len(theta))


def test_automatic_eps_is_in_a_sane_range_and_never_mixes_clusters():
    theta = _blobs()
    labels_true = np.repeat([0, 1, 2], (300, 60, 30))
    eps = k_distance_eps(theta.reshape(len(theta), -1), min_pts=8)
    # within the clusters' own scale (spread 0.05), far below the 1.0 between them
    assert 0.005 < eps < 0.2
    step = DBSCANClustering(min_pts=8, unit_free=False, confidence=None,
                            max_clustered=None).fit(_Local(theta), np.ones((390, 1)))
    assert step.eps_auto_ and step.eps_ == pytest.approx(eps)
    # every cluster holds one blob only (sparser blobs may be left to the later search for
    # missed modes of RefinedSubModels, tested in test_submodels.py)
    found = {c: set(labels_true[step.labels_ == c]) for c in range(step.n_clusters_)}
    assert step.n_clusters_ >= 1 and all(len(v) == 1 for v in found.values())


def test_labels_are_scikit_learns_dbscan_relabelled_by_size():
    theta = _blobs(seed=3)
    step = DBSCANClustering(eps=0.08, min_pts=6, unit_free=False, confidence=None,
                            max_clustered=None).fit(_Local(theta), np.ones((390, 1)))
    ref = DBSCAN(eps=0.08, min_samples=6).fit_predict(theta.reshape(390, 2))
    # the same labels, border points included, numbered by size
    np.testing.assert_array_equal(step.labels_, relabel_by_size(ref))
    assert ref.max() >= 1
    sizes = np.bincount(step.labels_[step.labels_ >= 0])
    assert np.all(np.diff(sizes) <= 0)  # 0 is the largest cluster


def _counts_on_the_radius_graph(x, grid, min_pts):
    """The previous k_distance_eps's counts: scikit-learn's DBSCAN on one radius graph."""
    graph = NearestNeighbors(radius=grid[-1]).fit(x).radius_neighbors_graph(
        mode="distance", sort_results=True)
    graph.data = np.maximum(graph.data, np.finfo(float).tiny)  # keep exact duplicates
    return [DBSCAN(eps=e, min_samples=min_pts, metric="precomputed").fit(graph).labels_.max() + 1
            for e in grid]


@pytest.mark.parametrize("dense", [True, False], ids=["all distances", "by point"])
@pytest.mark.parametrize(("seed", "dims", "min_pts", "on_grid"), [
    (0, 1, 3, True), (1, 2, 8, True), (2, 2, 1, True), (3, 3, 12, True), (4, 8, 5, True),
    (5, 15, 20, True), (6, 20, 10, False)])
def test_cluster_counts_are_scikit_learns_at_every_candidate_eps(seed, dims, min_pts,
                                                                 on_grid, dense,
                                                                 monkeypatch):
    # Blobs and noise, up to 15 dimensions on a 0.1 grid (many distances tie), candidates
    # at the k-distance quantiles as k_distance_eps takes them: pairs at exactly a
    # candidate ε occur. Above 15 dimensions (scikit-learn's brute force, rounded by BLAS)
    # off the grid. Both ways of computing the distances.
    if not dense:
        monkeypatch.setattr(clustering, "_DENSE", 0)
    rng = np.random.default_rng(seed)
    x = np.vstack([rng.normal(rng.uniform(-5, 5, dims), 0.5, (150, dims))
                   for _ in range(3)] + [rng.uniform(-8, 8, (60, dims))])
    if on_grid:
        x = np.round(x, 1)
    grid = np.unique(np.maximum(
        np.quantile(k_distances(x, min_pts), np.linspace(0.02, 0.6, 20)), 1e-6))
    counts = dbscan_cluster_counts(x, grid, min_pts)
    np.testing.assert_array_equal(counts, _counts_on_the_radius_graph(x, grid, min_pts))
    assert counts.max() >= 2


def test_unit_free_theta_makes_eps_independent_of_the_output_scale():
    theta = _blobs()
    y = np.random.default_rng(0).normal(size=(390, 1))
    base = DBSCANClustering(eps=0.08, min_pts=6, confidence=None, max_clustered=None)
    a = base.fit(_Local(theta), y).labels_
    b = DBSCANClustering(**base.get_params()).fit(_Local(theta * 1000), y * 1000).labels_
    np.testing.assert_array_equal(a, b)


def test_subset_and_confidence_filter_mark_rows_not_clustered():
    theta = _blobs()
    local = _Local(theta)
    local.residual_var_[:10] = 100.0  # ten mixed local sets
    step = DBSCANClustering(min_pts=6, unit_free=False, max_clustered=200).fit(
        local, np.ones((390, 1)))
    assert step.clustered_.sum() == 200 and not step.clustered_[:10].any()
    assert np.all(step.labels_[~step.clustered_] == -1)
    assert step.noise_share_ == pytest.approx(np.mean(step.labels_[step.clustered_] < 0))


def test_no_cluster_names_eps_min_pts_and_noise_share():
    theta = np.random.default_rng(0).normal(size=(50, 3, 2))
    with pytest.raises(ValueError, match=r"no cluster with eps = 1e-06 and min_pts = 10.*noise share 100%"):
        cluster_local_models(theta, 1e-6, 10)


def test_bad_settings():
    local, y = _Local(_blobs()), np.ones((390, 1))
    with pytest.raises(InvalidParameterError, match="'embedding' parameter.*'cosine'"):
        DBSCANClustering(embedding="cosine").fit(local, y)
    with pytest.raises(InvalidParameterError, match="'eps' parameter.*-1.0"):
        DBSCANClustering(eps=-1.0).fit(local, y)
    with pytest.raises(ValueError, match="fewer than min_pts"):
        cluster_local_models(_blobs()[:3], 0.1, 5)


def test_confidence_filter_drops_large_residuals():
    resvar = np.ones((10, 2))
    resvar[3, 1] = 10.0
    keep = confident_models(resvar, 3.0)
    assert keep.sum() == 9 and not keep[3]


def test_resolved_params_report_the_values_chosen_from_the_data():
    rng = np.random.default_rng(0)
    phi = rng.normal(size=(400, 3))
    local = LocalLeastSquares().fit(phi, phi @ np.ones((3, 1)))
    step = DBSCANClustering().fit(local, phi @ np.ones((3, 1)))
    assert local.resolved_params()["n_rho"] == 9 and step.resolved_params()["min_pts"] == 6
    assert step.resolved_params()["eps"] == step.eps_ > 0 and step.get_params()["eps"] is None
