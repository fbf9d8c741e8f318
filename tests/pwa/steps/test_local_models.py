import numpy as np
import pytest

from pwa_pipeline.pwa import LocalLeastSquares
from pwa_pipeline.pwa.steps.local_models import local_least_squares, local_sets


def test_local_fits_recover_a_linear_map_exactly():
    rng = np.random.default_rng(0)
    phi = rng.normal(size=(300, 3)) * [1.0, 100.0, 0.01]  # badly scaled columns
    theta = np.array([[1.0, -2.0], [0.03, 0.5], [40.0, 7.0]])
    local = LocalLeastSquares(n_rho=10).fit(phi, phi @ theta)
    assert local.theta_.shape == (300, 3, 2) and local.n_rho_ == 10
    np.testing.assert_allclose(local.theta_, np.broadcast_to(theta, (300, 3, 2)), rtol=1e-8)
    assert np.all(local.residual_var_ < 1e-18)
    assert np.all(local.neighbours_[:, 0] == np.arange(300))


def test_default_n_rho_is_three_times_d():
    phi = np.random.default_rng(0).normal(size=(100, 4))
    assert LocalLeastSquares().fit(phi, phi[:, :1]).neighbours_.shape == (100, 12)


def test_standardised_search_is_not_dominated_by_a_large_channel():
    rng = np.random.default_rng(1)
    phi = np.column_stack([rng.normal(size=200), 1000 * rng.normal(size=200)])
    raw = local_sets(phi, 5, standardize=False)
    std = local_sets(phi, 5, standardize=True)
    # raw neighbours are close in the large column only; z-scored ones in both
    spread = lambda idx: np.abs(phi[idx, 0] - phi[idx[:, :1], 0]).mean()  # noqa: E731
    assert spread(std) < 0.5 * spread(raw)


def test_duplicate_regressors_keep_own_row_first():
    phi = np.repeat(np.arange(20.0)[:, None], 3, axis=0)
    idx = local_sets(phi, 4, standardize=False)
    assert np.all(idx[:, 0] == np.arange(60))


def test_n_rho_too_small_or_too_large():
    phi = np.random.default_rng(0).normal(size=(30, 4))
    with pytest.raises(ValueError, match="n_rho = 4 must exceed the regressor dimension d = 4"):
        LocalLeastSquares(n_rho=4).fit(phi, phi[:, :1])
    with pytest.raises(ValueError, match="too few samples for n_rho = 40.*only 30"):
        LocalLeastSquares(n_rho=40).fit(phi, phi[:, :1])


def test_degenerate_local_sets_are_marked_and_get_the_minimum_norm_solution():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(50, 1))
    phi = np.hstack([x, 2 * x])  # collinear columns: every local problem is rank-deficient
    local = LocalLeastSquares(n_rho=6, standardize=False).fit(phi, 3 * x)
    assert local.n_degenerate_ == 50 and local.degenerate_.all()
    # y = 3x = a·x + b·2x, minimum-norm in unit-RMS columns (x and 2x scale alike): a = 2b
    a, b = local.theta_[:, 0, 0], local.theta_[:, 1, 0]
    np.testing.assert_allclose(a + 2 * b, 3.0)
    np.testing.assert_allclose(a, 2 * b)
    ridged = local_least_squares(phi, 3 * x, local.neighbours_, ridge=1e-8)
    assert np.all(np.isfinite(ridged[0])) and not ridged[3].any()


def test_only_the_rank_deficient_sets_are_marked():
    rng = np.random.default_rng(1)
    phi = rng.normal(size=(200, 3))
    phi[:20, 1:] = [5.0, 7.0]  # a hold of two inputs: constant, hence collinear, columns
    phi[:20, 0] = np.linspace(100, 101, 20)  # far from the rest, so their sets stay inside
    local = LocalLeastSquares(n_rho=8, standardize=False).fit(phi, phi @ [[1.0], [2.0], [3.0]])
    assert set(np.flatnonzero(local.degenerate_)) <= set(range(20))
    assert local.degenerate_[:20].sum() >= 10
    good = ~local.degenerate_
    np.testing.assert_allclose(local.theta_[good, :, 0],
                               np.broadcast_to([1.0, 2.0, 3.0], (good.sum(), 3)))


@pytest.mark.parametrize(("standardize", "ridge"), [(True, 0.0), (False, 0.0), (True, 0.1)])
def test_same_local_models_as_a_plain_implementation(standardize, ridge):
    # A seeded 3-output ARX record with 16 regressors (the blocked neighbour search), against
    # scikit-learn's brute-force neighbours and one least-squares solve per local set.
    from sklearn.neighbors import NearestNeighbors

    from pwa_pipeline._arrays import column_rms
    from pwa_pipeline.regressors import build_regressors

    rng = np.random.default_rng(11)
    u = rng.normal(size=(1500, 2)).cumsum(axis=0) * 0.1 + rng.normal(size=(1500, 2))
    y = np.zeros((1500, 3))
    a, b = rng.normal(size=(3, 3)) * 0.2, rng.normal(size=(2, 3))
    for k in range(1, 1500):
        y[k] = y[k - 1] @ a + u[k - 1] @ b + 0.01 * rng.normal(size=3)
    reg = build_regressors([(u, y)], 4, 2, False)
    phi, target = reg.phi, reg.target
    assert phi.shape[1] == 16
    local = LocalLeastSquares(n_rho=40, standardize=standardize, ridge=ridge).fit(phi, target)

    x = (phi - phi.mean(0)) / phi.std(0) if standardize else phi
    ref = NearestNeighbors(n_neighbors=40, algorithm="brute").fit(x).kneighbors(
        x, return_distance=False)
    np.testing.assert_array_equal(np.sort(local.neighbours_, 1), np.sort(ref, 1))
    scale = column_rms(phi)
    for k in range(0, len(phi), 37):
        p, t = phi[ref[k]] / scale, target[ref[k]]
        if ridge:
            th = np.linalg.solve(p.T @ p + ridge * np.eye(16), p.T @ t)
        else:
            th = np.linalg.lstsq(p, t, rcond=None)[0]
        np.testing.assert_allclose(local.theta_[k], th / scale[:, None], rtol=1e-8,
                                   atol=1e-10 * np.abs(th / scale[:, None]).max())
        np.testing.assert_allclose(local.residual_var_[k],
                                   ((t - p @ th) ** 2).sum(0) / (40 - 16), rtol=1e-7)


def test_rank_deficient_sets_match_the_pseudo_inverse_of_the_local_matrix():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(200, 2))
    phi = np.column_stack([x, x @ [1.0, -2.0]])  # rank 2 of 3 everywhere
    target = rng.normal(size=(200, 2))
    local = LocalLeastSquares(n_rho=12, standardize=False).fit(phi, target)
    assert local.degenerate_.all()
    from pwa_pipeline._arrays import column_rms

    scale = column_rms(phi)
    for k in range(0, 200, 23):
        p, t = phi[local.neighbours_[k]] / scale, target[local.neighbours_[k]]
        th = np.linalg.pinv(p, rtol=1e-10) @ t
        np.testing.assert_allclose(local.theta_[k] * scale[:, None], th, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(local.residual_var_[k], ((t - p @ th) ** 2).sum(0) / 9,
                                   rtol=1e-9)


def test_ill_conditioned_local_sets_are_solved_to_their_conditioning():
    # Lagged outputs of a slow signal are nearly collinear (condition numbers up to 7e8 on
    # the robot): θ_k must agree with an SVD-based solve to about κ · rounding.
    from pwa_pipeline._arrays import column_rms
    from pwa_pipeline.pwa.steps.local_models import local_least_squares

    rng = np.random.default_rng(5)
    base = rng.normal(size=(400, 1))
    phi = np.hstack([base, base + 1e-7 * rng.normal(size=(400, 1)), rng.normal(size=(400, 3)),
                     np.ones((400, 1))])
    target = phi @ rng.normal(size=(6, 2)) + 1e-3 * rng.normal(size=(400, 2))
    neighbours = np.array([rng.permutation(400)[:30] for _ in range(50)])
    theta, resvar, scale, degenerate = local_least_squares(phi, target, neighbours)
    assert not degenerate.any()
    for k in range(50):
        p, t = phi[neighbours[k]] / scale, target[neighbours[k]]
        assert np.linalg.cond(p) > 1e6
        th = np.linalg.lstsq(p, t, rcond=None)[0] / scale[:, None]
        np.testing.assert_allclose(theta[k], th, rtol=0, atol=1e-6 * np.abs(th).max())
        np.testing.assert_allclose(resvar[k], ((t - p @ (th * scale[:, None])) ** 2).sum(0)
                                   / (30 - 6), rtol=1e-6)
    assert np.array_equal(scale, column_rms(phi))


def test_a_nearly_triangular_local_set_keeps_its_accuracy():
    # Columns nearly along the first unit vectors: a reflection of the wrong sign would
    # cancel (x − ‖x‖e₁ ≈ 0) and lose the digits that the stable choice keeps.
    from pwa_pipeline.pwa.steps.local_models import local_least_squares

    rng = np.random.default_rng(6)
    phi = np.vstack([np.triu(rng.uniform(1, 2, (4, 4))), 1e-6 * rng.normal(size=(26, 4))])
    target = phi @ rng.normal(size=(4, 1)) + 1e-9 * rng.normal(size=(30, 1))
    theta, resvar, scale, _ = local_least_squares(phi, target, np.arange(30)[None])
    p = phi / scale
    th = np.linalg.lstsq(p, target, rcond=None)[0] / scale[:, None]
    np.testing.assert_allclose(theta[0], th, rtol=1e-9)
    np.testing.assert_allclose(resvar[0], ((target - phi @ th) ** 2).sum(0) / 26, rtol=1e-6)


@pytest.mark.parametrize("dims", [3, 16])  # k-d tree and blocked search
def test_a_subset_of_local_models_equals_those_of_every_sample(dims):
    rng = np.random.default_rng(3)
    phi = rng.normal(size=(900, dims))
    target = np.tanh(phi[:, :2]) + 0.01 * rng.normal(size=(900, 2))
    every = LocalLeastSquares(n_rho=3 * dims, max_sets=None).fit(phi, target)
    some = LocalLeastSquares(n_rho=3 * dims, max_sets=200, random_state=1).fit(phi, target)
    rows = np.flatnonzero(some.estimated_)
    assert some.n_estimated_ == len(rows) == 200 and every.estimated_.all()
    np.testing.assert_array_equal(some.neighbours_[rows], every.neighbours_[rows])
    np.testing.assert_allclose(some.theta_[rows], every.theta_[rows], rtol=1e-12)
    np.testing.assert_allclose(some.residual_var_[rows], every.residual_var_[rows], rtol=1e-12)
    rest = ~some.estimated_
    assert np.isnan(some.theta_[rest]).all() and np.isnan(some.residual_var_[rest]).all()
    assert (some.neighbours_[rest] == -1).all() and not some.degenerate_[rest].any()
    other = LocalLeastSquares(n_rho=3 * dims, max_sets=200, random_state=2).fit(phi, target)
    assert not np.array_equal(other.estimated_, some.estimated_)  # the seed draws the subset


def test_a_tiled_record_draws_the_subset_of_the_record_once():
    rng = np.random.default_rng(4)
    phi = rng.normal(size=(400, 5))
    target = phi @ rng.normal(size=(5, 1))
    once = LocalLeastSquares(n_rho=20, max_sets=100).fit(phi, target)
    tiled = LocalLeastSquares(n_rho=20, max_sets=100).fit(np.tile(phi, (3, 1)),
                                                        np.tile(target, (3, 1)))
    np.testing.assert_array_equal(tiled.estimated_, np.tile(once.estimated_, 3))
    np.testing.assert_array_equal(tiled.theta_, np.tile(once.theta_, (3, 1, 1)))
    assert tiled.n_estimated_ == 300
    rows = np.flatnonzero(tiled.estimated_)
    np.testing.assert_array_equal(tiled.neighbours_[rows, 0], rows)


def test_samples_without_a_local_model_are_marked_and_a_pickle_loads_the_same_step():
    """With ``max_sets`` the samples left out hold NaN (θ_k, residual variance) and −1 (local
    set); the estimated ones hold the local models of a fit of every sample, copies of a
    sample their original's; a pickled step loads with the same arrays, and a step fitted
    again keeps nothing of its previous fit."""
    import pickle

    rng = np.random.default_rng(5)
    phi = np.tile(rng.normal(size=(600, 4)), (2, 1))  # a repeated record: copies too
    target = np.tanh(phi[:, :2])
    some = LocalLeastSquares(n_rho=12, max_sets=60).fit(phi, target)
    every = LocalLeastSquares(n_rho=12, max_sets=None).fit(phi, target)
    est = some.estimated_
    assert est.sum() == some.n_estimated_ == 120  # 60 distinct samples, each twice
    np.testing.assert_array_equal(est[:600], est[600:])
    assert np.isnan(some.theta_[~est]).all() and np.isnan(some.residual_var_[~est]).all()
    assert (some.neighbours_[~est] == -1).all()
    assert not np.isnan(some.theta_[est]).any() and (some.neighbours_[est] >= 0).all()
    np.testing.assert_allclose(some.theta_[est], every.theta_[est], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(some.residual_var_[est], every.residual_var_[est],
                               rtol=1e-10, atol=1e-14)
    np.testing.assert_array_equal(some.neighbours_[est], every.neighbours_[est])
    assert some.neighbours_.dtype == every.neighbours_.dtype
    for step in (some, every):
        back = pickle.loads(pickle.dumps(step, protocol=5))
        assert set(vars(back)) == set(vars(step))
        np.testing.assert_equal(vars(back), vars(step))  # NaN, −1 and dtypes as fitted
    refitted = pickle.loads(pickle.dumps(some)).set_params(max_sets=None).fit(phi, target)
    np.testing.assert_equal(vars(refitted), {**vars(every)})
    other = LocalLeastSquares(n_rho=12, max_sets=60, random_state=1).fit(phi, target)
    again = refitted.set_params(max_sets=60, random_state=1).fit(phi, target)
    np.testing.assert_equal(vars(again), vars(other))


def test_the_paper_setting_estimates_every_local_model():
    from pwa_pipeline import PWARX

    assert PWARX.paper(1, 1, n_rho=18, eps=0.1, min_pts=20).local_models.max_sets is None
    assert PWARX.default().local_models.max_sets == 5000


def test_a_long_record_fits_the_same_model_from_a_subset_of_local_models():
    # the section 5 system over 12,000 samples: the local models of 5,000 of them (the
    # default) give the sub-models and regions of every local model's fit
    from pwa_pipeline import PWARX, make_hure_vasak
    from pwa_pipeline.scoring.metrics import match_submodels

    data = make_hure_vasak(n_samples=12_000, seed=3)
    some = PWARX.default().fit(data.u_train[0], data.y_train[0])
    every = PWARX.default().set_params(local_models__max_sets=None).fit(data.u_train[0], data.y_train[0])
    assert some.steps_["local_models"].n_estimated_ == 5000
    assert every.steps_["local_models"].n_estimated_ == len(every.steps_["submodels"].labels_)
    assert some.n_submodels_ == every.n_submodels_ == 4
    assert match_submodels(some.thetas_, every.thetas_)[1].max() < 2e-3
    assert match_submodels(some.thetas_, data.truth.thetas)[1].max() < 0.03
    assert np.mean(some.steps_["submodels"].labels_ == every.steps_["submodels"].labels_) > 0.995


def test_a_pickle_keeps_the_estimated_rows_and_loads_the_same_arrays():
    import pickle

    import numpy as np

    from pwa_pipeline.pwa import LocalLeastSquares

    rng = np.random.default_rng(0)
    phi, target = rng.normal(size=(3000, 3)), rng.normal(size=(3000, 1))
    step = LocalLeastSquares(n_rho=10, max_sets=300, random_state=0).fit(phi, target)
    whole = LocalLeastSquares(n_rho=10, random_state=0).fit(phi, target)
    data = pickle.dumps(step)
    assert len(data) < len(pickle.dumps(whole)) / 5  # 300 of 3000 rows
    loaded = pickle.loads(data)
    for name in ("theta_", "neighbours_", "residual_var_", "estimated_"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(step, name))
    assert loaded.theta_.shape == (3000, 3, 1) and np.isnan(loaded.theta_[~step.estimated_]).all()
    assert (loaded.neighbours_[~step.estimated_] == -1).all()
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(whole)).theta_, whole.theta_)
