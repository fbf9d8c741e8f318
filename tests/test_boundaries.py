"""Region boundaries placed by the residuals (ResidualRegions, issue 10)."""

import numpy as np
import pytest

from pwa_pipeline import PWARX
from pwa_pipeline.pwa import ResidualRegions, SVMRegions
from pwa_pipeline.pwa.boundaries import mixture_of_experts

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
    model = PWARX(na=1, nb=1).fit(sim_30db.u[:1500], sim_30db.y[:1500])
    assert isinstance(model.regions_, ResidualRegions) and model.regions_.n_gate_iter_ > 0
    assert model.thetas_ is model.regions_.thetas_ is model.base_thetas()
    paper = PWARX.paper(1, 1, n_rho=12, eps=0.3, min_pts=8)
    assert type(paper.steps()["regions"]) is SVMRegions
