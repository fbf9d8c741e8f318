"""Region boundaries placed by the residuals (ResidualRegions, issue 10)."""


import numpy as np
import pytest

from pwa_pipeline import PWARX
from pwa_pipeline.datasets.simulated import HURE_VASAK_THETAS, make_hure_vasak
from pwa_pipeline.pwa import ResidualRegions, SVMRegions
from pwa_pipeline.pwa.steps.boundaries import denoised_regressors, mixture_of_experts, previous_rows
from pwa_pipeline.pwa.steps.submodels import output_lag_columns
from pwa_pipeline.regressors import build_regressors

THETAS = np.array([[[1.0], [0.5]], [[-1.0], [0.5]]])  # y = ±x + 0.5·v, boundary at x = 0.3


def _record(n=3000, seed=0, sigma=0.05):
    rng = np.random.default_rng(seed)
    phi = np.column_stack([rng.normal(size=n), rng.uniform(-1, 1, n)])
    mode = (phi[:, 0] > 0.3).astype(int)
    y = np.einsum("nd,ndm->nm", phi, THETAS[mode]) + sigma * rng.normal(size=(n, 1))
    return phi, y, mode


def _boundary(coef, intercept):
    """x where the two regions meet (at v = 0)."""
    return (intercept[0] - intercept[1]) / (coef[1, 0] - coef[0, 0])


def test_a_shifted_boundary_moves_back_to_where_the_residuals_switch():
    phi, y, _ = _record()
    shifted = (phi[:, 0] > 0.7).astype(int)  # labels whose boundary is 0.4 off
    svm = SVMRegions().fit(phi, shifted, 2)
    assert abs(_boundary(svm.coef_, svm.intercept_) - 0.7) < 0.05  # the SVM keeps it off
    regions = ResidualRegions(n_em=0).fit(phi, shifted, 2, target=y, thetas=THETAS)
    assert abs(_boundary(regions.coef_, regions.intercept_) - 0.3) < 0.02
    np.testing.assert_array_equal(regions.svm_coef_, svm.coef_)
    assert regions.n_gate_iter_ > 0
    fresh, _, mode = _record(seed=1)
    assert np.mean(regions.predict(fresh) == mode) > 0.995


def test_em_steps_refit_the_sub_models_with_the_regions():
    phi, y, mode = _record()
    start = THETAS + np.array([[[0.1], [-0.1]], [[0.1], [0.1]]])
    svm = SVMRegions().fit(phi, mode, 2)
    thetas, coef, intercept, *_ = mixture_of_experts(phi, y, start, svm.coef_, svm.intercept_,
                                                    n_em=3)
    np.testing.assert_allclose(thetas, THETAS, atol=0.01)
    assert abs(_boundary(coef, intercept) - 0.3) < 0.02
    kept, *_ = mixture_of_experts(phi, y, start, svm.coef_, svm.intercept_, n_em=0)
    np.testing.assert_array_equal(kept, start)


def test_without_residuals_it_is_the_svm():
    phi, _, mode = _record(n=500)
    plain = SVMRegions(C=3.0).fit(phi, mode, 2)
    regions = ResidualRegions(C=3.0).fit(phi, mode, 2)
    np.testing.assert_array_equal(regions.coef_, plain.coef_)
    np.testing.assert_array_equal(regions.intercept_, plain.intercept_)
    assert regions.n_gate_iter_ == 0 and not hasattr(regions, "thetas_")


def test_a_region_never_chosen_stays_so():
    phi, y, mode = _record(n=800)
    thetas = np.concatenate([THETAS, THETAS[:1]])
    regions = ResidualRegions().fit(phi, mode, 3, target=y, thetas=thetas)
    assert regions.intercept_[2] == -np.inf and set(regions.predict(phi)) <= {0, 1}


def test_bad_residual_arguments_are_named():
    phi, y, mode = _record(n=300)
    with pytest.raises(ValueError, match="needs both target and thetas, got only target"):
        ResidualRegions().fit(phi, mode, 2, target=y)
    with pytest.raises(ValueError, match=r"thetas must have shape \(regions, d, m\) = \(2, 2, 1\)"):
        ResidualRegions().fit(phi, mode, 2, target=y, thetas=THETAS[:, :1])


def test_the_estimator_passes_the_sub_models_and_uses_the_refitted_ones(sim_30db):
    model = PWARX(na=1, nb=1).fit(sim_30db.u_train[0][:1500], sim_30db.y_train[0][:1500])
    assert isinstance(model.regions_, ResidualRegions) and model.regions_.n_gate_iter_ > 0
    assert model.thetas_ is model.regions_.thetas_ is model.steps_["regions"].thetas_
    plain = PWARX(na=1, nb=1, regions=ResidualRegions(denoise=False)).fit(
        sim_30db.u_train[0][:1500], sim_30db.y_train[0][:1500])
    assert not np.allclose(plain.regions_.coef_, model.regions_.coef_)  # experiments passed
    paper = PWARX.paper(1, 1, n_rho=12, eps=0.3, min_pts=8)
    assert type(paper.step_objects()["regions"]) is SVMRegions


def test_step_6_fits_its_gate_with_blas_on_one_thread(monkeypatch):
    """The gate's products are tall and thin; ResidualRegions runs them on one BLAS thread."""
    from threadpoolctl import threadpool_info

    from pwa_pipeline.pwa.steps import boundaries

    def blas_threads():
        return {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}

    if blas_threads() == {1}:
        pytest.skip("BLAS runs on one thread here anyway")
    seen, real = [], boundaries.mixture_of_experts

    def spy(*args, **kwargs):
        seen.append(blas_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(boundaries, "mixture_of_experts", spy)
    sim, reg, _, _ = _hure_vasak_regressors()
    ResidualRegions().fit(reg.phi, sim.truth.modes_train[0][1:], 4, target=reg.target,
                          thetas=HURE_VASAK_THETAS)
    assert seen == [{1}]
    assert blas_threads() != {1}  # the limit ends with the fit


def test_previous_rows_stop_at_each_experiment():
    np.testing.assert_array_equal(previous_rows(np.array([0, 0, 0, 1, 1, 2])),
                                  [-1, 0, 1, -1, 3, -1])


def _hure_vasak_regressors(seed=0):
    sim = make_hure_vasak(4000, 30.0, seed=seed)
    reg = build_regressors([(sim.u_train[0], sim.y_train[0])], 1, 1, False)
    clean = build_regressors([(sim.u_train[0], sim.truth.y_clean_train[0])], 1, 1, False).phi
    return sim, reg, clean, output_lag_columns(2, 1, 4)


def test_denoised_output_lags_are_closer_to_the_noise_free_outputs():
    sim, reg, clean, lags = _hure_vasak_regressors()
    post = np.eye(4)[sim.truth.modes_train[0][1:]]
    sigma2 = (sim.y_train[0] - sim.truth.y_clean_train[0]).var(axis=0)
    denoised = denoised_regressors(reg.phi, reg.target, HURE_VASAK_THETAS, post, sigma2, lags,
                                   previous_rows(reg.experiment), reg.phi)
    ratio = ((denoised - clean)[:, :2] ** 2).mean(axis=0) / (
        (reg.phi - clean)[:, :2] ** 2).mean(axis=0)
    assert np.all(ratio < 0.5)  # measured 0.45 and 0.32: measurement and prediction averaged
    np.testing.assert_array_equal(denoised[:, 2:], reg.phi[:, 2:])  # the inputs are kept
    np.testing.assert_array_equal(denoised[0], reg.phi[0])  # no previous row: kept


def test_the_gate_sees_denoised_lags_only_with_the_experiments():
    sim, reg, _, lags = _hure_vasak_regressors(seed=1)
    modes = sim.truth.modes_train[0][1:]
    fits = {key: ResidualRegions(denoise=key[0]).fit(
        reg.phi, modes, 4, target=reg.target, thetas=HURE_VASAK_THETAS, output_lags=lags,
        experiment=reg.experiment if key[1] else None)
        for key in [(True, True), (True, False), (False, True)]}
    np.testing.assert_array_equal(fits[True, False].coef_, fits[False, True].coef_)
    assert not np.allclose(fits[True, True].coef_, fits[True, False].coef_)
    fresh = make_hure_vasak(4000, None, seed=101)
    phi = build_regressors([(fresh.u_train[0], fresh.y_train[0])], 1, 1, False).phi
    accuracy = {k: np.mean(r.predict(phi) == fresh.truth.modes_train[0][1:]) for k, r in fits.items()}
    assert accuracy[True, True] > accuracy[True, False]  # measured 99.52 % against 99.45 %
    with pytest.raises(ValueError, match=r"experiment must have one entry per row of phi"):
        ResidualRegions().fit(reg.phi, modes, 4, target=reg.target, thetas=HURE_VASAK_THETAS,
                              experiment=reg.experiment[1:])
