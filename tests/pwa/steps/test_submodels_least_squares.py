"""Least-squares sub-models on the rows of each label (pwa.submodels.least_squares)."""

import numpy as np

from pwa_pipeline.pwa.steps.submodels.least_squares import _normal_solves, least_squares, refit


def test_least_squares_equals_lstsq_well_conditioned_or_not():
    rng = np.random.default_rng(3)
    # columns of very different sizes (the normal matrix is solved after scaling them)
    phi = rng.normal(size=(2000, 6)) * np.array([1e-3, 1.0, 1e4, 5.0, 1.0, 1.0])
    phi[:, 4] += 3 * phi[:, 5]  # correlated, still well conditioned
    target = phi @ rng.normal(size=(6, 2)) + 0.1 * rng.normal(size=(2000, 2))
    ref = np.linalg.lstsq(phi, target, rcond=None)[0]
    # each θ_j times its column's size: what a coefficient contributes to the prediction
    size = np.sqrt((phi**2).mean(axis=0))[:, None]
    got = least_squares(phi, target)
    np.testing.assert_allclose(got * size, ref * size, rtol=0,
                               atol=1e-10 * np.abs(ref * size).max())
    # refit: every row under one label; rows by label, −1 left out, a label with < d rows NaN
    thetas = refit(phi, target, np.zeros(2000, int), 1)
    np.testing.assert_allclose(thetas[0] * size, ref * size, rtol=0,
                               atol=1e-10 * np.abs(ref * size).max())
    labels = np.zeros(2000, int)
    labels[::7], labels[-300:], labels[:4], labels[4:50] = 1, 2, 3, -1
    thetas = refit(phi, target, labels, 4)
    for i in range(3):
        rows = labels == i
        one = np.linalg.lstsq(phi[rows], target[rows], rcond=None)[0]
        np.testing.assert_allclose(thetas[i] * size, one * size, rtol=0,
                                   atol=1e-10 * np.abs(one * size).max())
    assert np.isnan(thetas[3]).all()
    # rank deficient (a repeated column) and a zero column: lstsq's minimum-norm solution
    for bad in (np.column_stack([phi, phi[:, 1]]), np.column_stack([phi, np.zeros(2000)])):
        ref = np.linalg.lstsq(bad, target, rcond=None)[0]
        np.testing.assert_allclose(least_squares(bad, target), ref, rtol=1e-12, atol=1e-12)


def test_refit_takes_a_row_sets_fit_from_its_memo():
    # The memo is keyed by the rows, not the label: relabelled groups reuse their fits, and
    # what it returns is what a fresh refit gives, bit for bit.
    rng = np.random.default_rng(8)
    phi, target = rng.normal(size=(200, 3)), rng.normal(size=(200, 2))
    labels = rng.integers(0, 4, 200)
    memo = {}
    first = refit(phi, target, labels, 4, memo)
    assert len(memo) == 4
    swapped = np.array([1, 0, 2, 3])[labels]
    second = refit(phi, target, swapped, 4, memo)
    np.testing.assert_array_equal(second, first[[1, 0, 2, 3]])
    assert len(memo) == 4  # nothing refitted
    np.testing.assert_array_equal(second, refit(phi, target, swapped, 4))
    merged = np.where(labels == 3, 2, labels)
    refit(phi, target, merged, 3, memo)
    assert len(memo) == 5  # only the merged group is new


def test_stacked_normal_solves_are_least_squares_or_nan_where_ill_conditioned():
    """_normal_solves solves a stack of normal equations as least_squares would, and marks
    with NaN the ones least_squares hands to lstsq (a zero or a repeated column)."""
    rng = np.random.default_rng(2)
    blocks = [rng.normal(size=(80, 3)) * [1.0, 1e3, 1e-2] for _ in range(3)]
    blocks[1][:, 2] = 0.0  # a zero column
    blocks[2][:, 2] = blocks[2][:, 0]  # a repeated column
    targets = [rng.normal(size=(80, 2)) for _ in blocks]
    grams = np.stack([b.T @ b for b in blocks])
    rhs = np.stack([b.T @ t for b, t in zip(blocks, targets)])
    got = _normal_solves(grams, rhs)
    np.testing.assert_allclose(got[0], least_squares(blocks[0], targets[0]), rtol=1e-9,
                               atol=1e-12)
    assert np.isnan(got[1]).all() and np.isnan(got[2]).all()
