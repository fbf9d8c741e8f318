"""Step 6 on small hand-built cases."""

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.svm import LinearSVC

from pwa_pipeline.pwa import PWARX, SVMRegions


def _halfplane(scale=(1.0, 1.0), n=600, seed=0):
    """Two classes split by x1 + 2·x2 = 0.5 in unit coordinates, with a margin of 0.1,
    and φ = the unit coordinates times ``scale`` per column."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (n, 2))
    side = x @ [1.0, 2.0] - 0.5
    x = x[np.abs(side) > 0.1]
    return x * scale, (x @ [1.0, 2.0] > 0.5).astype(int), x


def test_two_classes_are_separated_along_the_true_boundary():
    phi, labels, _ = _halfplane()
    reg = SVMRegions(C=100.0).fit(phi, labels)
    assert reg.n_regions_ == 2 and np.mean(reg.predict(phi) == labels) == 1.0
    normal = reg.coef_[1] - reg.coef_[0]
    cosine = normal @ [1.0, 2.0] / np.linalg.norm(normal) / np.sqrt(5.0)
    assert cosine > 0.98
    # the offset: the boundary meets the line t·(1, 2) where x1 + 2·x2 = 5t = 0.5
    b = reg.intercept_[1] - reg.intercept_[0]
    assert 5 * -b / (normal @ [1.0, 2.0]) == pytest.approx(0.5, abs=0.03)


def test_hyperplanes_are_mapped_back_to_the_units_of_phi():
    scale = np.array([1000.0, 0.001])
    phi, labels, x = _halfplane(scale=scale)
    reg = SVMRegions(C=100.0).fit(phi, labels)
    unit = SVMRegions(C=100.0).fit(x, labels)
    np.testing.assert_array_equal(reg.predict(phi), unit.predict(x))
    # a hyperplane in φ's units equals the unit-coordinate one divided by the column scale
    np.testing.assert_allclose(reg.coef_ * scale, unit.coef_, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(reg.intercept_, unit.intercept_, rtol=1e-6)


def test_two_classes_solve_crammer_and_singers_problem():
    # overlapping classes (a fifth of the labels flipped), so that C shapes the solution
    rng = np.random.default_rng(5)
    phi = rng.normal(size=(800, 3)) * [2.0, 0.5, 1.0] + [1.0, 0.0, -3.0]
    labels = (phi @ [1.0, -2.0, 0.5] > 0).astype(int)
    labels[rng.random(800) < 0.2] ^= 1
    weight = rng.uniform(0.5, 2.0, 800)
    reg = SVMRegions(C=0.3, tol=1e-8).fit(phi, labels, sample_weight=weight)
    mean, std = phi.mean(axis=0), phi.std(axis=0)
    cs = LinearSVC(C=0.3, multi_class="crammer_singer", tol=1e-8, max_iter=10**6)
    cs.fit((phi - mean) / std, labels, sample_weight=weight)
    v = cs.coef_[0] / std
    np.testing.assert_allclose(reg.coef_[1] - reg.coef_[0], v, rtol=1e-4)
    np.testing.assert_allclose(reg.intercept_[1] - reg.intercept_[0],
                               cs.intercept_[0] - v @ mean, rtol=1e-4)
    np.testing.assert_allclose(reg.coef_[0], -reg.coef_[1])


def test_a_label_with_no_row_is_never_predicted():
    rng = np.random.default_rng(2)
    phi = rng.normal(size=(300, 2))
    labels = np.where(phi[:, 0] > 0, 2, 0)  # label 1 has no row
    reg = SVMRegions().fit(phi, labels, n_regions=3)
    assert reg.intercept_[1] == -np.inf and np.all(reg.coef_[1] == 0)
    assert 1 not in set(reg.predict(rng.normal(size=(5000, 2)) * 10))


def test_noise_and_zero_weight_rows_are_left_out():
    phi, labels, _ = _halfplane()
    poisoned = np.concatenate([labels, np.ones(200, int), np.zeros(200, int)])
    junk = np.random.default_rng(3).uniform(-1, 1, (400, 2))
    phi2 = np.vstack([phi, junk])
    clean = SVMRegions(C=100.0).fit(phi, labels)
    with_noise = SVMRegions(C=100.0).fit(phi2, np.where(np.arange(len(poisoned)) < len(labels),
                                                        poisoned, -1))
    weights = (np.arange(len(poisoned)) < len(labels)).astype(float)
    weighted = SVMRegions(C=100.0).fit(phi2, poisoned, sample_weight=weights)
    for other in (with_noise, weighted):
        np.testing.assert_allclose(other.coef_, clean.coef_)
        np.testing.assert_allclose(other.intercept_, clean.intercept_)


def test_one_class_is_one_region_and_predict_needs_fit():
    reg = SVMRegions().fit(np.ones((10, 2)), np.zeros(10, int))
    assert reg.n_regions_ == 1 and set(reg.predict(np.zeros((4, 2)))) == {0}
    with pytest.raises(NotFittedError):
        SVMRegions().predict(np.ones((2, 2)))


def test_capped_rows_stand_for_their_class():
    from pwa_pipeline.pwa.steps.regions import _capped_per_class

    rows = np.arange(1000)
    labels = np.r_[np.zeros(900, int), np.ones(80, int), np.full(20, 2)]
    kept, represents = _capped_per_class(rows, labels, 100, np.random.default_rng(0))
    assert np.all(np.diff(kept) > 0)
    counts = np.bincount(labels[kept])
    assert list(counts) == [100, 80, 20]  # the rare classes keep every row
    # the classes keep the proportions they have among all rows, at mean weight 1
    np.testing.assert_allclose(np.bincount(labels[kept], weights=represents),
                               np.array([900, 80, 20]) * kept.size / 1000)
    assert represents.mean() == pytest.approx(1.0)


def test_a_row_cap_keeps_the_boundary_of_the_full_fit():
    rng = np.random.default_rng(4)
    x = rng.uniform(-1, 1, (20000, 2))
    labels = (x[:, 0] + 0.3 * rng.normal(size=20000) > 0.6).astype(int)  # overlapping, 80/20
    full = SVMRegions(max_rows=None).fit(x, labels)
    capped = SVMRegions(max_rows=2000).fit(x, labels)
    fresh = rng.uniform(-1, 1, (20000, 2))
    assert np.mean(full.predict(fresh) == capped.predict(fresh)) > 0.98
    # below the cap every row is used: the same fit
    small = SVMRegions(max_rows=None).fit(x[:1500], labels[:1500])
    same = SVMRegions(max_rows=2000).fit(x[:1500], labels[:1500])
    np.testing.assert_array_equal(small.coef_, same.coef_)


def test_the_paper_preset_solves_at_1e_2_with_the_regions_of_a_tight_solve():
    regions = PWARX.paper(1, 1, n_rho=10, eps=0.1, min_pts=5).regions
    assert regions.get_params()["tol"] == 1e-2 and regions.get_params()["max_rows"] is None
    # six overlapping sectors (10 % of labels flipped): the solver's hard case
    rng = np.random.default_rng(4)
    x = rng.normal(size=(4000, 3))
    labels = ((np.arctan2(x[:, 1], x[:, 0]) + np.pi) // (np.pi / 3)).astype(int) % 6
    flip = rng.random(4000) < 0.1
    labels[flip] = rng.integers(0, 6, flip.sum())
    loose = clone(regions).fit(x, labels)
    tight = clone(regions).set_params(tol=1e-6).fit(x, labels)
    # where classes overlap this much, rows near the boundaries move between solves at any
    # tolerance (1e-3: 99.9 %, 1e-2: 99.8 %, 1e-1: 99.3 % of rows agree with 1e-6)
    assert np.mean(loose.predict(x) == tight.predict(x)) >= 0.995
