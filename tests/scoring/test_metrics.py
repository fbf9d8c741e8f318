import numpy as np
import pytest

from pwa_pipeline.scoring.metrics import mean_nrmse, mean_r2, nrmse, r2_score, rmse


def test_hand_computed_values():
    y = np.array([[1.0, 0.0], [2.0, 2.0], [3.0, 4.0], [4.0, 6.0]])
    yhat = np.array([[1.0, 1.0], [2.0, 1.0], [4.0, 4.0], [3.0, 6.0]])
    # output 1: errors 0,0,1,-1 -> rmse sqrt(0.5); std of 1..4 = sqrt(1.25)
    # output 2: errors 1,-1,0,0 -> rmse sqrt(0.5); std of 0,2,4,6 = sqrt(5)
    np.testing.assert_allclose(rmse(y, yhat), [np.sqrt(0.5)] * 2)
    np.testing.assert_allclose(nrmse(y, yhat), [np.sqrt(0.5 / 1.25), np.sqrt(0.5 / 5)])
    np.testing.assert_allclose(r2_score(y, yhat), [1 - 0.5 / 1.25, 1 - 0.5 / 5])
    assert mean_nrmse(y, yhat) == pytest.approx((np.sqrt(0.4) + np.sqrt(0.1)) / 2)
    assert mean_r2(y, yhat) == pytest.approx((0.6 + 0.9) / 2)


def test_r2_uses_measured_mean_not_papers_typo():
    y = np.array([0.0, 1.0, 2.0, 3.0])
    yhat = y + 10.0  # a constant offset: the paper's eq. (22) with the estimate's mean would hide it
    assert r2_score(y, yhat)[0] == pytest.approx(1 - 100 / 1.25)


def test_divergent_prediction_scores_inf_and_shapes_checked():
    y = np.arange(5.0)[:, None]
    assert np.isinf(nrmse(y, np.full_like(y, np.nan))[0])
    with pytest.raises(ValueError, match="differ in shape"):
        nrmse(y, y[:4])
    with pytest.raises(ValueError, match="y_true contains NaN"):
        nrmse(np.array([[np.nan], [1.0]]), np.zeros((2, 1)))


def test_match_submodels_pairs_by_parameters():
    from pwa_pipeline.scoring.metrics import match_submodels

    true = np.array([[[1.0]], [[2.0]], [[3.0]]])
    est = np.array([[[3.1]], [[0.95]]])
    mode_of, error = match_submodels(est, true)
    np.testing.assert_array_equal(mode_of, [2, 0])
    np.testing.assert_allclose(error, [0.1, 0.05])
    mode_of, error = match_submodels(np.array([[[1.0]], [[1.1]], [[9.0]]]), true[:2])
    assert (mode_of == -1).sum() == 1 and np.isnan(error[mode_of == -1][0])
