import numpy as np
from scipy.spatial.distance import pdist

from pwa_pipeline.pwa.steps.clustering import cluster_local_models
from pwa_pipeline.pwa.steps.embedding import exact_embedding, literal_embedding


def test_literal_layout_eq_9_10():
    theta = np.arange(6.0).reshape(1, 3, 2)  # d = 3, m = 2
    v = literal_embedding(theta)[0]
    col0, col1 = theta[0, :, 0], theta[0, :, 1]
    np.testing.assert_array_equal(v, np.r_[col0, col1, col0 - col1, col1 - col0])
    assert v.size == 3 * 2**2


def test_exact_embedding_has_the_papers_distances():
    rng = np.random.default_rng(0)
    for m in (1, 2, 3, 6):
        theta = rng.normal(size=(40, 5, m))
        lit, ex = literal_embedding(theta), exact_embedding(theta)
        assert ex.shape[1] == 5 * m and lit.shape[1] == 5 * m**2
        np.testing.assert_allclose(pdist(ex), pdist(lit), rtol=1e-12, atol=1e-12)


def test_exact_and_literal_give_same_dbscan_labels():
    rng = np.random.default_rng(1)
    centres = rng.normal(size=(3, 4, 3))
    theta = np.concatenate([c + 0.02 * rng.normal(size=(60, 4, 3)) for c in centres])
    theta = np.concatenate([theta, rng.normal(scale=3, size=(15, 4, 3))])  # noise points
    a, _ = cluster_local_models(theta, 0.3, 5, "exact")
    b, _ = cluster_local_models(theta, 0.3, 5, "literal")
    np.testing.assert_array_equal(a, b)
    assert a.max() + 1 == 3 and (a[-15:] == -1).mean() > 0.8
