"""A simulated system's parameters written over a larger regressor predict as over its own."""

import numpy as np

from pwa_pipeline.regressors import lagged_matrix
from pwa_pipeline.scoring.truth import embedded_thetas


def test_the_truth_over_a_larger_regressor_predicts_as_over_its_own():
    """Over a structure search's regressor (one more output lag, two more input lags, a
    constant) the system's parameters give the same predictions; a regressor that lacks
    one of the system's entries (fewer lags, no constant) takes none."""
    rng = np.random.default_rng(0)
    m, r, na, nb = 2, 3, 1, 2
    thetas = rng.normal(size=(4, m * na + r * nb + 1, m))
    u, y = rng.normal(size=(50, r)), rng.normal(size=(50, m))
    big = embedded_thetas(thetas, m, r, na, nb, True, na + 1, nb + 2, True)
    assert big.shape == (4, m * (na + 1) + r * (nb + 2) + 1, m)
    own, wide = lagged_matrix(u, y, na, nb, True), lagged_matrix(u, y, na + 1, nb + 2, True)
    shift = own.shape[0] - wide.shape[0]  # (the larger regressor starts later)
    for i in range(4):
        np.testing.assert_allclose(wide @ big[i], own[shift:] @ thetas[i], rtol=0, atol=1e-12)
    assert embedded_thetas(thetas, m, r, na, nb, True, na + 1, nb - 1, True) is None
    assert embedded_thetas(thetas, m, r, na, nb, True, na + 1, nb, False) is None
