"""Re-assignment of rows by residual and region until stable (pwa.submodels.reassign)."""

import numpy as np
import pytest

from pwa_pipeline.pwa import SVMRegions
from pwa_pipeline.pwa.steps.submodels import reassign
from pwa_pipeline.pwa.steps.submodels.least_squares import refit
from pwa_pipeline.pwa.steps.submodels.reassign import refine, theta_shift

from ..._submodel_cases import _two_modes


def test_refinement_recovers_from_a_wrong_split():
    phi, y, mode, thetas = _two_modes(gap=40.0)
    wrong = (phi[:, 0] > 0.5).astype(int)  # a quarter of the rows on the wrong side
    assert np.mean(wrong == mode) < 0.8
    est, labels, margin, sweeps = refine(phi, y, wrong, min_size=5, n_iter=20,
                                         regions=SVMRegions(C=10.0))
    # labels are renumbered by size; match them to the true modes first
    flip = np.mean(labels == mode) < 0.5
    labels = 1 - labels if flip else labels
    est = est[::-1] if flip else est
    assert np.mean(labels == mode) > 0.99 and sweeps >= 2
    np.testing.assert_allclose(est, thetas, atol=0.05)  # a wrong split errs by ~1
    assert margin.shape == (len(y),) and np.median(margin) > 4


def test_memoised_sweeps_repeat_none_and_change_nothing(monkeypatch):
    """refine with a memo gives the result without one, bit for bit, with and without
    regions on one memo, and a repeated call fits no region SVM."""
    phi, y, mode, _ = _two_modes(gap=3.0)  # overlapping: the sweeps do not settle at once
    start = (phi[:, 0] > 0.4).astype(int)
    plain = [refine(phi, y, start, 5, 20, regions) for regions in (None, SVMRegions())]
    memo = {}
    for _ in range(2):
        for regions, expected in zip((None, SVMRegions()), plain):
            got = refine(phi, y, start, 5, 20, regions, memo)
            for a, b in zip(got, expected):
                np.testing.assert_array_equal(a, b)
    assert plain[1][3] >= 2
    fits = []
    real = SVMRegions.fit
    monkeypatch.setattr(SVMRegions, "fit", lambda self, *a, **k: fits.append(1)
                        or real(self, *a, **k))
    refine(phi, y, start, 5, 20, SVMRegions(), memo)
    assert fits == []
    with pytest.raises(ValueError, match="memo holds sweeps of other data"):
        refine(phi.copy(), y, start, 5, 20, SVMRegions(), memo)


def test_sweeps_stop_when_few_rows_move_and_the_sub_models_are_kept():
    """refine's tol: a sweep that moves at most tol × n rows ends it, unless it changed the
    number of sub-models (a dropped one is re-assigned and the sweeps go on)."""
    phi, y, mode, _ = _two_modes(gap=40.0)
    start = (phi[:, 0] > 0.5).astype(int)
    assert refine(phi, y, start, 5, 20, SVMRegions(), tol=1.0)[3] == 1
    exact = refine(phi, y, start, 5, 20, SVMRegions())
    assert exact[3] >= 2  # the first sweep moved rows
    tiny = start.copy()
    tiny[:3] = 2  # a third sub-model of 3 rows, below min_size: the first sweep drops it
    dropped = refine(phi, y, tiny, 5, 20, SVMRegions(), tol=1.0)
    assert dropped[0].shape[0] == 2 and dropped[3] == 2


def test_theta_shift_is_in_standard_errors_on_each_sub_models_rows():
    """theta_shift: the root mean square over θ_i's d·m entries of its change, each in its
    least-squares standard error on sub-model i's rows (the largest over i)."""
    rng = np.random.default_rng(0)
    n, d, m = 400, 3, 2
    phi = rng.normal(size=(n, d))
    labels = (phi[:, 0] > 0).astype(int)
    sigma2 = np.array([0.01, 0.04])
    before = rng.normal(size=(2, d, m))
    after = before.copy()
    v = rng.normal(size=d)
    # output 1 of sub-model 1 moved along v so that Σ ‖Φ_1 Δθ‖² / σ² = 0.7² · d·m
    after[1, :, 1] += 0.7 * np.sqrt(d * m * sigma2[1]) / np.linalg.norm(phi[labels == 1] @ v) * v
    assert theta_shift(phi, before, after, labels, sigma2) == pytest.approx(0.7, rel=1e-12)
    after[0, :, 0] += 0.3 * np.sqrt(d * m * sigma2[0]) / np.linalg.norm(phi[labels == 0] @ v) * v
    assert theta_shift(phi, before, after, labels, sigma2) == pytest.approx(0.7, rel=1e-12)
    assert np.isnan(theta_shift(phi, before, after[:1], labels, sigma2))


def test_sweeps_stop_once_no_sub_model_moves_by_more_than_settle_standard_errors():
    """refine's settle: the re-assignment ends at the first sweep that keeps the number of
    sub-models and changes no θ_i by more than ``settle`` standard errors (theta_shift
    between the sub-models it starts from and those it ends with, σ̂² its own)."""
    from pwa_pipeline._arrays import relabel_by_size

    phi, y, mode, _ = _two_modes(gap=3.0, seed=1)
    plain = refine(phi, y, mode, 5, 20, SVMRegions())
    settle = 0.5  # the sweeps' shifts: 49 (the first renumbers), 0.79, 0.25, 0.12, 0
    got = refine(phi, y, mode, 5, 20, SVMRegions(), settle=settle)
    labels = relabel_by_size(mode)
    thetas = refit(phi, y, labels, 2)
    for sweep in range(1, 21):
        new, after, sigma2 = reassign._sweep(phi, y, thetas, 5, SVMRegions())
        assert new.max() == labels.max()
        if theta_shift(phi, thetas, after, new, sigma2) <= settle:
            break
        labels, thetas = new, after
    assert 1 < sweep == got[3] < plain[3]
    np.testing.assert_array_equal(got[1], new)
    np.testing.assert_array_equal(got[0], after)
    # settle 0: only a sweep that moves no row ends it, as without the parameter
    for a, b in zip(refine(phi, y, mode, 5, 20, SVMRegions(), settle=0.0), plain):
        np.testing.assert_array_equal(a, b)


def test_rows_flipping_on_a_boundary_end_the_sweeps_once_the_sub_models_settle():
    """Modes 3 noise deviations apart: rows near the boundary flip between the sub-models in
    every sweep and the sweeps run to their limit, while the sub-models settle at once."""
    phi, y, mode, _ = _two_modes(gap=3.0, seed=3)
    plain = refine(phi, y, mode, 5, 20, SVMRegions())
    settled = refine(phi, y, mode, 5, 20, SVMRegions(), settle=0.3)
    assert plain[3] == 20 and settled[3] <= 3
    assert np.mean(settled[1] == plain[1]) > 0.99
