"""The compiled held-out free run of the structure search equals its numpy loop."""

import numpy as np
import pytest

from pwa_pipeline.pwa.partitions import ProjectedRegions, SignRegions
from pwa_pipeline.pwa.search.search import _HeldOut
from pwa_pipeline.pwa.steps.regions import SVMRegions
from pwa_pipeline.pwa.structures import OutputModel, output_regressors


def _experiments(seed: int, lengths=(120, 90, 150), m: int = 2, r: int = 2):
    rng = np.random.default_rng(seed)
    out = []
    for n in lengths:
        u = rng.uniform(-1, 1, (n, r))
        y = np.zeros((n, m))
        for k in range(2, n):
            y[k] = 0.6 * y[k - 1] - 0.1 * y[k - 2] + 0.4 * u[k - 1] \
                + 0.1 * np.sign(y[k - 1] - y[k - 2])
        out.append((u, y + 0.01 * rng.standard_normal((n, m))))
    return out


def _model(j: int, lags: int, nb: int, n_vars: int, rng, scale: float = 0.3,
           form: str = "level"):
    """Output j's model: linear (``n_vars`` 0), on the signs of ``n_vars`` random
    variables, or (``n_vars`` < 0) on -n_vars regions of an SVM fitted on ψ = M φ (the
    clusters' regions)."""
    M, c, names = output_regressors(j, 2, 2, lags - 1, nb, True, form, "joint",
                                    phi_lags=lags, phi_nb=nb)
    if n_vars == 0:
        om = OutputModel(M, c, np.zeros(len(names), bool), 1, None, "linear", names)
    elif n_vars < 0:
        psi = rng.uniform(-1, 1, (400, M.shape[0]))
        psi[:, -1] = 1.0
        labels = np.argmax(psi @ rng.standard_normal((M.shape[0], -n_vars)), axis=1)
        regions = ProjectedRegions(M, SVMRegions().fit(psi, labels))
        om = OutputModel(M, c, np.ones(len(names), bool), -n_vars, regions, "clustered",
                         names)
    else:
        sign = SignRegions(rng.standard_normal((n_vars, M.shape[1])))
        om = OutputModel(M, c, np.ones(len(names), bool), sign.n_regions_, sign, "all",
                         names)
    om.p = scale * rng.standard_normal(om.n_params)
    return om


def tight_limits(experiments: list) -> np.ndarray:
    """Limits at each output's 40 % and 60 % quantiles (`pwa_pipeline.pwa.limits`), which
    clip often."""
    y = np.vstack([e[1] for e in experiments])
    return np.quantile(y, [0.4, 0.6], axis=0)


@pytest.mark.parametrize("n_vars, form, limited",
                         [((0, 0), "level", False), ((1, 2), "level", False),
                          ((2, 0), "velocity", False), ((3, 1), "level", False),
                          ((-3, -2), "level", False), ((-2, 1), "level", False),
                          ((0, 0), "level", True), ((1, 2), "level", True),
                          ((-2, 1), "level", True)])
def test_the_compiled_free_run_equals_the_numpy_loop(n_vars, form, limited):
    lags, nb = 3, 2
    experiments = _experiments(0)
    limits = tight_limits(experiments) if limited else None
    held = _HeldOut(experiments, lags, nb, warmup=5, limits=limits)
    rng = np.random.default_rng(1)
    models = {j: _model(j, lags, nb, n_vars[j], rng, scale=0.1, form=form) for j in (0, 1)}
    for group in ([0], [1], [0, 1]):
        compiled = held.compiled_sse(models, group)
        loop = held.simulated_sse(models, group)
        assert np.all(np.isfinite(loop)) and np.all(loop > 0)
        assert np.all(np.sqrt(loop / held.count) / held.std[group] < 10)  # not diverged
        np.testing.assert_allclose(compiled, loop, rtol=1e-10)
        np.testing.assert_allclose(held.nrmse(models, group),
                                   np.sqrt(loop / held.count) / held.std[group], rtol=1e-10)
        if limited:  # the limits clip: the same models run otherwise without them
            free = _HeldOut(experiments, lags, nb, warmup=5).compiled_sse(models, group)
            assert np.any(np.abs(free - loop) > 1e-3 * loop)


def test_a_diverging_free_run_is_inf_in_both():
    """A run that overflows is inf in both, for every output of the group."""
    lags, nb = 3, 2
    held = _HeldOut(_experiments(2), lags, nb, warmup=5)
    rng = np.random.default_rng(3)
    models = {j: _model(j, lags, nb, 1, rng, scale=50.0) for j in (0, 1)}
    assert np.all(np.isinf(held.simulated_sse(models, [0, 1])))
    assert np.all(np.isinf(held.compiled_sse(models, [0, 1])))
    assert np.all(np.isinf(held.nrmse(models, [0, 1])))
