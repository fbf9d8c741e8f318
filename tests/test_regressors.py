import numpy as np
import pytest

from pwa_pipeline._validation import as_experiments
from pwa_pipeline.regressors import build_regressors, regressor_dim, regressor_names


def test_order_follows_eq_2_3():
    # y has 2 outputs, u 1 input; values encode (channel, time) so positions are checkable.
    k = np.arange(6.0)
    y = np.column_stack([100 + k, 200 + k])
    u = (300 + k)[:, None]
    reg = build_regressors(as_experiments(u, y), na=2, nb=1, affine=True)
    # first row is k = 2: y1(1), y1(0), y2(1), y2(0), u1(1), 1
    np.testing.assert_array_equal(reg.phi[0], [101, 100, 201, 200, 301, 1])
    np.testing.assert_array_equal(reg.target[0], [102, 202])
    assert reg.phi.shape == (4, regressor_dim(2, 1, 2, 1, True))
    assert regressor_names(["a", "b"], ["c"], 2, 1, True) == [
        "a(k-1)", "a(k-2)", "b(k-1)", "b(k-2)", "c(k-1)", "1"]


def test_regressors_never_span_two_experiments():
    e1 = np.zeros((5, 1)), np.zeros((5, 1))
    e2 = np.full((5, 1), 1e6), np.full((5, 1), 1e6)
    reg = build_regressors(as_experiments([e1[0], e2[0]], [e1[1], e2[1]]), 2, 2, False)
    assert reg.phi.shape[0] == 2 * 3
    # every row is all-zero or all-1e6: no row mixes the two experiments
    assert set(np.unique(reg.phi)) <= {0.0, 1e6}
    assert all(np.ptp(row) == 0 for row in reg.phi)
    np.testing.assert_array_equal(reg.experiment, [0, 0, 0, 1, 1, 1])
    np.testing.assert_array_equal(reg.time, [2, 3, 4, 2, 3, 4])


def test_bad_orders_and_too_short():
    ex = as_experiments(np.zeros((3, 1)), np.zeros((3, 1)))
    with pytest.raises(ValueError, match="na >= 0"):
        build_regressors(ex, 0, 0, False)
    with pytest.raises(ValueError, match="no experiment is longer than max"):
        build_regressors(ex, 3, 1, False)


@pytest.mark.parametrize(
    ("u", "y", "message"),
    [
        (np.zeros((10, 1)), np.full((10, 1), np.nan), "non-finite value.*NaN at sample 0"),
        (np.zeros((10, 1)), np.r_[np.zeros(9), np.inf][:, None], "non-finite.*inf at sample 9"),
        (np.zeros((10, 1)), np.zeros((9, 1)), "different lengths: 10 and 9"),
        (np.zeros((10, 1, 1)), np.zeros((10, 1)), "must be 2-D.*shape \\(10, 1, 1\\)"),
        ([np.zeros((5, 1))], [np.zeros((5, 1)), np.zeros((5, 1))], "1 experiment.*has 2"),
        ([np.zeros((5, 1)), np.zeros((5, 2))], [np.zeros((5, 1))] * 2, "experiment 1 has 2 inputs"),
        (np.array(["a", "b"]), np.zeros((2, 1)), "must be numeric"),
    ],
)
def test_bad_input_is_named(u, y, message):
    with pytest.raises(ValueError, match=message):
        as_experiments(u, y)
