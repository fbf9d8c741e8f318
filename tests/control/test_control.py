"""The PWA state-space form of fitted models (pwa_pipeline.control): it simulates as the model,
its explicit regions are the model's regions inside the envelope, ties go as the model's, and
its JSON, MPT3 script and stability report hold what they say."""

import copy
import json
import re

import numpy as np
import pytest

from pwa_pipeline import PWARX, LinearARX, make_hure_vasak
from pwa_pipeline.control import SCHEMA_VERSION, PWAStateSpace
from pwa_pipeline.control.polyhedra import Box, chebyshev_ball, irredundant_rows
from pwa_pipeline.control.stability import stability_report
from pwa_pipeline.pwa import ClusterCentres
from pwa_pipeline.pwa.output_error import OutputErrorRefinement
from pwa_pipeline.pwa.scheduling import SignScheduling
from pwa_pipeline.pwa.steps.base import BaseRegions
from pwa_pipeline.pwa.steps.regions import SVMRegions


@pytest.fixture(scope="module")
def default_ss(default_30db):
    return default_30db.to_state_space()


def _friction_step(y1: float, y2: float, u1: float) -> float:
    """y(k) of the Coulomb-friction axis from y(k−1), y(k−2), u(k−1): Δy(k) = 0.8Δy(k−1)
    − 0.02y(k−1) + 0.5u(k−1) ∓ 0.3 by the sign of Δy(k−1)."""
    dy = y1 - y2
    return y1 + 0.8 * dy - 0.02 * y1 + 0.5 * u1 + (-0.3 if dy > 0 else 0.3)


def _friction(n_exp: int = 3, n: int = 300, seed: int = 0):
    """A Coulomb-friction axis (:func:`_friction_step`), the structured route's test system."""
    rng = np.random.default_rng(seed)
    us, ys = [], []
    for _ in range(n_exp):
        u = rng.normal(size=(n, 1))
        y = np.zeros((n, 1))
        for k in range(2, n):
            y[k, 0] = _friction_step(y[k - 1, 0], y[k - 2, 0], u[k - 1, 0])
        us.append(u)
        ys.append(y)
    return us, ys


def _two_axes(n_exp: int = 3, n: int = 300, seed: int = 0):
    """Output 1 linear in u; output 2 the friction axis (:func:`_friction_step`) driven by u2."""
    rng = np.random.default_rng(seed)
    us, ys = [], []
    for _ in range(n_exp):
        u = rng.normal(size=(n, 2))
        y = np.zeros((n, 2))
        for k in range(2, n):
            y[k, 0] = 0.7 * y[k - 1, 0] + 0.4 * u[k - 1, 0] - 0.2 * u[k - 1, 1]
            y[k, 1] = _friction_step(y[k - 1, 1], y[k - 2, 1], u[k - 1, 1])
        us.append(u)
        ys.append(y)
    return us, ys


def _paper_system():
    data = make_hure_vasak(n_samples=1500, snr_db=30.0, seed=2)
    return data.u_train[0], data.y_train[0]


def _random_in_envelope(ss: PWAStateSpace, n: int, seed: int = 0) -> np.ndarray:
    lower, upper = ss.envelope
    return np.random.default_rng(seed).uniform(lower, upper, size=(n, lower.size))


def _closed_membership(ss: PWAStateSpace, z: np.ndarray) -> np.ndarray:
    """(N, s): z in the closed region P_i, no tolerance."""
    return np.column_stack([np.all(z @ H.T <= h, axis=1) for H, h in ss.regions])


# --- dynamics ---------------------------------------------------------------------------

def test_state_space_simulates_as_the_default_model(default_30db, default_ss, sim_30db):
    u, y = sim_30db.u_train[0], sim_30db.y_train[0]
    assert default_ss.n_modes == default_30db.n_submodels_ == 4
    assert default_ss.state_names == ["y1(k-1)", "y2(k-1)", "u1(k-1)", "u2(k-1)"]
    np.testing.assert_allclose(default_ss.simulate(u, y[:10]), default_30db.simulate(u, y[:10]),
                               rtol=0, atol=1e-8)
    # lists of experiments are simulated each from its own warm-up, as the model does
    us, ys = [u[:1500], u[1500:]], [y[:3], y[1500:1502]]
    for a, b in zip(default_ss.simulate(us, ys), default_30db.simulate(us, ys), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-8)


def test_linear_arx_is_one_mode_that_simulates_as_the_model():
    rng = np.random.default_rng(4)
    u = rng.normal(size=(600, 2))
    y = np.zeros((600, 2))
    for k in range(2, 600):
        y[k] = (0.5 * y[k - 1] - 0.2 * y[k - 2] + [0.3, -0.1] + u[k - 1] @ [[1.0, 0.2], [0.0, 0.5]]
                + 0.3 * u[k - 2] + 0.01 * rng.normal(size=2))
    model = LinearARX(na=2, nb=2, affine=True).fit(u, y)
    ss = model.to_state_space()
    assert ss.n_modes == 1 and ss.n_states == 2 * 2 + 2 * 2
    np.testing.assert_allclose(ss.simulate(u, y[:5]), model.simulate(u, y[:5]), rtol=0, atol=1e-8)
    # the one mode's matrices are the ARX parameters and the shift of the lags
    theta = model.theta_
    np.testing.assert_array_equal(ss.C[0], theta[:8].T)
    np.testing.assert_array_equal(ss.g[0], theta[8])
    np.testing.assert_array_equal(ss.A[0][[0, 2]], theta[:8].T)  # newest lag of y1, y2
    np.testing.assert_array_equal(ss.A[0][1], np.eye(8)[0])      # y1(k-2) ← y1(k-1)
    np.testing.assert_array_equal(ss.A[0][5], np.eye(8)[4])      # u1(k-2) ← u1(k-1)
    np.testing.assert_array_equal(ss.B[0][[4, 6]], np.eye(2))    # u(k) → u(k-1)
    np.testing.assert_array_equal(ss.f[0][[0, 2]], theta[8])


def test_step_is_the_one_step_prediction_and_the_shift_of_the_state(default_30db, default_ss,
                                                                     sim_30db):
    u, y = sim_30db.u_train[0][:500], sim_30db.y_train[0][:500]
    x = default_ss.states(u, y)
    x_next, y_hat = default_ss.step(x, u[1:])
    np.testing.assert_allclose(y_hat, default_30db.predict(u, y)[1:], rtol=0, atol=1e-12)
    # the next state is the measured one with the prediction in the output lags
    np.testing.assert_allclose(x_next[:-1, 2:], x[1:, 2:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(x_next[:, :2], y_hat, rtol=0, atol=1e-12)
    one_x, one_y = default_ss.step(x[7], u[8])
    np.testing.assert_array_equal(one_x, x_next[7])
    np.testing.assert_array_equal(one_y, y_hat[7])


def test_states_and_regressors_are_aligned_with_the_data():
    u, y = _friction(n_exp=2)
    model = PWARX(na=1, nb=1, affine=True, form="velocity", outputs="decoupled",
                  scheduling=SignScheduling(switch="offset")).fit(u, y)
    ss = model.to_state_space()
    assert ss.state_names == ["y1(k-1)", "y1(k-2)", "u1(k-1)"] and ss.n_initial == 2
    x, phi = ss.states(u, y), ss.regressors(u, y)
    assert isinstance(x, list) and len(x) == 2
    assert x[0].shape == (len(u[0]) - 2, 3)
    np.testing.assert_array_equal(x[0][:, 0], y[0][1:-1, 0])   # x(k) holds y(k−1) …
    np.testing.assert_array_equal(x[0][:, 1], y[0][:-2, 0])    # … y(k−2) …
    np.testing.assert_array_equal(x[0][:, 2], u[0][1:-1, 0])   # … and u(k−1)
    np.testing.assert_array_equal(phi[0], np.column_stack([x[0], np.ones(len(x[0]))]))


def test_leaving_the_envelope_is_refused_or_extrapolated(default_30db, default_ss, sim_30db):
    u, y = 3 * sim_30db.u_train[0][:200], sim_30db.y_train[0][:200]
    with pytest.raises(ValueError, match="leaves the data envelope at sample 1 .*u1"):
        default_ss.simulate(u, y[:1])
    assert default_ss.mode_of(default_ss.states(u, y), u[1:]).min() == -1
    with pytest.raises(ValueError, match="outside the data envelope"):
        default_ss.step(np.zeros(4), np.array([100.0, 0.0]))
    # a linear model has one mode: extrapolating it is the model's own simulation
    linear = LinearARX(na=1, nb=1).fit(sim_30db.u_train[0], sim_30db.y_train[0])
    ls = linear.to_state_space()
    np.testing.assert_allclose(ls.simulate(u, y[:1], outside="nearest"),
                               linear.simulate(u, y[:1]), rtol=0, atol=1e-8)


# --- regions ------------------------------------------------------------------------------

def test_mode_of_is_the_models_region_on_every_training_row(default_30db, default_ss, sim_30db):
    x = default_ss.states(sim_30db.u_train[0], sim_30db.y_train[0])
    phi = default_ss.regressors(sim_30db.u_train[0], sim_30db.y_train[0])
    mode = default_ss.mode_of(x, sim_30db.u_train[0][1:])
    assert mode.min() >= 0
    np.testing.assert_array_equal(default_ss.mode_regions[mode, 0],
                                  default_30db.regions_.predict(phi))


def test_each_explicit_region_is_the_models_region_inside_the_envelope(default_30db, default_ss):
    """Random points of the envelope: each lies in exactly one closed region, and region i
    holds exactly the points the model's argmax gives to it, so removing rows kept the sets."""
    z = _random_in_envelope(default_ss, 20000)
    inside = _closed_membership(default_ss, z)
    np.testing.assert_array_equal(inside.sum(axis=1), 1)
    model_region = default_30db.regions_.predict(z[:, :default_ss.n_states])
    np.testing.assert_array_equal(default_ss.mode_regions[inside.argmax(axis=1), 0], model_region)
    np.testing.assert_array_equal(default_ss.mode_of(z[:, :4], z[:, 4:]), inside.argmax(axis=1))
    # redundant rows are gone: 3 hyperplanes and 12 box rows per region before
    assert all(len(h) < 15 for _, h in default_ss.regions)


def test_redundant_rows_are_removed_and_the_set_kept():
    box = Box(np.array([-1.0, 0.0, 2.0]), np.array([1.0, 4.0, 3.0]))
    H = np.array([[1.0, 1.0, 0.0],     # x + y ≤ 2: shapes the set
                  [1.0, 1.0, 0.0],     # the same row again: redundant
                  [1.0, 1.0, 0.0],     # x + y ≤ 6: redundant (the box gives ≤ 5)
                  [0.0, 0.0, 1.0],     # z ≤ 2.5: shapes the set
                  [-1.0, 0.0, -1.0],   # −x − z ≤ 0: redundant (x ≥ −1, z ≥ 2)
                  [0.0, 1.0, 0.0]])    # y ≤ 2.98: cuts a sliver off the corner x = −1, y = 3
    h = np.array([2.0, 2.0, 6.0, 2.5, 0.0, 2.98])
    bH, bh = box.rows()
    Ht, ht = box.to_unit(np.vstack([H, bH]), np.concatenate([h, bh]))
    keep = irredundant_rows(Ht, ht)
    # of the two equal rows the later stays (the first is tested while the second is there);
    # of the box rows y ≤ 4 is implied by y ≤ 2 − x ≤ 3 and z ≤ 3 by z ≤ 2.5
    np.testing.assert_array_equal(keep, [False, True, False, True, False, True,
                                         True, False, False, True, True, True])
    # rays from the Chebyshev centre settle most rows without a program, to the same rows
    radius, centre = chebyshev_ball(Ht, ht)
    assert radius > 0.1
    np.testing.assert_array_equal(irredundant_rows(Ht, ht, interior=centre), keep)
    pts = np.random.default_rng(0).uniform([-2, -1, 1], [2, 5, 4], size=(20000, 3))
    full = np.all(pts @ np.vstack([H, bH]).T <= np.concatenate([h, bh]), axis=1)
    Hk, hk = box.from_unit(Ht[keep], ht[keep])
    np.testing.assert_array_equal(np.all(pts @ Hk.T <= hk + 1e-12, axis=1), full)


def test_a_tie_on_a_boundary_goes_to_the_lowest_region_as_the_model_does(default_30db):
    """Regions y1(k−1) ≥ 0 (0) and ≤ 0 (1); regions 2 and 3 never win inside the envelope and
    are dropped. On y1(k−1) = 0 the model's argmax picks 0, and so does mode_of."""
    model = copy.deepcopy(default_30db)
    coef = np.zeros((4, 4))
    coef[0, 0], coef[1, 0] = 1.0, -1.0
    model.regions_.coef_, model.regions_.intercept_ = coef, np.array([0.0, 0.0, -100.0, -100.0])
    ss = model.to_state_space()
    assert ss.n_modes == 2
    np.testing.assert_array_equal(ss.mode_regions[:, 0], [0, 1])
    np.testing.assert_array_equal(ss.dropped_modes, [[2, 2], [3, 3]])
    x = np.array([[0.0, 1.0, 0.5, 0.5], [1e-3, 1.0, 0.5, 0.5], [-1e-3, 1.0, 0.5, 0.5]])
    u = np.zeros((3, 2))
    np.testing.assert_array_equal(model.regions_.predict(x), [0, 0, 1])
    np.testing.assert_array_equal(ss.mode_of(x, u), [0, 0, 1])
    assert _closed_membership(ss, np.hstack([x, u]))[0].all()  # the tie: in both regions


def test_a_sign_tie_goes_to_bit_zero_as_the_model_does():
    u, y = _friction()
    model = PWARX(na=1, nb=1, affine=True, form="velocity", outputs="decoupled",
                  scheduling=SignScheduling(switch="offset")).fit(u, y)
    ss = model.to_state_space()
    assert ss.n_modes == 2
    out = model.structure_fit_.outputs[0]
    c = (ss.envelope[0][0] + ss.envelope[1][0]) / 2
    x = np.array([[c, c, 0.0], [c, c - 0.1, 0.0], [c - 0.1, c, 0.0]])  # Δy = 0, > 0, < 0
    phi = np.column_stack([x, np.ones(3)])
    np.testing.assert_array_equal(out.regions(phi), [0, 1, 0])
    np.testing.assert_array_equal(ss.mode_regions[ss.mode_of(x, np.zeros((3, 1))), 0],
                                  [0, 1, 0])
    np.testing.assert_allclose(ss.simulate(u[0], y[0][:2]), model.simulate(u[0], y[0][:2]),
                               rtol=0, atol=1e-8)


def test_decoupled_outputs_take_the_product_partition():
    data = make_hure_vasak(n_samples=1500, snr_db=30.0, seed=2)
    model = PWARX(na=1, nb=1, form="velocity", outputs="decoupled").fit(data.u_train[0], data.y_train[0])
    ss = model.to_state_space()
    sizes = [o.n_regions for o in model.structure_fit_.outputs]
    assert ss.n_modes + len(ss.dropped_modes) == np.prod(sizes)
    np.testing.assert_allclose(ss.simulate(data.u_train[0], data.y_train[0][:5]),
                               model.simulate(data.u_train[0], data.y_train[0][:5]),
                               rtol=0, atol=1e-8)
    x, phi = ss.states(data.u_train[0], data.y_train[0]), ss.regressors(data.u_train[0], data.y_train[0])
    mode = ss.mode_of(x, data.u_train[0][2:])
    for j, out in enumerate(model.structure_fit_.outputs):
        np.testing.assert_array_equal(ss.mode_regions[mode, j], out.regions(phi))
    z = _random_in_envelope(ss, 5000, seed=1)
    np.testing.assert_array_equal(_closed_membership(ss, z).sum(axis=1), 1)
    assert PWAStateSpace.from_json(ss.to_json()).n_modes == ss.n_modes  # a partition
    assert ss.source["outputs"] == "2 output groups: y1; y2"


def _model_regions(model, phi: np.ndarray) -> np.ndarray:
    """(N, m): the fitted model's region of each output's sub-model for each φ row."""
    out = np.empty((len(phi), model.n_outputs_), dtype=int)
    for group in model.groups_:
        out[:, group.outputs] = group.regions.predict(phi)[:, None]
    return out


@pytest.mark.parametrize("make, data", [
    (lambda: PWARX(na=1, nb=1, form="velocity"), _paper_system),
    (lambda: PWARX(na=1, nb=1, refinement=OutputErrorRefinement(max_iter=2)), _paper_system),
    (lambda: PWARX(na=2, nb=1, affine=True, scheduling=SignScheduling()), _two_axes),
    (lambda: LinearARX(na=1, nb=1, affine=True, form="velocity", outputs="decoupled"),
     _two_axes),
], ids=["joint-velocity-clustered", "joint-level-refined", "joint-scheduled-own-increments",
        "linear-velocity-decoupled"])
def test_structured_and_refined_routes_convert_exactly(make, data):
    u, y = data()
    model = make().fit(u, y)
    ss = model.to_state_space()
    u0, y0 = (u[0], y[0]) if isinstance(u, list) else (u, y)
    np.testing.assert_allclose(ss.simulate(u0, y0[:5]), model.simulate(u0, y0[:5]),
                               rtol=0, atol=1e-8)
    x, phi = ss.states(u0, y0), ss.regressors(u0, y0)
    mode = ss.mode_of(x, u0[ss.n_initial:])
    np.testing.assert_array_equal(ss.mode_regions[mode], _model_regions(model, phi))
    # random points of the envelope: one region each, the model's
    z = _random_in_envelope(ss, 3000, seed=3)
    x = z[:, :ss.n_states]
    np.testing.assert_array_equal(_closed_membership(ss, z).sum(axis=1), 1)
    phi = np.column_stack([x, np.ones(len(z))]) if model.affine else x
    np.testing.assert_array_equal(ss.mode_regions[ss.mode_of(x, z[:, ss.n_states:])],
                                  _model_regions(model, phi))
    assert PWAStateSpace.from_json(ss.to_json()).n_modes == ss.n_modes  # a partition


def test_the_envelope_is_the_padded_training_range(default_30db, default_ss, sim_30db):
    lower, upper = default_ss.envelope
    y_lo, y_hi = sim_30db.y_train[0].min(axis=0), sim_30db.y_train[0].max(axis=0)
    u_lo, u_hi = sim_30db.u_train[0].min(axis=0), sim_30db.u_train[0].max(axis=0)
    # z = [y1(k-1), y2(k-1), u1(k-1), u2(k-1), u1(k), u2(k)]: each lag its channel's range
    u_lower = u_lo - 0.05 * (u_hi - u_lo)
    np.testing.assert_allclose(lower, np.concatenate([y_lo - 0.05 * (y_hi - y_lo), u_lower,
                                                      u_lower]))
    np.testing.assert_allclose(upper[:2], y_hi + 0.05 * (y_hi - y_lo))
    from_data = default_30db.to_state_space(sim_30db.u_train[0], sim_30db.y_train[0])
    np.testing.assert_array_equal(from_data.envelope[0], lower)
    wider = default_30db.to_state_space(padding=0.2)
    assert np.all(wider.envelope[0] < lower) and np.all(wider.envelope[1] > upper)
    old = copy.copy(default_30db)
    del old.signal_range_
    with pytest.raises(ValueError, match="pass the training data"):
        old.to_state_space()
    with pytest.raises(ValueError, match="padding must be a positive"):
        default_30db.to_state_space(padding=0.0)


class _Intervals(BaseRegions):
    """A region learner of one's own: φ's first entry cut at its quantiles into as many
    intervals as there are sub-models (ties to the lower interval)."""

    def fit(self, phi, labels, n_regions=None, sample_weight=None, **given):
        self.n_regions_ = int(np.max(labels)) + 1 if n_regions is None else n_regions
        self.cuts_ = np.quantile(phi[:, 0], np.arange(1, self.n_regions_) / self.n_regions_)
        self.d_ = phi.shape[1]
        return self

    def predict(self, phi):
        return np.searchsorted(self.cuts_, phi[:, 0], side="left")

    def halfspaces(self):
        e, out = np.eye(self.d_)[:1], []
        for i in range(self.n_regions_):
            rows = [(np.zeros((0, self.d_)), np.zeros(0))]
            rows += [(e, self.cuts_[i:i + 1])] if i < self.n_regions_ - 1 else []
            rows += [(-e, -self.cuts_[i - 1:i])] if i > 0 else []
            out.append((np.vstack([r[0] for r in rows]), np.concatenate([r[1] for r in rows])))
        return out


def test_a_region_learner_of_ones_own_exports_and_a_wrong_one_is_refused(sim_30db):
    """Any region step that writes its regions as halfspaces converts exactly; one whose
    halfspaces do not describe its predict is refused, naming it, not exported wrong."""
    u, y = sim_30db.u_train[0][:1500], sim_30db.y_train[0][:1500]
    model = PWARX(na=1, nb=1, submodels=ClusterCentres(), regions=_Intervals()).fit(u, y)
    ss = model.to_state_space()
    assert ss.n_modes == model.n_submodels_ >= 2
    x, now = ss.states(u, y), u[ss.n_initial:]
    inside = ss.in_envelope(x, now)
    assert inside.mean() > 0.9
    np.testing.assert_allclose(ss.step(x[inside], now[inside])[1],
                               model.predict(u, y)[ss.n_initial:][inside], rtol=0, atol=1e-8)

    class NearestRegions(SVMRegions):
        def predict(self, phi):
            return np.zeros(len(phi), dtype=int)

    wrong = PWARX(na=1, nb=1, submodels=ClusterCentres(), regions=NearestRegions()).fit(u, y)
    with pytest.raises(ValueError, match=r"halfspaces\(\) of NearestRegions .* disagree"):
        wrong.to_state_space()


# --- export ------------------------------------------------------------------------------

def test_json_round_trip_is_exact(default_ss, sim_30db, tmp_path):
    path = tmp_path / "model.json"
    text = default_ss.to_json(path)
    doc = json.loads(text)
    assert doc["schema_version"] == SCHEMA_VERSION and doc["n_modes"] == 4
    for back in (PWAStateSpace.from_json(text), PWAStateSpace.from_json(path)):
        for name in "ABfCg":
            np.testing.assert_array_equal(getattr(back, name), getattr(default_ss, name))
        for (H, h), (H0, h0) in zip(back.regions, default_ss.regions, strict=True):
            np.testing.assert_array_equal(H, H0)
            np.testing.assert_array_equal(h, h0)
        np.testing.assert_array_equal(back.envelope[0], default_ss.envelope[0])
        np.testing.assert_array_equal(back.mode_regions, default_ss.mode_regions)
        assert back.state_names == default_ss.state_names
        assert back.source == default_ss.source
    u, y = sim_30db.u_train[0][:300], sim_30db.y_train[0][:300]
    np.testing.assert_array_equal(back.simulate(u, y[:1]), default_ss.simulate(u, y[:1]))


@pytest.mark.parametrize("change, message", [
    (lambda d: d.update(schema_version=3), "schema version 3 is not supported"),
    (lambda d: d.update(schema="something-else"), "not a PWA state-space document"),
    (lambda d: d.pop("B"), r"lacks field\(s\) \['B'\]"),
    (lambda d: d.update(A=[a[:-1] for a in d["A"]]), r"A has shape \(4, 3, 4\)"),
    (lambda d: d.update(g=[row + [0.0] for row in d["g"]]), r"g has shape \(4, 3\)"),
    (lambda d: d["regions"][1].update(h=d["regions"][1]["h"][:-1]), "region 1 h has shape"),
    (lambda d: d["regions"][0].update(H=[r[:-1] for r in d["regions"][0]["H"]]),
     "region 0 H has shape"),
    (lambda d: d["envelope"].update(lower=d["envelope"]["upper"]), "envelope is empty"),
    (lambda d: d.update(output_lags=2), "the state has 4 entries"),
    (lambda d: d.update(state_names=["a", "b", "c", "d"]), "state_names"),
])
def test_bad_json_is_refused_naming_the_problem(default_ss, change, message):
    doc = json.loads(default_ss.to_json())
    change(doc)
    with pytest.raises(ValueError, match=message):
        PWAStateSpace.from_json(json.dumps(doc))


def test_not_json_is_refused():
    with pytest.raises(ValueError, match="not a JSON document"):
        PWAStateSpace.from_json("{not json")


def _set(field: str, index: tuple, value):
    """A change of the document: ``doc[field][i][j]… = value``."""
    def change(doc):
        target = doc[field]
        for i in index[:-1]:
            target = target[i]
        target[index[-1]] = value
    return change


@pytest.mark.parametrize("change, message", [
    (lambda d: d.update(affine="false"), 'affine must be true or false, got "false"'),
    (lambda d: d.pop("affine"), r"lacks field\(s\) \['affine'\]"),
    (lambda d: d.pop("mode_regions"), r"lacks field\(s\) \['mode_regions'\]"),
    (lambda d: d["envelope"].pop("padding"), r"envelope lacks field\(s\) \['padding'\]"),
    (lambda d: d.update(schema_version=True), "schema version True is not supported"),
    (lambda d: d.update(n_modes=4.0), "n_modes must be a whole number, got 4.0"),
    (lambda d: d.update(output_lags=True), "output_lags must be a whole number"),
    (_set("mode_regions", (0, 0), 1.7), r"mode_regions\[0\]\[0\] is 1.7, not a whole number"),
    (_set("mode_regions", (0, 0), None), r"mode_regions\[0\]\[0\] is null, not a whole number"),
    (_set("mode_regions", (0, 0), -1), r"mode_regions\[0\]\[0\] is -1, not a whole number"),
    (_set("A", (0, 0, 0), "0.5"), r'A\[0\]\[0\]\[0\] is "0.5", not a number'),
    (_set("A", (0, 0, 0), True), r"A\[0\]\[0\]\[0\] is true, not a number"),
    (_set("A", (0, 0, 0), 10 ** 400), r"A\[0\]\[0\]\[0\] is 1000.*, beyond float64's range"),
    (_set("A", (0, 0), 0.5), r"A\[0\]\[0\] is 0.5, expected a list"),
    (lambda d: d.update(A=None), "A is null, expected a list"),
    (lambda d: d.update(input_names="ab"), "input_names must be a list of strings"),
    (lambda d: d.update(output_names=[1, 2]), "output_names must be a list of strings"),
    (lambda d: d.update(source="ab"), "source must be an object"),
    (lambda d: d["envelope"].update(padding="0.05"), "envelope padding must be a number"),
    (lambda d: d["regions"][1].update(H=[], h=[]),
     "region 1 has no rows: all of z, which overlaps the other 3 regions"),
    (lambda d: d["regions"][1].update(H=[[0.0] * 6, [1.0] + [0.0] * 5], h=[1.0, -1e9]),
     "region 1 is empty inside the envelope"),
    (lambda d: d["regions"].__setitem__(2, d["regions"][0]), "regions 0 and 2 overlap"),
])
def test_a_tampered_document_is_refused_naming_the_field(default_ss, change, message):
    """Values of the wrong type are not converted (``"false"`` is not true, 1.7 not 1), no
    field takes a default, and the regions must stay non-empty and without overlap."""
    doc = json.loads(default_ss.to_json())
    change(doc)
    with pytest.raises(ValueError, match=message):
        PWAStateSpace.from_json(json.dumps(doc))


def _shrunk(doc: dict, i: int, factor: float) -> None:
    """Region `i` of the document scaled by `factor` about its Chebyshev centre, which
    leaves a gap between it and its neighbours."""
    ss = PWAStateSpace.from_json(json.dumps(doc))
    box = Box(*ss.envelope)
    H, h = ss.regions[i]
    centre = box.centre + box.half_width * chebyshev_ball(*box.to_unit(H, h))[1]
    doc["regions"][i]["h"] = (H @ centre + factor * (h - H @ centre)).tolist()


def test_regions_that_no_longer_cover_the_envelope_are_refused_naming_a_point(default_ss):
    doc = json.loads(default_ss.to_json())
    _shrunk(doc, 1, 0.9)
    with pytest.raises(ValueError, match=r"the regions do not cover the envelope: the point "
                       r"y1\(k-1\) = \S+, .*, u2 = \S+ inside it lies in no region") as err:
        PWAStateSpace.from_json(json.dumps(doc))
    z = np.array([float(v) for v in re.findall(r" = (\S+?)[, ]", str(err.value))])
    assert z.shape == (6,) and np.all((z >= doc["envelope"]["lower"])
                                      & (z <= doc["envelope"]["upper"]))
    assert not any(np.all(np.array(r["H"]) @ z <= np.array(r["h"])) for r in doc["regions"])
    doc = json.loads(default_ss.to_json())
    _shrunk(doc, 1, 1 - 1e-12)  # rounding: the regions still meet
    assert PWAStateSpace.from_json(json.dumps(doc)).n_modes == 4


@pytest.mark.parametrize("text, message", [
    ("[1, 2]", "the JSON document is a list, not an object"),
    ("null", "the JSON document is null, not an object"),
    ("3", "the JSON document is a number, not an object"),
    ('"model.json"', "the JSON document is a string, not an object"),
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ('{"A": ' + "[" * 5_000 + "]" * 5_000 + "}", "nested too deeply"),
])
def test_a_document_that_is_not_an_object_is_refused_not_read_as_a_path(text, message):
    with pytest.raises(ValueError, match=message):
        PWAStateSpace.from_json(text)


def test_a_deeply_nested_field_is_refused_naming_it(default_ss):
    text = json.dumps({**json.loads(default_ss.to_json()), "A": "@"})
    with pytest.raises(ValueError, match=r"A\[0\]\[0\]\[0\] is a list, expected a number"):
        PWAStateSpace.from_json(text.replace('"@"', "[" * 900 + "]" * 900))


def test_a_missing_file_is_still_a_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        PWAStateSpace.from_json(str(tmp_path / "absent.json"))


def test_mpt3_script_builds_the_pwa_system_from_the_matrices(default_ss, tmp_path):
    path = tmp_path / "model_pwa.m"
    script = default_ss.to_mpt3(path)
    assert path.read_text() == script
    assert script.count("LTISystem('A', A") == default_ss.n_modes == 4
    assert "pwa = PWASystem([sys1, sys2, sys3, sys4]);" in script
    assert "sys3.setDomain('xu', Polyhedron('A', H3, 'b', h3));" in script
    for value in (default_ss.A[0, 0, 0], default_ss.A[3, 1, 2], default_ss.C[2, 1, 0],
                  default_ss.regions[1][0][0, 1], default_ss.regions[2][1][-1],
                  default_ss.envelope[1][5]):
        assert f"{value:.17g}" in script
    # the mode's A matrix, row by row, as MATLAB reads it
    a1 = "A1 = [" + "; ".join(" ".join(f"{v:.17g}" for v in row) for row in default_ss.A[0]) + "];"
    assert a1 in script


def _renamed(ss: PWAStateSpace, inputs: list[str], outputs: list[str],
             source: dict | None = None) -> PWAStateSpace:
    """``ss`` with other signal names (and source)."""
    lower, upper = ss.envelope
    return PWAStateSpace(ss.A, ss.B, ss.f, ss.C, ss.g, ss.regions, lower, upper,
                         output_lags=ss.output_lags, input_lags=ss.input_lags,
                         affine=ss.affine, input_names=inputs, output_names=outputs,
                         mode_regions=ss.mode_regions, dropped_modes=ss.dropped_modes,
                         source=source if source is not None else ss.source)


#: The only statements the MPT3 script holds: the sample time, the envelope, each mode's
#: matrices, systems and domains, and the PWA system.
_STATEMENT = re.compile(r"(Ts|z_min|z_max|[ABfCDgHh]\d+|sys\d+|pwa) = [^%']*;"
                        r"|sys\d+ = LTISystem\(('[A-Za-z]+', [A-Za-z]+\d*(, )?)+\);"
                        r"|sys\d+\.setDomain\('xu', Polyhedron\('A', H\d+, 'b', h\d+\)\);")


def test_names_never_become_matlab_code(default_ss):
    """A name with a line break, quotes or a comment sign stays inside its comment line,
    written with Python's escapes, so the script holds only its own statements."""
    hostile = ["u\nsystem('touch pwned')", "it's \"q\"\r%{\rx"]
    outputs = ["y\u2028disp(1)", "a\\nb\x85!rm"]
    ss = _renamed(default_ss, hostile, outputs,
                  source={"class": "PWARX\nsystem('id')", "na": 1})
    script = ss.to_mpt3()
    lines = script.split("\n")[:-1]
    assert script.splitlines() == lines  # no other line break (\r, \u2028, \x85)
    code = [line for line in lines if not line.startswith("%")]
    assert [line for line in code if not _STATEMENT.fullmatch(line)] == []
    assert len(code) == sum(not line.startswith("%") for line in default_ss.to_mpt3().splitlines())
    assert "% inputs u: u\\nsystem('touch pwned'), it's \"q\"\\r%{\\rx" in lines
    assert "% outputs y: y\\u2028disp(1), a\\\\nb\\x85!rm" in lines
    assert lines[0].endswith(": class=PWARX\\nsystem('id'), na=1")


@pytest.mark.parametrize("Ts", [0.0, -1, float("nan"), float("inf"), True, "1"])
def test_mpt3_refuses_a_sample_time_that_is_not_positive_and_finite(default_ss, Ts):
    with pytest.raises(ValueError, match=r"Ts must be a finite number > 0 \(the sampling "
                                         r"time\), got " + re.escape(repr(Ts))):
        default_ss.to_mpt3(Ts=Ts)
    assert "Ts = 0.01;" in default_ss.to_mpt3(Ts=0.01)


def test_mpt3_says_when_the_sample_time_is_unknown(default_ss):
    given, unknown = default_ss.to_mpt3(Ts=0.25), default_ss.to_mpt3()
    assert "Ts = 0.25;" in given and "unknown" not in given
    assert "% sample time unknown: Ts = 1 counts samples" in unknown and "Ts = 1;" in unknown


# --- stability ---------------------------------------------------------------------------

def test_stability_of_the_identified_system_is_certified(default_ss):
    report = default_ss.stability()
    np.testing.assert_allclose(report.spectral_radius,
                               [np.abs(np.linalg.eigvals(a)).max() for a in default_ss.A])
    assert report.certified and report.method.startswith("common quadratic")
    P = report.certificates["P"]
    assert np.linalg.eigvalsh(P).min() > 0
    for a in default_ss.A:
        assert np.linalg.eigvalsh(a.T @ P @ a - P).max() < 0
    assert 0 < report.contraction < 1
    assert json.dumps(report.to_dict())


def _hand_made(A: np.ndarray) -> PWAStateSpace:
    """Modes x⁺ = A_i x over two output lags of one output, one input that enters nothing."""
    s = len(A)
    box = (np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0]))
    regions = [(np.eye(3), np.ones(3))] * s
    return PWAStateSpace(A, np.zeros((s, 2, 1)), np.zeros((s, 2)), np.zeros((s, 1, 2)),
                         np.zeros((s, 1)), regions, *box, output_lags=2, input_lags=0)


def test_stability_is_not_certified_when_it_cannot_be():
    unstable = stability_report(_hand_made(np.array([[[1.1, 0.0], [1.0, 0.0]]])))
    assert not unstable.certified and unstable.method == "spectral radius"
    assert "mode(s) [0]" in unstable.message and unstable.certificates == {}
    # each mode stable, but switching between them diverges: no common quadratic function
    pair = np.array([[[0.5, 2.0], [0.0, 0.5]], [[0.5, 0.0], [2.0, 0.5]]])
    switching = stability_report(_hand_made(pair))
    assert not switching.certified and switching.method.startswith("piecewise quadratic")
    assert "no common quadratic Lyapunov function was found" in switching.message
    assert switching.spectral_radius.max() < 1
    np.testing.assert_allclose(switching.spectral_radius, [0.5, 0.5])


def test_one_stable_mode_is_certified_by_its_spectral_radius_without_a_solver():
    # the robot's linear model had ρ = 0.9996 and was shown "not certified"
    ss = _hand_made(np.array([[[1.8996, -0.89964], [1.0, 0.0]]]))  # poles 0.9996, 0.9
    np.testing.assert_allclose(np.abs(np.linalg.eigvals(ss.A[0])).max(), 0.9996)
    report = stability_report(ss, solvers=())  # no LMI solver is needed, nor asked
    assert report.certified and report.method == "spectral radius"
    assert report.message.startswith("certified: one mode (a linear model) of spectral "
                                     "radius 0.9996 < 1")
    P = report.certificates["P"]
    np.testing.assert_allclose(ss.A[0].T @ P @ ss.A[0] - P, -np.eye(2), atol=1e-6)
    assert 0 < report.contraction < 1 and json.dumps(report.to_dict())
    # one mode of ρ ≥ 1 stays uncertified, by its spectral radius
    assert not stability_report(_hand_made(np.array([[[1.0, 0.0], [1.0, 0.0]]]))).certified


def test_a_solver_that_fails_is_named_in_a_few_words_never_by_its_own_text(monkeypatch):
    import cvxpy as cp

    def failing(self, solver=None, **options):
        raise cp.error.SolverError(f"Solver '{solver}' failed. Try another solver, or "
                                   "solve with verbose=True for more information.")

    monkeypatch.setattr(cp.Problem, "solve", failing)
    pair = np.array([[[0.5, 0.0], [0.0, 0.5]], [[0.4, 0.0], [0.0, 0.4]]])
    report = stability_report(_hand_made(pair))
    assert not report.certified
    assert "no common quadratic Lyapunov function was found (CLARABEL: failed " \
           "numerically; SCS: failed numerically)" in report.message
    assert "Try another solver" not in report.message and "'" not in report.message
    assert "\n" not in report.message


def _flagged(B0, B1, c0=1.0, c1=1.0, split: str = "flag") -> PWAStateSpace:
    """Two modes x⁺ = A_i x + f_i over three output lags of one output (one input entering
    nothing): A_i = diag(B_i, 0.5), f_i = (0, 0, c_i), so x3 is a flag that mode i moves to
    0.5·x3 + c_i. Mode 0 holds where x3 ≤ 0 and mode 1 where x3 ≥ 0 (``split="flag"``), or
    where u ≤ 0 and u ≥ 0 (``split="input"``: the input picks the mode, any switching).
    Envelope: x1, x2, u in [−1, 1], x3 in [−2, 2]."""
    A = np.zeros((2, 3, 3))
    for i, Bi in enumerate((B0, B1)):
        A[i, :2, :2], A[i, 2, 2] = Bi, 0.5
    f = np.array([[0.0, 0.0, c0], [0.0, 0.0, c1]])
    column = 2 if split == "flag" else 3
    rows = [np.eye(4)[column], -np.eye(4)[column]]
    regions = [(rows[0][None, :], np.zeros(1)), (rows[1][None, :], np.zeros(1))]
    box = (np.array([-1.0, -1.0, -2.0, -1.0]), np.array([1.0, 1.0, 2.0, 1.0]))
    return PWAStateSpace(A, np.zeros((2, 3, 1)), f, np.zeros((2, 1, 3)), np.zeros((2, 1)),
                         regions, *box, output_lags=3, input_lags=0)


#: Each stable (ρ = 0.5), but alternating between them diverges (ρ(A_1 A_0) ≈ 4.2).
_SHEAR = (np.array([[0.5, 2.0], [0.0, 0.5]]), np.array([[0.5, 0.0], [2.0, 0.5]]))


def _check_certificate(report, ss, pairs):
    for i in range(ss.n_modes):
        assert np.linalg.eigvalsh(report.certificates[f"P{i + 1}"]).min() > 0
    for i, j in pairs:
        Pi, Pj = report.certificates[f"P{i + 1}"], report.certificates[f"P{j + 1}"]
        assert np.linalg.eigvalsh(ss.A[i].T @ Pj @ ss.A[i] - Pi).max() < 0


def test_piecewise_quadratic_certifies_where_no_common_function_exists():
    import cvxpy as cp

    ss = _flagged(*_SHEAR)  # mode 1 keeps x3 ≥ 1: the model never goes back to mode 0
    A0, A1 = ss.A
    # no common quadratic function: it would contract A_1 A_0, whose spectral radius is > 1
    assert np.abs(np.linalg.eigvals(A1 @ A0)).max() > 1
    P = cp.Variable((3, 3), symmetric=True)
    lmi = cp.Problem(cp.Minimize(0), [P >> np.eye(3)]
                     + [a.T @ P @ a - P << -np.eye(3) for a in ss.A])
    lmi.solve(solver="CLARABEL")
    assert lmi.status == "infeasible"

    report = ss.stability()
    assert report.certified and report.method.startswith("piecewise quadratic")
    assert "no common quadratic Lyapunov function was found" in report.message
    # 0 → 0 only on the face x3 = −2 (kept: closed regions), 0 → 1, 1 → 1; never 1 → 0
    assert sorted(map(tuple, report.transitions.tolist())) == [(0, 0), (0, 1), (1, 1)]
    _check_certificate(report, ss, [(0, 0), (0, 1), (1, 1)])
    assert set(report.certificates) == {"P1", "P2"} and report.P is None
    assert 0 < report.contraction < 1
    assert json.dumps(report.to_dict())


def test_a_mode_of_spectral_radius_one_or_more_is_decided_by_its_own_transition():
    # mode 1 (ρ = 1.05) keeps the flag up: it can follow itself, nothing is certified
    looping = _flagged(_SHEAR[0], np.array([[1.05, 0.0], [0.3, 0.5]])).stability()
    assert not looping.certified and looping.method == "spectral radius"
    assert "mode(s) [1]" in looping.message and "follow themselves" in looping.message
    assert looping.certificates == {}
    # mode 0 (ρ = 1.2) always raises the flag (x3⁺ ≥ 0.5): it never follows itself, so a
    # piecewise function can exist, where a common one cannot
    passing = _flagged(np.array([[1.2, 0.0], [0.0, 0.5]]), _SHEAR[1], c0=1.5)
    report = passing.stability()
    assert report.certified and report.method.startswith("piecewise quadratic")
    assert sorted(map(tuple, report.transitions.tolist())) == [(0, 1), (1, 1)]
    _check_certificate(report, passing, [(0, 1), (1, 1)])


def test_switching_between_stable_modes_is_not_certified_by_the_piecewise_search():
    # the input picks the mode: every switching sequence can happen, and alternating
    # diverges, so the decrease across modes (i → j, i ≠ j) must be asked for
    ss = _flagged(*_SHEAR, c0=0.0, c1=0.0, split="input")
    x = np.array([0.1, 0.1, 0.0])
    for _ in range(5):
        x = ss.A[1] @ ss.A[0] @ x
    assert np.abs(x).max() > 100
    report = ss.stability()
    assert sorted(map(tuple, report.transitions.tolist())) == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert not report.certified and report.method.startswith("piecewise quadratic")
    assert "no piecewise-quadratic Lyapunov function" in report.message


def _sampled_steps(ss: PWAStateSpace, seed: int = 3) -> set[tuple[int, int]]:
    """The pairs (mode, next mode) of one step from 4000 random points of the envelope,
    each with a random next input (steps that leave the envelope left out)."""
    rng = np.random.default_rng(seed)
    lower, upper = ss.envelope
    n = ss.n_states
    z = rng.uniform(lower, upper, size=(4000, lower.size))
    mode = ss.mode_of(z[:, :n], z[:, n:])
    x_next = np.einsum("kij,kj->ki", ss.A[mode], z[:, :n]) \
        + np.einsum("kij,kj->ki", ss.B[mode], z[:, n:]) + ss.f[mode]
    following = ss.mode_of(x_next, rng.uniform(lower[n:], upper[n:],
                                               size=(len(z), ss.n_inputs)))
    return {(int(i), int(j)) for i, j in zip(mode, following, strict=True) if j >= 0}


def test_transitions_hold_every_step_and_leave_out_the_impossible(default_ss):
    from pwa_pipeline.control.stability import transitions

    possible = transitions(default_ss)
    seen = _sampled_steps(default_ss)
    assert len(seen) > 1 and all(possible[i, j] for i, j in seen)
    # the input drives the flag x3 (off-centre, unevenly scaled envelope): mode 0
    # (x3 ≤ 1) steps to 0.5·x3 + 0.2·u + 0.1 in [0.5, 1.2], either region; mode 1 (x3 ≥ 1)
    # to 0.5·x3 + 0.5·u in [1.5, 3.5], never back
    A = np.zeros((2, 3, 3))
    A[:, :2, :2], A[:, 2, 2] = 0.5 * np.eye(2), 0.5
    B = np.zeros((2, 3, 1))
    B[:, 2, 0] = [0.2, 0.5]
    flag = np.array([[0.0, 0.0, 1.0, 0.0]])
    ss = PWAStateSpace(A, B, np.array([[0.0, 0.0, 0.1], [0.0, 0.0, 0.0]]),
                       np.zeros((2, 1, 3)), np.zeros((2, 1)),
                       [(flag, np.ones(1)), (-flag, -np.ones(1))],
                       np.array([-1.0, -1.0, 0.0, 2.0]), np.array([1.0, 1.0, 4.0, 3.0]),
                       output_lags=3, input_lags=0)
    possible = transitions(ss)
    assert possible.tolist() == [[True, True], [False, True]]
    assert _sampled_steps(ss) == {(0, 0), (0, 1), (1, 1)}


def test_the_search_keeps_to_its_size_and_time_bounds():
    ss = _flagged(*_SHEAR)
    big = ss.stability(max_lmi_size=10)
    assert not big.certified and big.method.endswith("(not searched: LMI too large)")
    assert "max_lmi_size = 10" in big.message
    late = ss.stability(max_seconds=0.0)
    assert not late.certified and "(not searched: time)" in late.method
    assert "max_seconds" in late.message


def test_a_version_1_document_is_still_read(default_ss):
    """Documents written before the feedthrough D existed (version 1, no D) read as D = 0."""
    doc = json.loads(default_ss.to_json())
    doc["schema_version"] = 1
    del doc["D"]
    back = PWAStateSpace.from_json(json.dumps(doc))
    np.testing.assert_array_equal(back.D, np.zeros_like(default_ss.D))
    np.testing.assert_array_equal(back.A, default_ss.A)


def test_output_lags_nothing_reads_are_left_out_of_the_state():
    """A regressor with an output lag no parameter row or region reads (as a structure
    search's level-form choice of order na on its φ of na + 1 lags) gives a state without
    it: no entry that nothing reads, the same free run from the same warm-up, and a JSON
    that reads back; ``source`` names the outputs' coupling."""
    data = make_hure_vasak(n_samples=600, snr_db=30.0, seed=3)
    u, y = data.u_train[0], data.y_train[0]
    model = LinearARX(na=2, nb=1).fit(u, y)
    full = model.to_state_space()
    assert full.n_states == 6 and full.source["outputs"] == "joint"
    model.theta_[[1, 3]] = 0.0  # y1(k-2), y2(k-2): read by nothing
    ss = model.to_state_space()
    assert ss.output_lags == 1 and ss.state_names == ["y1(k-1)", "y2(k-1)", "u1(k-1)",
                                                      "u2(k-1)"]
    assert not np.any(np.all(ss.A == 0, axis=(0, 2)) & np.all(ss.C == 0, axis=(0, 1)))
    np.testing.assert_allclose(ss.simulate(u, y[:5]), model.simulate(u, y[:5]), rtol=0,
                               atol=1e-10)
    back = PWAStateSpace.from_json(ss.to_json())
    np.testing.assert_array_equal(back.simulate(u, y[:5]), ss.simulate(u, y[:5]))
