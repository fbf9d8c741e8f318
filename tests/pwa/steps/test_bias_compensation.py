"""Bias-compensated refit of the sub-models for noise in the output lags (issue 10)."""

import numpy as np
import pytest

from pwa_pipeline import PWARX, make_hure_vasak
from pwa_pipeline.pwa import ResidualRegions, SVMRegions
from pwa_pipeline.pwa.steps.submodels import bias_compensated_refit, output_lag_columns, refit
from pwa_pipeline.regressors import build_regressors

#: y0(k) = a_i y0(k−1) + b_i u(k−1), mode 1 where u(k−1) > 0; y = y0 + e
THETAS = np.array([[[0.8], [1.0]], [[0.4], [-0.5]]])
SIGMA = 0.3


def _pwarx(n=6000, seed=0):
    """φ = [y(k−1), u(k−1)] from the noisy output, y(k), the true mode of each row and the
    output's noise variance."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=n)
    y0 = np.zeros(n)
    for k in range(1, n):
        y0[k] = THETAS[int(u[k - 1] > 0), :, 0] @ [y0[k - 1], u[k - 1]]
    y = y0 + SIGMA * rng.normal(size=n)
    reg = build_regressors([(u[:, None], y[:, None])], 1, 1, False)
    return reg.phi, reg.target, (u[:-1] > 0).astype(int)


def test_output_lag_columns_follow_eq_3():
    np.testing.assert_array_equal(output_lag_columns(2, 2, 7), [0, 0, 1, 1, -1, -1, -1])


def test_compensated_refit_is_closer_to_the_truth_than_least_squares():
    phi, y, mode = _pwarx()
    ls = refit(phi, y, mode, 2)
    bc, sigma2, compensated = bias_compensated_refit(phi, y, np.eye(2)[mode],
                                                     output_lag_columns(1, 1, 2))
    ls_err, bc_err = np.abs(ls - THETAS).max(), np.abs(bc - THETAS).max()
    assert ls_err > 0.04  # the noisy lag pulls a_i towards zero
    assert bc_err < 0.25 * ls_err
    assert compensated.all()
    assert sigma2 == pytest.approx([SIGMA**2], rel=0.1)


def test_a_region_whose_lags_cannot_hold_the_noise_keeps_least_squares():
    phi, y, mode = _pwarx()
    # a third group of rows whose output lag spreads far less than the noise: ΦᵀΦ − N·σ̂²
    # is not positive definite there
    rng = np.random.default_rng(1)
    extra = np.column_stack([0.01 * rng.normal(size=50), rng.normal(size=50)])
    phi = np.vstack([phi, extra])
    y = np.vstack([y, extra @ [[0.5], [1.0]] + 0.01 * rng.normal(size=(50, 1))])
    labels = np.concatenate([mode, np.full(50, 2)])
    bc, sigma2, compensated = bias_compensated_refit(phi, y, np.eye(3)[labels],
                                                     output_lag_columns(1, 1, 2))
    np.testing.assert_array_equal(compensated, [True, True, False])
    np.testing.assert_allclose(bc[2], refit(phi, y, labels, 3)[2], atol=1e-8)
    assert np.abs(bc[:2] - THETAS).max() < 0.05


def test_residual_regions_refits_compensated_given_the_output_lags():
    phi, y, mode = _pwarx()
    lags = output_lag_columns(1, 1, 2)
    fits = {bc: ResidualRegions(compensate_bias=bc).fit(
        phi, mode, 2, target=y, thetas=refit(phi, y, mode, 2), output_lags=lags)
        for bc in (False, True)}
    assert np.abs(fits[True].thetas_ - THETAS).max() < 0.5 * np.abs(
        fits[False].thetas_ - THETAS).max()
    assert fits[True].n_uncompensated_ == 0
    with pytest.raises(ValueError, match="output_lags must have one entry per column"):
        ResidualRegions().fit(phi, mode, 2, target=y, thetas=THETAS, output_lags=[0])


def test_the_default_compensates_and_the_paper_setting_does_not():
    data = make_hure_vasak(n_samples=2000, snr_db=30, seed=3)
    default = PWARX(na=1, nb=1).fit(data.u_train[0], data.y_train[0])
    plain = PWARX(na=1, nb=1, regions=ResidualRegions(compensate_bias=False)).fit(
        data.u_train[0], data.y_train[0])
    assert default.regions_.n_uncompensated_ == 0
    assert not np.allclose(default.thetas_, plain.thetas_, atol=1e-3)
    paper = PWARX.paper(1, 1, n_rho=20, eps=0.3, min_pts=5)
    assert isinstance(paper.step_objects()["regions"], SVMRegions)
    assert not isinstance(paper.step_objects()["regions"], ResidualRegions)
