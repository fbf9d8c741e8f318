"""The data envelope at use time: fitted models flag the samples whose regressor φ(k) leaves
the padded box of their training data (one-step and free run), the evaluation reports the
share, MLflow logs it, and the prediction figure hatches those stretches."""

import copy
import pickle

import numpy as np
import pytest

from pwa_pipeline import PWARX, LinearARX, SubspaceSS, make_hure_vasak
from pwa_pipeline.datasets import Dataset
from pwa_pipeline.envelope import PADDING, channel_bounds, regressor_bounds
from pwa_pipeline.orchestration.reporting import score_metrics
from pwa_pipeline.plotting import PredictionDisplay
from pwa_pipeline.scoring.evaluation import evaluate

WARMUP = 10


def _arx(u: np.ndarray, a: float = 0.5, b: float = 2.0) -> np.ndarray:
    """y(k) = a·y(k−1) + b·u1(k−1) (− 0.5·u2(k−1) with a second input), noise free."""
    y = np.zeros((u.shape[0], 1))
    for k in range(1, u.shape[0]):
        y[k] = a * y[k - 1] + b * u[k - 1, 0] - (0.5 * u[k - 1, 1] if u.shape[1] > 1 else 0)
    return y


def _box(signal_range: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each channel's training range widened by 5 % of its span, computed here by hand."""
    lo, hi = signal_range
    return lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo)


def _brute_force(u: np.ndarray, y: np.ndarray, signal_range: np.ndarray, lags: int, nb: int,
                 start: int = 0) -> np.ndarray:
    """Whether φ(k) = [y_p(k−1…k−lags) per output, u_q(k−1…k−nb) per input] leaves the box,
    one sample at a time (False before max(lags, nb) and before ``start``)."""
    lo, hi = _box(signal_range)
    m = y.shape[1]
    out = np.zeros(u.shape[0], bool)
    for k in range(max(lags, nb, start), u.shape[0]):
        for p in range(m):
            for j in range(1, lags + 1):
                v = y[k - j, p]
                out[k] |= not (lo[p] <= v <= hi[p])
        for q in range(u.shape[1]):
            for j in range(1, nb + 1):
                v = u[k - j, q]
                out[k] |= not (lo[m + q] <= v <= hi[m + q])
    return out


@pytest.fixture(scope="module")
def input_only():
    """y(k) = 2·u(k−1) + noise fitted as ARX(0, 1): φ(k) = u(k−1) alone, so the share outside
    the envelope is known from the input's distribution."""
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, size=(4000, 1))
    y = np.r_[[[0.0]], 2 * u[:-1]] + rng.normal(0, 0.01, size=(4000, 1))
    return LinearARX(na=0, nb=1).fit(u, y)


@pytest.fixture(scope="module")
def paper():
    """The paper's system (2 outputs, 2 inputs): the default PWARX and a held-out record."""
    train = make_hure_vasak(n_samples=1500, snr_db=30, seed=0)
    test = make_hure_vasak(n_samples=1500, snr_db=30, seed=1000)
    return PWARX(na=1, nb=1).fit(train.u_train[0], train.y_train[0]), train, test


def test_inputs_three_times_the_training_range_are_flagged(input_only):
    """|3v| with v uniform on [−1, 1] leaves the padded range [−1.1, 1.1] with probability
    1 − 1.1/3: the second half of the record, scaled 3×, has that share outside, the first
    half none."""
    rng = np.random.default_rng(1)
    u = rng.uniform(-1, 1, size=(20000, 1))
    u[10000:] *= 3
    y = 2 * np.r_[[[0.0]], u[:-1]]
    flags = input_only.outside_envelope(u, y)
    assert flags.shape == (20000,) and flags.dtype == bool
    assert not flags[:10001].any()  # φ(10000) = u(9999), unscaled
    assert flags[10001:].mean() == pytest.approx(1 - 1.1 / 3, abs=0.015)  # (σ 0.005)
    np.testing.assert_array_equal(flags, _brute_force(u, y, input_only.signal_range_, 0, 1))
    ev = evaluate(input_only, u, y, warmup=WARMUP)
    for mode in ("one_step", "free_run"):  # (φ holds no output: both modes alike)
        expected = flags[WARMUP:].mean()
        assert ev.outside_share(mode) == pytest.approx(expected, abs=1e-12)
        assert expected == pytest.approx((1 - 1.1 / 3) / 2, abs=0.01)


def test_in_range_data_give_a_share_of_zero():
    """A noise-free ARX model scored on its own training record: every one-step φ is a
    training regressor, and the exact model's free run retraces the data."""
    u = np.random.default_rng(2).normal(size=(600, 2))
    y = _arx(u)
    model = LinearARX(na=1, nb=1).fit(u, y)
    ev = evaluate(model, u, y, warmup=WARMUP)
    assert ev.outside_share("one_step") == 0 and ev.outside_share("free_run") == 0
    assert not any(f.any() for flags in ev.outside.values() for f in flags)
    assert (ev.table["outside_share"] == 0).all()
    # just beyond the padding: flagged; just inside it: not
    lo, hi = channel_bounds(model.signal_range_)
    for value, outside in ((hi[1] * (1 + 1e-6), True), (hi[1] * (1 - 1e-6), False)):
        edge = u.copy()
        edge[300, 0] = value
        flags = model.outside_envelope(edge, y)
        assert flags[301] == outside and flags.sum() == int(outside)


@pytest.mark.parametrize("make", [
    lambda: LinearARX(na=2, nb=1),
    lambda: LinearARX(na=1, nb=3),
    lambda: LinearARX(na=1, nb=1, form="velocity"),
    lambda: PWARX(na=1, nb=1),
], ids=["arx21", "arx13", "velocity", "pwarx"])
def test_the_flags_match_a_brute_force_check_of_phi_against_the_padded_box(make, paper):
    """One-step (measured outputs) and free run (the run's own): each sample's φ(k) checked
    entry by entry against its channel's padded range. The channels have different ranges
    (the inputs are scaled apart), so a lag given another channel's bounds is caught."""
    _, train, test = paper
    scale = np.array([1.0, 4.0])
    model = make().fit(train.u_train[0] * scale, train.y_train[0])
    lags = model.output_lags_
    u = test.u_train[0] * scale * np.where(np.arange(1500) % 300 < 60, 1.6, 1.0)[:, None]
    y = test.y_train[0]
    # the range the fit recorded is the training data's own
    np.testing.assert_array_equal(model.signal_range_, np.vstack([
        np.hstack([train.y_train[0], train.u_train[0] * scale]).min(axis=0),
        np.hstack([train.y_train[0], train.u_train[0] * scale]).max(axis=0)]))
    one = model.outside_envelope(u, y)
    np.testing.assert_array_equal(one, _brute_force(u, y, model.signal_range_, lags, model.nb))
    assert 0.05 < one.mean() < 0.5
    sim = model.simulate(u, y[:WARMUP])
    free = model.outside_envelope(u, sim)
    np.testing.assert_array_equal(free[WARMUP:], _brute_force(u, sim, model.signal_range_, lags,
                                                              model.nb, start=WARMUP)[WARMUP:])


def test_predict_and_simulate_answer_in_kind_and_the_flags_come_apart(paper):
    """One experiment in, one array out; a list in, a list out; the envelope's flags from
    outside_envelope, never beside the numbers."""
    model, _, test = paper
    u = test.u_train[0] * 2.0
    us, ys = [u[:700], u[700:]], [test.y_train[0][:700], test.y_train[0][700:]]
    pred = model.predict(us, ys, n_init=20)
    assert isinstance(pred, list) and [p.shape for p in pred] == [(700, 2), (800, 2)]
    for p, ue, ye in zip(pred, us, ys, strict=True):
        np.testing.assert_array_equal(p, model.predict(ue, ye, n_init=20))
        flags = model.outside_envelope(ue, ye)
        assert flags.shape == (ue.shape[0],) and flags.any()
    assert isinstance(model.predict(u, test.y_train[0]), np.ndarray)
    sims = model.simulate(us, [y[:5] for y in ys])
    assert isinstance(sims, list) and isinstance(model.simulate(u, test.y_train[0][:5]), np.ndarray)
    with pytest.raises(TypeError, match="return_outside"):
        model.simulate(u, test.y_train[0][:5], return_outside=True)


def test_a_diverged_free_run_is_outside_from_where_it_is_not_finite():
    u = np.random.default_rng(3).normal(size=(400, 1))
    model = LinearARX(na=1, nb=1).fit(u, _arx(u[:, :1]))
    model.theta_[:] = np.array([[10.0], [1.0]])  # y(k) = 10y(k−1) + u(k−1): overflows
    sim = model.simulate(u, np.zeros((1, 1)))
    flags = model.outside_envelope(u, sim)
    bad = np.flatnonzero(~np.isfinite(sim[:, 0]))
    assert bad.size and flags[bad[0] + 1:].all()
    ev = evaluate(model, u, _arx(u), warmup=WARMUP)
    assert ev.diverged() and ev.outside_share("free_run") > 0.9
    m = score_metrics(ev)  # no free-run score of a diverged run, its share neither
    assert not {"free_run_nrmse", "free_run_outside_share"} & m.keys()
    assert m["one_step_outside_share"] == float(f"{ev.outside_share('one_step'):.4g}")


def test_the_envelope_is_the_one_the_state_space_form_bounds_its_regions_with(paper):
    """One box: the state-space envelope over x is the model's over φ (the constant left
    out), with each input's padded range appended for u(k)."""
    model, _, _ = paper
    ss = model.to_state_space()
    lower, upper = model.envelope()
    n = ss.n_states
    np.testing.assert_array_equal(ss.envelope[0][:n], lower)
    np.testing.assert_array_equal(ss.envelope[1][:n], upper)
    lo, hi = channel_bounds(model.signal_range_)
    np.testing.assert_array_equal(ss.envelope[0][n:], lo[model.n_outputs_:])
    np.testing.assert_array_equal(ss.envelope[1][n:], hi[model.n_outputs_:])
    assert PADDING == 0.05
    wide = model.envelope(padding=0.5)
    assert np.all(wide[0] < lower) and np.all(wide[1] > upper)
    # a φ(k) outside the box is out of the state-space envelope too, whatever u(k)
    u = np.random.default_rng(4).normal(size=(300, 2)) * 2.5
    y = model.simulate(u, np.zeros((1, 2)))
    flags = model.outside_envelope(u, y)[1:]
    x = ss.states(u, y)
    inside = ss.in_envelope(x, np.zeros_like(u[1:]))  # (0 is inside every input's range)
    np.testing.assert_array_equal(flags, ~inside)
    assert flags.any() and not flags.all()


def test_a_model_without_its_training_range_has_no_envelope(paper):
    """A model that records no training range (one pickled before signal_range_ existed)
    says so, and the evaluation reports no share outside rather than a wrong one."""
    fitted, _, test = paper
    bare = copy.copy(fitted)
    del bare.signal_range_
    with pytest.raises(ValueError, match="does not record the range of its training data"):
        bare.outside_envelope(test.u_train[0], test.y_train[0])
    ev = evaluate(bare, test.u_train[0], test.y_train[0], warmup=WARMUP)
    assert ev.outside is None and ev.table["outside_share"].isna().all()
    assert not any("outside" in k for k in score_metrics(ev))


def test_evaluate_reports_the_share_per_mode_and_mlflow_logs_it(paper):
    model, _, test = paper
    u = test.u_train[0].copy()
    u[300:500] *= 3
    us, ys = [u[:800], u[800:]], [test.y_train[0][:800], test.y_train[0][800:]]
    ev = evaluate(model, us, ys, warmup=WARMUP, output_names=["a", "b"])
    assert set(ev.outside) == {"one_step", "free_run"}
    one = [model.outside_envelope(ue, ye) for ue, ye in zip(us, ys, strict=True)]
    free = [model.outside_envelope(ue, p) for ue, p in
            zip(us, ev.predictions["free_run"], strict=True)]
    for mode, flags in (("one_step", one), ("free_run", free)):
        expected = np.concatenate([f[WARMUP:] for f in flags]).mean()
        rows = ev.table[ev.table["mode"] == mode]
        assert list(rows["output"]) == ["a", "b", "mean"]
        np.testing.assert_allclose(rows["outside_share"], expected, rtol=0, atol=1e-15)
        assert 0.05 < expected < 0.3
        for got, f in zip(ev.outside[mode], flags, strict=True):
            assert not got[:WARMUP].any()
            np.testing.assert_array_equal(got[WARMUP:], f[WARMUP:])
    m = score_metrics(ev)
    assert m["one_step_outside_share"] == float(f"{ev.outside_share('one_step'):.4g}")
    assert m["free_run_outside_share"] == float(f"{ev.outside_share('free_run'):.4g}")
    assert "per_output/one_step_outside_share_a" not in m
    again = pickle.loads(pickle.dumps(ev))  # the scores cache pickles it
    np.testing.assert_array_equal(again.outside["free_run"][1], ev.outside["free_run"][1])


def test_the_subspace_model_flags_samples_whose_past_left_its_training_range():
    """The state-space baseline has no regressor; its envelope is the channels' padded
    training range, tested on the past sample's inputs and outputs."""
    data = make_hure_vasak(n_samples=600, snr_db=30, seed=5)
    model = SubspaceSS(order=2).fit(data.u_train[0], data.y_train[0])
    u = data.u_train[0] * np.where(np.arange(600) % 200 < 40, 3.0, 1.0)[:, None]
    flags = model.outside_envelope(u, data.y_train[0])
    lower, upper = channel_bounds(model.signal_range_)
    past = np.hstack([data.y_train[0], u])[:-1]
    np.testing.assert_array_equal(flags[1:], ((past < lower) | (past > upper)).any(axis=1))
    ev = evaluate(model, u, data.y_train[0], warmup=WARMUP)
    expected = float(np.mean(flags[WARMUP:]))
    assert ev.outside_share("one_step") == pytest.approx(expected) and 0 < expected < 1


def _stretches(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) sample of each run of True."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _hatched(ax, label: str) -> list:
    return [c for c in ax.collections if c.get_label() == label]


def test_the_prediction_figure_hatches_the_stretches_outside_the_training_data(paper):
    model, train, test = paper
    u = test.u_train[0].copy()
    u[200:260] *= 3
    data = Dataset("hure_vasak", [train.u_train[0]], [train.y_train[0]], [u], [test.y_train[0]],
                   train.u_names,
                   train.y_names)
    ev = evaluate(model, u, test.y_train[0], warmup=WARMUP, output_names=train.y_names)
    fig = PredictionDisplay.from_evaluation(ev, data, WARMUP, context="hure_vasak | set s | PWA").figure_
    for mode, label in (("one_step", "one-step"), ("free_run", "free run")):
        mask = ev.outside[mode][0][:606]
        assert mask[200:260].any()
        for ax in fig.axes:
            (shade,) = _hatched(ax, f"{label} outside the training data")
            assert shade.get_hatch()
            # one polygon per stretch, from half a sample before it to half a sample after
            spans = sorted((round(p.vertices[:, 0].min(), 6), round(p.vertices[:, 0].max(), 6))
                           for p in shade.get_paths() if len(p.vertices))
            assert spans == [(a - 0.5, b + 0.5) for a, b in _stretches(mask)]
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "one-step outside the training data" in legend
    assert "free run outside the training data" in legend
    third = fig.get_suptitle().splitlines()[2]
    assert third == (f"Regressor outside the training data (hatched): one-step "
                     f"{100 * ev.outside_share('one_step'):.3g} %, free run "
                     f"{100 * ev.outside_share('free_run'):.3g} % of the scored samples")


def test_the_prediction_figure_has_no_hatching_inside_the_training_data():
    u = np.random.default_rng(6).normal(size=(500, 2))
    y = _arx(u)
    model = LinearARX(na=1, nb=1).fit(u, y)
    data = Dataset("d", [u], [y], [u], [y], ["u1", "u2"], ["y1"])
    ev = evaluate(model, u, y, warmup=WARMUP)
    fig = PredictionDisplay.from_evaluation(ev, data, WARMUP, context="d | set s | ARX").figure_
    assert not [c for ax in fig.axes for c in ax.collections
                if "outside the training data" in c.get_label()]
    assert len(fig.get_suptitle().splitlines()) == 2


def test_regressor_bounds_give_each_lag_its_channels_range():
    rng = np.array([[0.0, -1.0, 10.0], [1.0, 1.0, 10.0]])  # y1, u1, u2 (u2 constant)
    lower, upper = regressor_bounds(rng, m=1, r=2, output_lags=2, input_lags=1)
    np.testing.assert_allclose(lower, [-0.05, -0.05, -1.1, 9.5])
    np.testing.assert_allclose(upper, [1.05, 1.05, 1.1, 10.5])
    with pytest.raises(ValueError, match="padding"):
        regressor_bounds(rng, 1, 2, 1, 1, padding=-0.1)
    with pytest.raises(ValueError, match="3 channel"):
        regressor_bounds(rng, 2, 2, 1, 1)
