import numpy as np
import pytest

from pwa_pipeline import LinearARX, SubspaceSS, evaluate

A = np.array([[0.9, 0.2, 0.0], [-0.2, 0.9, 0.0], [0.0, 0.0, 0.5]])


def _state_space_data(n=5000, noise=0.01, seed=0):
    rng = np.random.default_rng(seed)
    b = rng.normal(size=(3, 2))
    c = rng.normal(size=(2, 3))
    u = rng.normal(size=(n, 2))
    x, y = np.zeros(3), np.zeros((n, 2))
    for k in range(n):
        y[k] = c @ x
        x = A @ x + b @ u[k]
    return u, y + noise * rng.normal(size=y.shape), y


def test_subspace_recovers_poles_and_order():
    u, y, _ = _state_space_data()
    model = SubspaceSS(order=3).fit(u, y)
    est = np.sort_complex(model.poles_)
    np.testing.assert_allclose(est, np.sort_complex(np.linalg.eigvals(A)), atol=2e-3)
    assert SubspaceSS().fit(u, y).order_ == 3  # chosen from the singular values


def test_subspace_free_run_matches_the_true_response_from_a_warm_up():
    u, y, clean = _state_space_data(noise=0.0)
    model = SubspaceSS(order=3).fit(u[:3000], y[:3000])
    sim = model.simulate(u[3000:3400], y[3000:3010])
    np.testing.assert_array_equal(sim[:10], y[3000:3010])
    np.testing.assert_allclose(sim, clean[3000:3400], atol=1e-6)


def test_linear_arx_free_run_matches_the_analytic_step_response():
    a, b = 0.8, 0.5
    u = np.ones((60, 1))
    y = np.zeros((60, 1))
    for k in range(1, 60):
        y[k] = a * y[k - 1] + b * u[k - 1]
    model = LinearARX(1, 1).fit(np.random.default_rng(0).normal(size=(500, 1)),
                                _arx_response(a, b, 500))
    sim = model.simulate(u, y[:1])
    k = np.arange(60)
    np.testing.assert_allclose(sim[:, 0], b * (1 - a**k) / (1 - a), atol=1e-10)


def _arx_response(a, b, n, seed=0):
    u = np.random.default_rng(seed).normal(size=(n, 1))
    y = np.zeros((n, 1))
    for k in range(1, n):
        y[k] = a * y[k - 1] + b * u[k - 1]
    return y


def test_experiments_never_leak_into_each_other():
    rng = np.random.default_rng(1)
    u1, u2 = rng.normal(size=(100, 1)), rng.normal(size=(100, 1)) + 1e6
    model = LinearARX(2, 2).fit(rng.normal(size=(400, 1)), _arx_response(0.7, 1.0, 400))
    y1 = model.simulate(u1, np.zeros((2, 1)))
    y2 = model.simulate(u2, np.full((2, 1), 3e6))
    both = evaluate(model, [u1, u2], [y1, y2], warmup=5)
    alone = evaluate(model, [u2], [y2], warmup=5)
    np.testing.assert_array_equal(both.predictions["free_run"][1], alone.predictions["free_run"][0])
    np.testing.assert_array_equal(both.predictions["one_step"][1], alone.predictions["one_step"][0])
    # the second free run starts from its own warm-up, not the first experiment's end
    np.testing.assert_array_equal(both.predictions["free_run"][1][:5], y2[:5])
    assert both.mean("free_run") < 1e-9


def test_evaluation_table_and_divergence_flag():
    rng = np.random.default_rng(2)
    stable = LinearARX(1, 1).fit(rng.normal(size=(300, 1)), _arx_response(0.5, 1.0, 300))
    unstable = LinearARX(1, 1).fit(rng.normal(size=(300, 1)), _arx_response(0.5, 1.0, 300))
    unstable.theta_[:] = np.array([[1.5], [1.0]])  # (its output group holds the same array)
    u = rng.normal(size=(200, 1))
    y = stable.simulate(u, np.zeros((1, 1)))
    ok = evaluate(stable, u, y, warmup=3, output_names=["pos"])
    assert list(ok.table.columns) == ["mode", "output", "nrmse", "r2", "rmse", "diverged",
                                      "outside_share"]
    assert set(ok.table["output"]) == {"pos", "mean"}
    assert not ok.diverged()
    bad = evaluate(unstable, u, y, warmup=3)
    assert bad.diverged() and bad.mean("free_run") > 10
    assert not bad.diverged("one_step")


def test_evaluation_rejects_bad_input():
    rng = np.random.default_rng(3)
    model = LinearARX(2, 2).fit(rng.normal(size=(300, 1)), _arx_response(0.5, 1.0, 300))
    u, y = rng.normal(size=(50, 1)), rng.normal(size=(50, 1))
    with pytest.raises(ValueError, match="u has 2 input.*fitted with 1"):
        evaluate(model, np.hstack([u, u]), y)
    with pytest.raises(ValueError, match="warm-up too short: y_init has 1 row.*"
                                         "at least max\\(output lags, nb\\) = 2"):
        evaluate(model, u, y, warmup=1)
    y_nan = y.copy()
    y_nan[7] = np.nan
    with pytest.raises(ValueError, match="y contains 1 non-finite value.*NaN at sample 7"):
        evaluate(model, u, y_nan)
    ss = SubspaceSS(order=3).fit(*_state_space_data(n=800)[:2])
    with pytest.raises(ValueError, match="warm-up too short: 1 sample.*cannot fix 3 states"):
        ss.simulate(rng.normal(size=(50, 2)), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="order 30 exceeds horizon·m = 20"):
        SubspaceSS(order=30).fit(*_state_space_data(n=800)[:2])


def test_subspace_simulation_refit_keeps_the_exact_response_over_several_experiments():
    u, y, clean = _state_space_data(noise=0.0)
    us, ys = [u[i:i + 500] for i in range(0, 3000, 500)], [y[i:i + 500] for i in range(0, 3000, 500)]
    model = SubspaceSS(order=3, refit="simulation").fit(us, ys)
    sim = model.simulate(u[3000:3400], y[3000:3010])
    np.testing.assert_allclose(sim, clean[3000:3400], atol=1e-6)
    np.testing.assert_allclose(np.sort_complex(model.poles_),
                               np.sort_complex(np.linalg.eigvals(A)), atol=1e-6)


def test_subspace_simulation_refit_lowers_the_free_run_error_of_a_wrong_b_and_d():
    from pwa_pipeline.baselines.subspace import _simulation_fit
    u, y, _ = _state_space_data(noise=0.0)
    model = SubspaceSS(order=3).fit(u, y)
    b, d = _simulation_fit(model.A_, model.C_, [(u[:2000], y[:2000]), (u[2000:], y[2000:])])
    np.testing.assert_allclose(b, model.B_, atol=1e-6)
    np.testing.assert_allclose(d, model.D_, atol=1e-6)


def test_unstable_subspace_poles_are_pulled_inside_the_radius():
    from pwa_pipeline.baselines.subspace import _stabilised
    a = np.array([[1.05, 0.3], [0.0, 0.5]])
    stable = _stabilised(a, 0.99)
    np.testing.assert_allclose(np.sort(np.abs(np.linalg.eigvals(stable))), [0.5, 0.99])
    np.testing.assert_array_equal(_stabilised(A, 0.99), A)


def test_subspace_refit_is_checked():
    with pytest.raises(ValueError, match="'refit' parameter of SubspaceSS must be a str among"):
        SubspaceSS(refit="yes").fit(np.zeros((50, 1)), np.zeros((50, 1)))
