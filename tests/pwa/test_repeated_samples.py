"""A record whose samples repeat exactly (an experiment given twice, a tiled record) fits as
the record once: repeated (φ, y) rows count once in steps 2–4 (issue 12)."""

import numpy as np
import pytest

from pwa_pipeline import PWARX, make_hure_vasak
from pwa_pipeline.pwa import DBSCANClustering, LocalLeastSquares
from pwa_pipeline.pwa.steps.neighbours import distinct_rows


def test_distinct_rows_in_order_of_first_occurrence():
    x = np.array([[1.0, 2.0], [0.0, 1.0], [1.0, 2.0], [-0.0, 1.0], [3.0, 3.0]])
    first, inverse = distinct_rows(x)
    np.testing.assert_array_equal(first, [0, 1, 4])  # −0.0 equals 0.0
    np.testing.assert_array_equal(inverse, [0, 1, 0, 1, 2])
    np.testing.assert_array_equal(x[first][inverse], x)


@pytest.mark.parametrize("reps", [2, 10])
def test_a_tiled_record_has_the_local_models_of_the_record_once(reps):
    rng = np.random.default_rng(4)
    phi = rng.normal(size=(400, 6))
    target = phi @ rng.normal(size=(6, 2)) + 0.1 * rng.normal(size=(400, 2))
    once = LocalLeastSquares(n_rho=30).fit(phi, target)
    tiled = LocalLeastSquares(n_rho=30).fit(np.tile(phi, (reps, 1)), np.tile(target, (reps, 1)))
    n = len(phi)
    np.testing.assert_array_equal(tiled.original_, np.tile(np.arange(n), reps))
    assert tiled.n_degenerate_ == 0
    np.testing.assert_allclose(tiled.theta_, np.tile(once.theta_, (reps, 1, 1)), rtol=1e-12)
    np.testing.assert_allclose(tiled.residual_var_, np.tile(once.residual_var_, (reps, 1)),
                               rtol=1e-12)
    np.testing.assert_array_equal(tiled.neighbours_[:, 0], np.arange(reps * n))
    np.testing.assert_array_equal(tiled.neighbours_[:, 1:], np.tile(once.neighbours_[:, 1:],
                                                                     (reps, 1)))


def test_equal_regressors_with_different_outputs_stay_distinct():
    rng = np.random.default_rng(5)
    phi = np.repeat(rng.normal(size=(100, 3)), 2, axis=0)
    target = rng.normal(size=(200, 1))  # two measurements at every regressor row
    local = LocalLeastSquares(n_rho=8).fit(phi, target)
    np.testing.assert_array_equal(local.original_, np.arange(200))


def test_too_few_distinct_samples_is_a_clear_error():
    phi = np.random.default_rng(0).normal(size=(10, 2))
    with pytest.raises(ValueError, match="only 10 distinct regressor rows \\(50 with repeats\\)"):
        LocalLeastSquares(n_rho=12).fit(np.tile(phi, (5, 1)), np.tile(phi[:, :1], (5, 1)))


@pytest.mark.parametrize("step", [DBSCANClustering(),
                                  DBSCANClustering(eps=0.18, min_pts=8, max_clustered=None)])
def test_a_tiled_record_is_clustered_as_the_record_once(sim_30db, step):
    from pwa_pipeline.regressors import build_regressors

    reg = build_regressors([(sim_30db.u_train[0], sim_30db.y_train[0])], 1, 1, False)
    once = LocalLeastSquares().fit(reg.phi, reg.target)
    tiled = LocalLeastSquares().fit(np.tile(reg.phi, (3, 1)), np.tile(reg.target, (3, 1)))
    a = step.fit(once, reg.target)
    a_labels, a_clustered, a_eps = a.labels_, a.clustered_, a.eps_
    b = step.fit(tiled, np.tile(reg.target, (3, 1)))
    assert a.n_clusters_ >= 4
    np.testing.assert_array_equal(b.labels_, np.tile(a_labels, 3))
    np.testing.assert_array_equal(b.clustered_, np.tile(a_clustered, 3))
    assert b.eps_ == a_eps


def test_a_record_given_ten_times_gives_the_sub_models_of_the_record_once():
    data = make_hure_vasak(n_samples=1500, snr_db=30.0, seed=3)
    once = PWARX(na=1, nb=1).fit(data.u_train[0], data.y_train[0])
    tiled = PWARX(na=1, nb=1).fit([data.u_train[0]] * 10, [data.y_train[0]] * 10)
    assert tiled.n_submodels_ == once.n_submodels_ == 4
    np.testing.assert_array_equal(tiled.steps_["clustering"].labels_,
                                  np.tile(once.steps_["clustering"].labels_, 10))
    # steps 5–6 see the copies (their region SVM weighs a repeated row more against its
    # regularisation): the sub-models agree to a small fraction of their noise
    np.testing.assert_allclose(tiled.thetas_, once.thetas_, atol=1e-3)
    phi = np.random.default_rng(0).normal(size=(2000, 4))
    assert np.mean(tiled.regions_.predict(phi) == once.regions_.predict(phi)) > 0.995


def test_the_missed_mode_search_sizes_its_local_sets_by_distinct_rows(sim_30db):
    """Step 5 re-runs steps 2–4 on rows no sub-model explains: a few distinct rows given ten
    times still get local sets (n_ρ from the distinct count, not the rows with copies)."""
    from pwa_pipeline.pwa.steps.submodels.refined import _missed_mode_clusters, _search_steps
    from pwa_pipeline.regressors import build_regressors

    reg = build_regressors([(sim_30db.u_train[0], sim_30db.y_train[0])], 1, 1, False)
    local = LocalLeastSquares().fit(reg.phi, reg.target)
    clustering = DBSCANClustering().fit(local, reg.target)
    assert local.n_rho_ > 10
    rows = np.flatnonzero(clustering.labels_ == 0)[:10]  # 10 distinct rows, fewer than n_ρ
    steps = _search_steps(local, clustering)
    once = _missed_mode_clusters(reg.phi[rows], reg.target[rows], *steps)
    tiled = _missed_mode_clusters(np.tile(reg.phi[rows], (10, 1)),
                                  np.tile(reg.target[rows], (10, 1)), *steps)
    assert once is not None and tiled is not None
    np.testing.assert_array_equal(tiled, np.tile(once, 10))
