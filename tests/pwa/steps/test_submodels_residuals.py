"""Noise-normalised residual costs of rows under sub-models (pwa.submodels.residuals)."""

import numpy as np
import pytest
from scipy.stats import chi2

from pwa_pipeline.pwa.steps.submodels.residuals import (
    _cost,
    margin_weights,
    robust_noise_var,
    unexplained_cost,
)


def test_the_robust_noise_variance_is_the_median_over_the_chi2_median_and_ignores_outliers():
    rng = np.random.default_rng(0)
    sq = (rng.normal(size=(20000, 2)) * [0.1, 2.0]) ** 2
    np.testing.assert_array_equal(robust_noise_var(sq), np.median(sq, axis=0) / chi2.ppf(0.5, 1))
    np.testing.assert_allclose(robust_noise_var(sq), [0.01, 4.0], rtol=0.05)
    spoiled = sq.copy()
    spoiled[:1000] = 1e6  # 5 % of rows no sub-model explains
    np.testing.assert_allclose(robust_noise_var(spoiled), [0.01, 4.0], rtol=0.15)
    assert (robust_noise_var(np.zeros((5, 2))) > 0).all()  # never zero


def test_unexplained_rows_cost_far_more_than_the_rest():
    """Rows of a mode no sub-model holds stand out in unexplained_cost; rows of a sub-model
    cost about χ²(m)."""
    rng = np.random.default_rng(1)
    phi = np.column_stack([rng.uniform(-1, 1, 1000), np.ones(1000)])
    thetas = np.array([[[1.0], [0.0]], [[-1.0], [0.5]]])
    mode = rng.integers(0, 3, 1000)
    truth = np.concatenate([thetas, [[[0.0], [3.0]]]])  # a third mode, not among thetas
    y = np.einsum("nd,ndm->nm", phi, truth[mode]) + 0.05 * rng.normal(size=(1000, 1))
    cost = unexplained_cost(phi, y, thetas)
    assert np.median(cost[mode < 2]) < chi2.ppf(0.9, 1)
    assert cost[mode == 2].min() > 10 * chi2.ppf(0.999, 1)


@pytest.mark.parametrize("m", [1, 3, 9])
def test_the_cost_is_the_sum_over_outputs_bit_for_bit(m):
    rng = np.random.default_rng(m)
    sq = rng.random((4, 50, m))
    sigma2 = rng.random(m) + 0.1
    np.testing.assert_array_equal(_cost(sq, sigma2), (sq / sigma2).sum(axis=-1))
    np.testing.assert_array_equal(_cost(sq), sq.sum(axis=-1))


def test_rows_weigh_in_the_regions_only_where_one_sub_model_wins_clearly():
    np.testing.assert_array_equal(margin_weights(np.array([0.0, 3.9, 4.0, 4.1, np.inf])),
                                  [0.0, 0.0, 0.0, 1.0, 1.0])
    np.testing.assert_array_equal(margin_weights(np.array([1.0, 2.0]), threshold=1.5), [0, 1])
