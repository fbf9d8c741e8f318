"""One estimator, one fitted shape: every way of configuring PWARX (and the linear baseline)
ends in the same fitted attributes, the same return types and a state-space form that
simulates as the model does."""

import numpy as np
import pytest
from sklearn.base import clone

from pwa_pipeline import PWARX, LinearARX, SubspaceSS, make_hure_vasak
from pwa_pipeline.pwa import OutputGroup, RegionMap
from pwa_pipeline.pwa.output_error import OutputErrorRefinement
from pwa_pipeline.pwa.scheduling import SignScheduling

ROUTES = {
    "paper": PWARX.paper(1, 1, n_rho=18, eps=0.1, min_pts=20),
    "default": PWARX(na=1, nb=1),
    "refined": PWARX(na=1, nb=1, refinement=OutputErrorRefinement(max_iter=2)),
    "velocity clustered": PWARX(na=1, nb=1, affine=True, form="velocity"),
    "decoupled clustered": PWARX(na=1, nb=1, outputs="decoupled"),
    "scheduled": PWARX(na=2, nb=1, affine=True, outputs="decoupled",
                       scheduling=SignScheduling(switch="select")),
    "search": PWARX.auto(1, 1, clustering=False, max_seconds=600),
    "linear": LinearARX(na=1, nb=1),
    "linear velocity": LinearARX(na=1, nb=1, affine=True, form="velocity",
                                 outputs="decoupled"),
}


@pytest.fixture(scope="module")
def data():
    train = make_hure_vasak(n_samples=1200, snr_db=30, seed=3)
    test = make_hure_vasak(n_samples=300, snr_db=30, seed=1003)
    return train, test


@pytest.fixture(scope="module", params=list(ROUTES))
def fitted(request, data):
    train, _ = data
    return request.param, clone(ROUTES[request.param]).fit(
        [train.u_train[0][:600], train.u_train[0][600:]], [train.y_train[0][:600], train.y_train[0][600:]])


def test_every_route_has_the_same_fitted_shape(fitted, data):
    name, model = fitted
    _, test = data
    m = 2
    groups = model.groups_
    assert groups and all(isinstance(g, OutputGroup) for g in groups)
    assert sorted(j for g in groups for j in g.outputs) == list(range(m)), name
    d = model.thetas_.shape[1]
    for g in groups:
        assert isinstance(g.regions, RegionMap)
        assert g.thetas.shape == (g.n_regions, d, len(g.outputs))
    assert isinstance(model.regions_, RegionMap)
    assert model.thetas_.shape == (model.n_submodels_, d, m)
    assert model.n_submodels_ == int(np.prod([g.n_regions for g in groups]))
    assert len(model.structures_) == m and all(isinstance(s, str) for s in model.structures_)
    assert sum(model.timings_.values()) > 0
    assert isinstance(model.steps_, dict)
    # the model as eq. (1) predicts as the groups do
    from pwa_pipeline.regressors import lagged_matrix

    phi = lagged_matrix(test.u_train[0], test.y_train[0], model.output_lags_, model.nb, model.affine)
    modes = model.regions_.predict(phi)
    np.testing.assert_allclose(np.einsum("nd,ndm->nm", phi, model.thetas_[modes]),
                               model.predict(test.u_train[0], test.y_train[0])[model.n_initial_:], atol=1e-10)


def test_every_route_answers_in_kind(fitted, data):
    """One experiment in, an ndarray (N, m) out; a list in, a list out; the same numbers."""
    name, model = fitted
    _, test = data
    one = model.predict(test.u_train[0], test.y_train[0])
    free = model.simulate(test.u_train[0], test.y_train[0][:10])
    assert isinstance(one, np.ndarray) and one.shape == test.y_train[0].shape
    assert isinstance(free, np.ndarray) and free.shape == test.y_train[0].shape
    us, ys = [test.u_train[0][:150], test.u_train[0][150:]], [test.y_train[0][:150], test.y_train[0][150:]]
    many = model.predict(us, ys)
    runs = model.simulate(us, [y[:10] for y in ys])
    assert isinstance(many, list) and isinstance(runs, list) and len(many) == len(runs) == 2
    np.testing.assert_array_equal(many[0], model.predict(us[0], ys[0]))
    np.testing.assert_array_equal(runs[1], model.simulate(us[1], ys[1][:10]))
    flags = model.outside_envelope(us, runs)
    assert isinstance(flags, list) and flags[0].dtype == bool
    assert isinstance(model.score(test.u_train[0], test.y_train[0]), float)


def test_every_route_exports_a_state_space_form_that_simulates_as_the_model(fitted, data):
    name, model = fitted
    _, test = data
    ss = model.to_state_space()
    assert ss.n_modes >= 1 and ss.source["structures"] == model.structures_
    u, y = test.u_train[0][:150], test.y_train[0][:150]
    np.testing.assert_allclose(ss.simulate(u, y[:10], outside="nearest"),
                               model.simulate(u, y[:10]), rtol=0, atol=1e-8)


def test_the_subspace_baseline_shares_the_interface(data):
    train, test = data
    model = SubspaceSS(order=4).fit(train.u_train[0], train.y_train[0])
    assert isinstance(model.predict(test.u_train[0], test.y_train[0]), np.ndarray)
    assert isinstance(model.simulate([test.u_train[0]], [test.y_train[0][:10]]), list)
    assert -1 < model.score(test.u_train[0], test.y_train[0]) <= 1
    flags = model.outside_envelope(test.u_train[0] * 100, test.y_train[0])
    assert not flags[0] and flags[1:].all()
    assert not model.outside_envelope(train.u_train[0], train.y_train[0]).any()
    assert model.timings_["fit"] > 0


def test_the_subspace_model_exports_a_state_space_form_with_its_feedthrough(data, tmp_path):
    """One mode, the model's own state x1 … xn and D; simulated from the model's initial
    state it is the model's free run; JSON keeps D and the state's names; an MPC plans on
    it."""
    from pwa_pipeline.control import HybridMPC, PWAStateSpace

    train, test = data
    model = SubspaceSS(order=4).fit(train.u_train, train.y_train)
    ss = model.to_state_space(train.u_train, train.y_train)
    assert (ss.n_modes, ss.n_states, ss.state_names[0]) == (1, 4, "x1")
    np.testing.assert_array_equal(ss.D[0], model.D_)
    u, y = test.u_train[0][:200], test.y_train[0][:200]
    x0 = model.initial_state(u[:10], y[:10])
    np.testing.assert_allclose(ss.simulate(u, x0=x0, outside="nearest")[10:],
                               model.simulate(u, y[:10])[10:], rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="not made of past outputs"):
        ss.simulate(u, y[:10])
    back = PWAStateSpace.from_json(ss.to_json(tmp_path / "ss.json"))
    np.testing.assert_array_equal(back.D, ss.D)
    assert back.state_names == ss.state_names and back.output_lags is None
    x = np.clip(x0, *(b[:4] for b in ss.envelope))
    plan = HybridMPC(ss, horizon=5).solve(x, y_ref=np.median(y, axis=0),
                                          u_prev=np.median(u, axis=0))
    assert plan.optimal and plan.u.shape == (5, 2)


def test_set_params_reaches_every_step_of_a_plain_pwarx():
    """PWARX(...) leaves its steps at None (the defaults, filled at fit); their parameters
    are settable all the same, and an option that is off says what to set first."""
    model = PWARX(na=2, nb=2).set_params(local_models__n_rho=200, clustering__eps=0.3,
                                         submodels__n_refine=3, regions__C=5.0)
    params = model.get_params(deep=True)
    assert (params["local_models__n_rho"], params["clustering__eps"],
            params["submodels__n_refine"], params["regions__C"]) == (200, 0.3, 3, 5.0)
    assert PWARX().local_models is None  # the default instance is not touched
    assert clone(model).get_params()["local_models__n_rho"] == 200
    with pytest.raises(ValueError, match="refinement__max_iter: refinement is None"):
        PWARX().set_params(refinement__max_iter=3)
    refined = PWARX().set_params(refinement=OutputErrorRefinement(), refinement__max_iter=3)
    assert refined.refinement.max_iter == 3
