import numpy as np
import pytest

from pwa_pipeline.local_models import estimate_local_models, local_least_squares, local_sets


def test_local_fits_recover_a_linear_map_exactly():
    rng = np.random.default_rng(0)
    phi = rng.normal(size=(300, 3)) * [1.0, 100.0, 0.01]  # badly scaled columns
    theta = np.array([[1.0, -2.0], [0.03, 0.5], [40.0, 7.0]])
    local = estimate_local_models(phi, phi @ theta, n_rho=10, standardize=True)
    assert local.theta.shape == (300, 3, 2)
    np.testing.assert_allclose(local.theta, np.broadcast_to(theta, (300, 3, 2)), rtol=1e-8)
    assert np.all(local.residual_var < 1e-18)
    assert np.all(local.neighbours[:, 0] == np.arange(300))


def test_duplicate_regressors_keep_own_row_first():
    phi = np.repeat(np.arange(20.0)[:, None], 3, axis=0)
    idx = local_sets(phi, 4, standardize=False)
    assert np.all(idx[:, 0] == np.arange(60))


def test_n_rho_too_small_or_too_large():
    phi = np.random.default_rng(0).normal(size=(30, 4))
    with pytest.raises(ValueError, match="n_rho = 4 must exceed the regressor dimension d = 4"):
        estimate_local_models(phi, phi[:, :1], n_rho=4, standardize=True)
    with pytest.raises(ValueError, match="too few samples for n_rho = 40.*only 30"):
        estimate_local_models(phi, phi[:, :1], n_rho=40, standardize=True)


def test_singular_local_problem_is_reported_and_ridge_fixes_it():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(50, 1))
    phi = np.hstack([x, 2 * x])  # collinear columns: every local problem is singular
    nbrs = local_sets(phi, 6, standardize=False)
    with pytest.raises(ValueError, match="singular for 50 local set.*first: regressor row 0"):
        local_least_squares(phi, x, nbrs)
    local = local_least_squares(phi, x, nbrs, ridge=1e-8)
    assert np.all(np.isfinite(local.theta))
