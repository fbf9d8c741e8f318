"""Output limits: found where an output sits flat at its extreme, clipping every free run the
fit measures or refines, and exported as PWA modes with the output held."""

import numpy as np
import pytest

from pwa_pipeline import PWARX
from pwa_pipeline.pwa.limits import PLATEAU, measured_limits, resolve_limits
from pwa_pipeline.pwa.output_error import OutputErrorRefinement
from pwa_pipeline.pwa.scheduling import SignScheduling

RIM = 2.5
TRUE = (0.8, 0.6, 0.3)  # y(k) = min(a·y(k−1) + b·u(k−1) + c + e(k), RIM)


def _overflowing_tank(seed: int, n: int = 1500) -> tuple[np.ndarray, np.ndarray]:
    """A level that overflows at ``RIM``: it reads exactly RIM while the tank is full."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n // 10 + 1), 10)[:n, None]
    y = np.zeros((n, 1))
    a, b, c = TRUE
    for k in range(1, n):
        y[k] = min(a * y[k - 1, 0] + b * u[k - 1, 0] + c + 0.02 * rng.standard_normal(), RIM)
    return u, y


def _hinged(limits) -> PWARX:
    """A continuous model with one hinge at u(k−1) = 0 (the machine has none: its slope
    should come out near zero), refined on the free-run error."""
    return PWARX(na=1, nb=1, affine=True, output_limits=limits,
                 scheduling=SignScheduling(variables=[{"u1(k-1)": 1.0}], switch="continuous"),
                 refinement=OutputErrorRefinement(max_iter=50))


def test_a_flat_top_of_plateau_samples_is_a_limit_and_a_shorter_one_is_not():
    y = np.linspace(0.0, 1.0, 40)[:, None].repeat(2, axis=1)
    y[10:10 + PLATEAU, 0] = 3.0          # output 1 sits at its largest value PLATEAU samples
    y[20:20 + PLATEAU - 1, 1] = -2.0     # output 2 at its smallest one sample too few
    y[30, 1] = -2.0
    limits = measured_limits([y[:25], y[25:]])
    np.testing.assert_array_equal(limits, [[-np.inf, -np.inf], [3.0, np.inf]])
    noisy = np.random.default_rng(0).normal(size=(500, 1))
    assert not np.any(np.isfinite(measured_limits([noisy])))


def test_given_limits_are_checked_and_nan_means_none():
    y = [np.zeros((10, 2))]
    np.testing.assert_array_equal(resolve_limits([[np.nan, 0.0], [1.0, np.nan]], y),
                                  [[-np.inf, 0.0], [1.0, np.inf]])
    with pytest.raises(ValueError, match=r"shape \(2, 2\).*got shape \(2,\)"):
        resolve_limits([0.0, 1.0], y)
    with pytest.raises(ValueError, match="y2's lower limit 3 is above its upper limit 1"):
        resolve_limits([[0.0, 3.0], [1.0, 1.0]], y)


def test_a_level_that_overflows_is_recovered_and_never_simulated_past_its_rim():
    u, y = _overflowing_tank(0)
    u_test, y_test = _overflowing_tank(1)
    assert np.sum(y == RIM) > 100  # the record does overflow
    limited = _hinged("measured").fit(u, y)
    np.testing.assert_array_equal(limited.output_limits_, [[-np.inf], [RIM]])
    assert limited.structures_ == ["level (1, 1), continuous (1 hinge), limited to y1 ≤ 2.5"]
    # both pieces are the machine's own model: the limit, not a bend, carries the overflow
    np.testing.assert_allclose(limited.groups_[0].thetas[:, :, 0], [TRUE, TRUE], atol=0.02)
    sim = limited.simulate(u_test, y_test[:2])
    assert sim.max() == RIM
    error = np.sqrt(np.mean((sim - y_test) ** 2))
    # without the limit the refined fit bends its slope to mimic the overflow and misses
    free = _hinged(None).fit(u, y)
    free_error = np.sqrt(np.mean((free.simulate(u_test, y_test[:2]) - y_test) ** 2))
    assert error < 0.04 and free_error > 3 * error


def test_given_limits_clip_the_paper_route_and_its_refinement():
    u, y = _overflowing_tank(2)
    model = PWARX(na=1, nb=1, affine=True, output_limits=[[np.nan], [RIM]],
                  refinement=OutputErrorRefinement(max_iter=5)).fit(u, y)
    assert model.resolved_params()["output_limits_y1"] == "y1 ≤ 2.5"
    phi = np.array([[RIM, 1.0, 1.0], [0.0, 0.0, 1.0]])  # past the rim, and well below it
    raw = np.einsum("nd,nd->n", phi, model.groups_[0].thetas[model.regions_.predict(phi), :, 0])
    pred = model.groups_[0].predict_phi(phi)[:, 0]
    assert raw[0] > RIM and pred[0] == RIM and raw[1] < RIM and pred[1] == pytest.approx(raw[1])
    sim = model.simulate(u, y[:10])
    assert sim.max() == RIM
    # the refinement measured the clipped free run: its cost is the fitted model's error
    refinement = model.groups_[0].steps["refinement"]
    assert refinement.cost_ == pytest.approx(np.mean((sim[10:] - y[10:]) ** 2), rel=1e-9)


def test_the_search_measures_and_refines_its_candidates_under_the_limit():
    """The linear candidate alone (no scheduling variables, no clusters): under the
    measured limit its held-out free run and refinement recover the machine; without it
    the overflow biases the fit."""
    u, y = _overflowing_tank(3)
    u_test, y_test = _overflowing_tank(103)

    def search(limits) -> tuple[PWARX, float]:
        model = PWARX.auto(1, 1, max_variables=0, clustering=False, forms=["level"])
        model = model.set_params(output_limits=limits).fit(u, y)
        sim = model.simulate(u_test, y_test[:2])
        return model, float(np.sqrt(np.mean((sim - y_test) ** 2)))

    limited, error = search("measured")
    assert limited.structures_ == ["level (1, 1), linear, limited to y1 ≤ 2.5"]
    np.testing.assert_allclose(limited.groups_[0].thetas[0, [0, 2, 3], 0], TRUE, atol=0.01)
    free, free_error = search(None)
    assert free.structures_ == ["level (1, 1), linear"]
    assert error < 0.04 and free_error > 5 * error


def test_the_state_space_export_holds_the_output_at_its_limit():
    u, y = _overflowing_tank(4)
    model = _hinged("measured").fit(u, y)
    ss = model.to_state_space()
    held = [i for i in range(ss.n_modes) if np.all(ss.C[i] == 0)]
    assert held and all(ss.g[i][0] == RIM and ss.f[i][0] == RIM for i in held)
    np.testing.assert_array_equal(np.flatnonzero(ss.held[:, 0]), held)
    assert ss.n_modes == model.n_submodels_ + len(held)  # regions, and their held parts
    u_test, y_test = _overflowing_tank(5)
    np.testing.assert_allclose(ss.simulate(u_test, y_test[:2], outside="nearest"),
                               model.simulate(u_test, y_test[:2]), atol=1e-9)


def test_the_switching_figure_of_a_limited_linear_model_says_where_it_is_held():
    """The figure's title, the page's switching note and the note of the leaderboard's
    row each say where the output is held; a model without limits says nothing of it."""
    from pwa_pipeline.plotting import SwitchingDisplay
    u, y = _overflowing_tank(6)
    model = PWARX.auto(1, 1, max_variables=0, clustering=False, forms=["level"]).fit(u, y)
    title = SwitchingDisplay.from_estimator(model, u, y).figure_.get_suptitle()
    assert title.endswith("\noutputs held at their limits (y1 ≤ 2.5)")
    assert "limited to" not in title
    from pwa_pipeline.orchestration.assets.identification import switching_note
    assert switching_note(model) == ("none: one mode (a single linear model), held at its "
                                     "limits (y1 ≤ 2.5) where it reaches them")
    from pwa_pipeline.orchestration.model_facts import model_note
    assert model_note(model) == ("linear kept (no switching structure beat it held out); "
                                 "outputs held at their limits (y1 ≤ 2.5)")
    model.set_params(output_limits=None).fit(u, y)  # the leaderboard's row and the CLI's line
    assert model_note(model) == "linear kept (no switching structure beat it held out)"


def test_the_mlflow_record_says_where_the_outputs_are_held():
    from types import SimpleNamespace

    from pwa_pipeline.datasets import Dataset
    from pwa_pipeline.orchestration.run_records import method_run
    from pwa_pipeline.scoring import evaluate

    u, y = _overflowing_tank(7)
    u_test, y_test = _overflowing_tank(8)
    data = Dataset("tank", [u], [y], [u_test], [y_test], ["valve"], ["level"],
                   units={"level": "m"})
    model = _hinged("measured").fit(data.u_train, data.y_train)
    record = method_run(SimpleNamespace(dataset="tank", hparams="limited", warmup=10), "pwa",
                        model, evaluate(model, data.u_test, data.y_test), data)
    assert record.params["model/limits"] == "level [m] ≤ 2.5"
    assert record.params["output_limits_y1"] == "y1 ≤ 2.5"
    assert "Outputs held at their limits where they reach them: level [m] ≤ 2.5." \
        in record.description


def test_an_unknown_limits_option_is_refused_naming_the_choices():
    u, y = _overflowing_tank(9, n=200)
    with pytest.raises(ValueError, match=r"'output_limits' parameter of PWARX must be a str "
                                         r"among \{'measured'\}, an array-like or None"):
        PWARX(na=1, nb=1, output_limits="measure").fit(u, y)
