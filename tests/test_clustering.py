import numpy as np
import pytest

from pwa_pipeline.clustering import cluster_local_models, confident_models, k_distance_eps


def _blobs(seed=0, spread=0.05):
    rng = np.random.default_rng(seed)
    centres = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    pts = np.concatenate([c + spread * rng.normal(size=(n, 2)) for c, n in zip(centres, (300, 60, 30))])
    return pts.reshape(-1, 2, 1)


def test_automatic_eps_is_in_a_sane_range_and_never_mixes_clusters():
    theta = _blobs()
    labels_true = np.repeat([0, 1, 2], (300, 60, 30))
    emb = theta.reshape(len(theta), -1)
    eps = k_distance_eps(emb, min_pts=8)
    # within the clusters' own scale (spread 0.05), far below the 1.0 between them
    assert 0.005 < eps < 0.2
    result = cluster_local_models(theta, None, 8)
    assert result.eps_auto and result.eps == pytest.approx(eps)
    # every cluster holds one blob only (sparser blobs may be left to the later search for
    # missed modes in PWARX, tested in test_identification.py)
    found = {c: set(labels_true[result.labels == c]) for c in range(result.n_clusters)}
    assert result.n_clusters >= 1 and all(len(v) == 1 for v in found.values())


def test_no_cluster_names_eps_min_pts_and_noise_share():
    theta = np.random.default_rng(0).normal(size=(50, 3, 2))
    with pytest.raises(ValueError, match=r"no cluster with eps = 1e-06 and min_pts = 10.*noise share 100%"):
        cluster_local_models(theta, 1e-6, 10)


def test_bad_settings():
    theta = _blobs()
    with pytest.raises(ValueError, match="embedding must be one of"):
        cluster_local_models(theta, 0.1, 5, embedding="cosine")
    with pytest.raises(ValueError, match="eps must be positive"):
        cluster_local_models(theta, -1.0, 5)
    with pytest.raises(ValueError, match="fewer than min_pts"):
        cluster_local_models(theta[:3], 0.1, 5)


def test_confidence_filter_drops_large_residuals():
    resvar = np.ones((10, 2))
    resvar[3, 1] = 10.0
    keep = confident_models(resvar, 3.0)
    assert keep.sum() == 9 and not keep[3]
