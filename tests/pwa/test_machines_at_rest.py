"""Machines the default once failed on: inputs at rest over whole neighbourhoods (a vehicle's
throttle and brake, never pressed together), and a free run that diverges although the
one-step fit looks fine (a valve with stiction at orders (1, 1) with a constant)."""

import numpy as np
import pytest

from pwa_pipeline import PWARX
from pwa_pipeline.pwa import DivergenceWarning, LocalLeastSquares
from pwa_pipeline.pwa.divergence import free_run_nrmse, mode_radii
from pwa_pipeline.scoring.metrics import nrmse


def vehicle(n: int, seed: int, noise: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Speed v of a vehicle under throttle or brake (never both; each held 20–60 samples,
    or neither: coasting): v⁺ = max(0, 0.95 v + 0.8 throttle − (1.2 brake + 0.05)·[v > 0])."""
    rng = np.random.default_rng(seed)
    pedals, k = np.zeros((n, 2)), 0
    while k < n:
        length, pedal = int(rng.integers(20, 60)), int(rng.integers(3))
        if pedal < 2:
            pedals[k:k + length, pedal] = rng.uniform(0.2, 1.0)
        k += length
    v = np.zeros(n)
    for k in range(n - 1):
        moving = v[k] > 0
        v[k + 1] = max(0.0, 0.95 * v[k] + 0.8 * pedals[k, 0]
                       - (1.2 * pedals[k, 1] + 0.05) * moving)
    return pedals, (v + noise * rng.standard_normal(n))[:, None]


def sticky_valve(n: int, seed: int, stick: float = 0.4, jump: float = 0.2,
                 noise: float = 0.005) -> tuple[np.ndarray, np.ndarray]:
    """A flow y behind a valve with stick-slip (Kano's model): the stem x stays until the
    command u is more than `stick` away, then slips to `stick − jump` short of it;
    y⁺ = 0.9 y + 0.1 x⁺. u: levels held 25 samples, with a little noise."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(0, 1, n // 25 + 1), 25)[:n] + 0.02 * rng.standard_normal(n)
    x, y = np.zeros(n), np.zeros(n)
    for k in range(n - 1):
        gap = u[k] - x[k]
        x[k + 1] = x[k] if abs(gap) <= stick else u[k] - np.sign(gap) * (stick - jump)
        y[k + 1] = 0.9 * y[k] + 0.1 * x[k + 1]
    return u[:, None], (y + noise * rng.standard_normal(n))[:, None]


def test_a_local_set_with_an_input_at_rest_is_identified_on_the_other_columns():
    # throttle zero throughout every local set: its column of Φ_k is zero, rank d − 1
    rng = np.random.default_rng(0)
    phi = np.column_stack([rng.normal(size=60), np.zeros(60), rng.normal(size=60)])
    step = LocalLeastSquares(n_rho=10).fit(phi, phi @ np.array([[0.5], [0.0], [-2.0]]))
    assert step.n_degenerate_ == 0
    assert np.allclose(step.theta_[:, :, 0], [0.5, 0.0, -2.0])  # minimum norm: 0 at rest
    # an input held at a constant beside the constant term stays degenerate (not identified)
    held = np.column_stack([phi[:, 0], np.full(60, 0.3), np.ones(60)])
    assert LocalLeastSquares(n_rho=10).fit(held, phi[:, :1]).n_degenerate_ == 60


@pytest.mark.parametrize("affine", [False, True])
def test_a_vehicle_whose_throttle_and_brake_are_never_pressed_together_fits(affine):
    u, y = vehicle(800, seed=0)
    u_test, y_test = vehicle(1000, seed=10)
    model = PWARX(1, 1, affine=affine).fit(u, y)
    free = model.simulate(u_test, y_test[:1])
    assert nrmse(y_test[1:], free[1:])[0] < (0.01 if affine else 0.1)


def test_a_valve_with_stiction_that_diverges_warns_at_fit_time():
    u, y = sticky_valve(1000, seed=7)
    with pytest.warns(DivergenceWarning, match=r"diverges in free run on its own training "
                      r"data \(NRMSE .* > 10\); sub-model\(s\) with spectral radius > 1: "
                      r"\d \(1\.0\d+\).* Try PWARX.auto\(na, nb\) .* na = 1, nb = 1"):
        model = PWARX(1, 1, affine=True).fit(u, y)
    assert free_run_nrmse(model, [(u, y)]) > 10


def test_the_divergence_check_reads_the_modes_and_the_free_run():
    # y⁺ = 1.1 y + u (ρ = 1.1) and y⁺ = 0.5 y − 0.2 y⁻ + u (ρ = √0.2)
    thetas = np.array([[[1.1], [0.0], [1.0]], [[0.5], [-0.2], [1.0]]])
    assert np.allclose(mode_radii(thetas, 1, 1, 2, 1, False), [1.1, np.sqrt(0.2)])
    u, y = vehicle(300, seed=1)
    model = PWARX(1, 1, affine=True).fit(u, y)
    assert free_run_nrmse(model, [(u, y)]) < 0.05
    assert free_run_nrmse(model, [(u, 1e-3 * y)]) > 10  # outputs the model never made
    # an experiment too short to simulate is passed over, not the end of the check
    assert free_run_nrmse(model, [(u[:1], 1e-3 * y[:1]), (u, 1e-3 * y)]) > 10
