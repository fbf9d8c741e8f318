"""The figures of :mod:`pwa_pipeline.plotting` on a small fit, as the pipeline's pages show them."""

import base64
import copy
import struct
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.contour import ContourSet

from pwa_pipeline import PWARX
from pwa_pipeline._arrays import column_rms
from pwa_pipeline._validation import as_experiments
from pwa_pipeline.datasets import Dataset, make_hure_vasak
from pwa_pipeline.orchestration.images import to_markdown, to_png
from pwa_pipeline.plotting import (
    ParameterClustersDisplay,
    PredictionDisplay,
    RegionsDisplay,
    SwitchingDisplay,
    context_title,
)
from pwa_pipeline.plotting import clusters as cluster_figure
from pwa_pipeline.plotting.prediction import clip_range
from pwa_pipeline.plotting.style import MAX_SAMPLES
from pwa_pipeline.pwa.partitions import argmax_halfspaces
from pwa_pipeline.pwa.steps.clustering import k_distances
from pwa_pipeline.pwa.steps.embedding import exact_embedding
from pwa_pipeline.regressors import build_regressors, lagged_matrix, regressor_names
from pwa_pipeline.scoring.evaluation import Evaluation, evaluate
from pwa_pipeline.scoring.metrics import match_submodels

WARMUP = 10


@pytest.fixture(scope="module")
def fit():
    """PWARX(na=1, nb=1) on 1,500 samples at 30 dB, scored on a fresh record."""
    data = make_hure_vasak(n_samples=1500, n_test=1500, snr_db=30, seed=0)
    model = PWARX(na=1, nb=1).fit(data.u_train, data.y_train)
    test = SimpleNamespace(u=data.u_test[0], y=data.y_test[0], modes=data.truth.modes_test[0],
                           thetas=data.truth.thetas)
    ev = evaluate(model, data.u_test, data.y_test, warmup=WARMUP, output_names=data.y_names)
    reg = build_regressors(as_experiments(data.u_train, data.y_train), 1, 1, False)
    names = regressor_names(data.y_names, data.u_names, 1, 1, False)
    return SimpleNamespace(model=model, data=data, ev=ev, reg=reg, names=names, test=test)


def _diverged(fit, flagged=True):
    """The fit's evaluation with y1's free run at 1e30 from k = 200 and y2's NaN from 300."""
    free = fit.ev.predictions["free_run"][0].copy()
    free[200:, 0] = 1e30
    free[300:, 1] = np.nan
    table = fit.ev.table.copy()
    rows = table["mode"] == "free_run"
    table.loc[rows, "diverged"] = flagged
    table.loc[rows, "nrmse"] = [1e30, np.inf, np.inf] if flagged else [0.5, 0.5, 0.5]
    return Evaluation(table, {"one_step": fit.ev.predictions["one_step"], "free_run": [free]})


def _line(ax, label):
    lines = [ln for ln in ax.get_lines() if ln.get_label() == label]
    assert len(lines) == 1, [ln.get_label() for ln in ax.get_lines()]
    return lines[0]


def _outside_line(ev):
    """The prediction figure's third title line for ``ev`` (its share of scored samples
    outside the data envelope), "" when no share is above 0."""
    means = ev.table[ev.table["output"] == "mean"].set_index("mode")["outside_share"]
    if not (means > 0).any():
        return ""
    return (f"\nRegressor outside the training data (hatched): one-step "
            f"{100 * means['one_step']:.3g} %, free run {100 * means['free_run']:.3g} % of the "
            f"scored samples")


def test_prediction_titles_give_each_outputs_nrmse(fit):
    fig = PredictionDisplay.from_evaluation(fit.ev, fit.data, WARMUP, context="pwa | test").figure_
    assert len(fig.axes) == 2
    assert fig.get_suptitle() == ("pwa | test\nMeasured output, one-step prediction and free "
                                  "run: held-out experiment 1 of 1, samples 0–605 of 1500"
                                  + _outside_line(fit.ev))
    table = fit.ev.table
    for ax, name in zip(fig.axes, fit.data.y_names, strict=True):
        one = table[(table["mode"] == "one_step") & (table["output"] == name)]["nrmse"].item()
        free = table[(table["mode"] == "free_run") & (table["output"] == name)]["nrmse"].item()
        assert one != free
        assert ax.get_title(loc="left") == f"{name}: NRMSE one-step {one:.4g}, free run {free:.4g}"
        assert ax.get_ylabel() == name  # a unit-free data set
        n = 606
        assert np.allclose(_line(ax, "measured").get_ydata(),
                           fit.data.y_test[0][:n, fit.data.y_names.index(name)])
        assert len(_line(ax, "free run").get_ydata()) == n
        assert not any("diverged" in ln.get_label() for ln in ax.get_lines())
        (span,) = [p for p in ax.patches if p.get_label() == "warm-up"]
        assert span.get_x() == 0 and span.get_width() == WARMUP


def test_diverged_free_run_is_clipped_marked_and_labelled(fit):
    fig = PredictionDisplay.from_evaluation(_diverged(fit), fit.data, WARMUP, context="diverged").figure_
    y = fit.data.y_test[0]
    exits = {0: 200, 1: 300}
    for j, ax in enumerate(fig.axes):
        assert "(diverged)" in ax.get_title(loc="left")
        line = _line(ax, "free run (diverged, clipped)")
        assert line.get_color() == "#d62728"
        lo, hi = clip_range(y[:606, j])
        assert lo == pytest.approx(y[:606, j].min() - 0.5 * np.ptp(y[:606, j]))
        data = np.asarray(line.get_ydata(), float)
        drawn = data[np.isfinite(data)]
        assert drawn.size > 150 and drawn.min() >= lo and drawn.max() <= hi
        # The line reaches the edge once, at the exit, and does not run along it.
        assert data[exits[j]] == hi and np.sum(data == hi) == 1
        assert np.isnan(data[exits[j] + 1:]).all()
        (marker,) = [ln for ln in ax.get_lines() if ln.get_marker() == "^"]
        assert list(marker.get_xdata()) == [exits[j]]
        assert ax.get_ylim()[1] < hi + 0.1 * (hi - lo)
    # the score shown as every page shows a diverged run's, never its number (1e30, inf)
    for ax in fig.axes:
        assert ax.get_title(loc="left").endswith(", free run ≥ 10 (diverged)")


def _legend_texts(fig):
    assert all(ax.get_legend() is None for ax in fig.axes)  # one legend, the figure's
    (legend,) = fig.legends
    return [t.get_text() for t in legend.get_texts()]


def test_prediction_figure_has_one_legend_of_what_any_output_draws(fit):
    fig = PredictionDisplay.from_evaluation(fit.ev, fit.data, WARMUP, context="t").figure_
    # (the fit's free run leaves the data envelope at a sample of the experiment drawn)
    outside = ["free run outside the training data"] \
        if fit.ev.outside["free_run"][0][:MAX_SAMPLES].any() else []
    assert _legend_texts(fig) == ["warm-up", "measured", "one-step", "free run", *outside]
    # output 1 diverges (clipped, shaded), output 2 is NaN: each entry once, in drawn order
    diverged = _diverged(fit, flagged=False)
    assert _legend_texts(PredictionDisplay.from_evaluation(diverged, fit.data, WARMUP,
                                                           context="t").figure_) == [
        "warm-up", "measured", "one-step", "free run (clipped)", "free run out of range",
        "free run (diverged, clipped)", "diverged free run out of range"]
    to_png(fig)  # laid out: the legend below every axes and its x label, inside the figure
    box = fig.legends[0].get_window_extent()
    assert box.y1 <= min(ax.xaxis.label.get_window_extent().y0 for ax in fig.axes
                         if ax.get_xlabel())
    assert fig.bbox.x0 <= box.x0 and box.x1 <= fig.bbox.x1 and box.y0 >= fig.bbox.y0


def test_non_finite_free_run_counts_as_diverged_without_the_flag(fit):
    fig = PredictionDisplay.from_evaluation(_diverged(fit, flagged=False), fit.data, WARMUP,
                                            context="t").figure_
    ax1, ax2 = fig.axes
    assert _line(ax1, "free run (clipped)").get_color() == "C1"  # finite 1e30, not flagged
    _line(ax2, "free run (diverged, clipped)")  # NaN
    assert "(diverged)" not in ax1.get_title(loc="left")
    assert "(diverged)" in ax2.get_title(loc="left")


def test_parameter_clusters_show_the_unit_free_embedding_and_eps(fit, monkeypatch):
    model, step = fit.model, fit.model.steps_["clustering"]
    assert step.unit_free
    fig = ParameterClustersDisplay.from_steps(model.steps_["local_models"], step, fit.reg.target).figure_
    assert len(fig.axes) == 2
    ax, ax_k = fig.axes
    assert sum(c.get_offsets().shape[0] for c in ax.collections) == step.clustered_.sum()
    labels = [c.get_label() for c in ax.collections]
    assert sum(lab.startswith("cluster") for lab in labels) == step.n_clusters_
    (noise,) = [c for c in ax.collections if c.get_label().startswith("noise")]
    assert noise.get_offsets().shape[0] == np.sum(step.labels_[step.clustered_] < 0)
    assert np.allclose(noise.get_facecolor()[0][:3], 0x9A / 255)
    theta = model.steps_["local_models"].theta_[step.clustered_]
    scale = model.steps_["local_models"].phi_scale_[None, :, None] / column_rms(fit.reg.target)
    n = int(step.clustered_.sum())
    assert n <= cluster_figure._CURVE_POINTS  # every clustered local model is queried
    expected = k_distances(exact_embedding(theta * scale), step.min_pts_)
    assert not np.allclose(expected, k_distances(exact_embedding(theta), step.min_pts_))
    curve = _line(ax_k, "k-distance")
    assert np.allclose(curve.get_ydata(), expected)
    assert np.allclose(curve.get_xdata(), 100 * (np.arange(n) + 0.5) / n)
    assert ax_k.get_xlabel() == "% of the clustered local models, sorted"
    assert ax_k.get_title(loc="left") == f"k-distance curve (MinPts = {step.min_pts_})"
    monkeypatch.setattr(cluster_figure, "_CURVE_POINTS", 400)  # more than it queries: a subset
    sub = ParameterClustersDisplay.from_steps(model.steps_["local_models"], step,
                                              fit.reg.target).figure_.axes[1]
    assert np.allclose(_line(sub, "k-distance").get_ydata(), k_distances(
        exact_embedding(theta * scale), step.min_pts_, max_query=400))
    assert sub.get_title(loc="left") == (f"k-distance curve (MinPts = {step.min_pts_}; 400 of "
                                         f"{n} queried)")
    eps = _line(ax_k, f"ε = {step.eps_:.4g} (chosen from the data)")
    assert np.allclose(eps.get_ydata(), step.eps_)
    given = copy.copy(step)
    given.eps_auto_ = False
    fig = ParameterClustersDisplay.from_steps(model.steps_["local_models"], given, fit.reg.target).figure_
    _line(fig.axes[1], f"ε = {step.eps_:.4g} (given)")


def test_switching_agreement_matches_a_direct_count(fit):
    model, test = fit.model, fit.test
    region = model.regions_.predict(lagged_matrix(test.u, test.y, 1, 1, False))
    mode_of = match_submodels(model.thetas_, test.thetas)[0]
    agreement = 100 * np.mean(mode_of[region] == test.modes[1:])
    assert 80 < agreement < 100
    assert abs(100 * np.mean(region == test.modes[1:]) - agreement) > 1  # pairing matters
    for modes in (test.modes, test.modes[1:]):  # per sample or per regressor row
        fig = SwitchingDisplay.from_estimator(model, test.u, test.y, true_modes=modes,
                                              true_thetas=test.thetas).figure_
        assert len(fig.axes) == 2
        # the agreement is over every row of the experiment, of which the first 605 are drawn
        assert fig.get_suptitle() == (
            f"Estimated region vs true mode, held-out experiment 1: agreement "
            f"{agreement:.1f} % over all {region.size} samples, the first 605 shown")
    shown = fig.axes[1].collections[0].get_offsets()
    assert shown[:, 0].min() == 1 and shown[:, 0].max() == 605
    # Each region sits at the level of the mode it is paired with.
    assert np.array_equal(shown[:, 1], mode_of[region[:605]])
    (wrong,) = [ln for ln in fig.axes[1].get_lines() if ln.get_label().startswith("disagrees")]
    assert len(wrong.get_xdata()) == np.sum(mode_of[region[:605]] != test.modes[1:606])


def test_switching_without_truth_and_bad_truth(fit):
    model, test = fit.model, fit.test
    fig = SwitchingDisplay.from_estimator(model, test.u, test.y).figure_
    assert len(fig.axes) == 1
    region = model.regions_.predict(lagged_matrix(test.u, test.y, 1, 1, False))
    assert np.array_equal(fig.axes[0].collections[0].get_offsets()[:, 1], region[:605])
    # 27 regions (the robot's paper setting), 3 of them visited: one level for each of those
    regions = SimpleNamespace(n_regions_=27, predict=lambda phi: np.array([3, 20, 26])[
        np.arange(len(phi)) % 3])
    many = SimpleNamespace(output_lags_=1, nb=1, affine=False, structures_=["x", "x"],
                           groups_=[SimpleNamespace(outputs=(0, 1), regions=regions,
                                                    n_regions=27)])
    ax = SwitchingDisplay.from_estimator(many, test.u, test.y).figure_.axes[0]
    assert np.array_equal(ax.collections[0].get_offsets()[:, 1], np.arange(605) % 3)
    assert [t.get_text() for t in ax.get_yticklabels()] == ["H4", "H21", "H27"]
    assert ax.get_ylabel() == "estimated region\n(3 of 27 visited)"
    with pytest.raises(ValueError, match="true_thetas"):
        SwitchingDisplay.compute(model, test.u, test.y, true_modes=test.modes)
    with pytest.raises(ValueError, match="true_modes has 10 entries"):
        SwitchingDisplay.compute(model, test.u, test.y, true_modes=test.modes[:10],
                                 true_thetas=test.thetas)


def test_regions_slice_covers_every_region(fit):
    model = fit.model
    fig = RegionsDisplay.from_estimator(model, fit.reg.phi, fit.names).figure_
    assert len(fig.axes) == 1
    ax = fig.axes[0]
    # The modes of the system switch on y(k−1): those are the two regressors chosen.
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("y1(k-1)", "y2(k-1)")
    (cs,) = [c for c in ax.collections if isinstance(c, ContourSet)]
    levels = np.asarray(cs.levels)
    s = model.regions_.n_regions_
    assert s == model.n_submodels_ == 4
    for r in range(s):
        assert np.sum((levels[:-1] < r) & (r < levels[1:])) == 1
    assert levels.size == s + 1
    # Every region shows up in the slice (the 2-D cut through the quadrants meets all four).
    assert all(len(p.vertices) > 0 for p in cs.get_paths())
    points = [c for c in ax.collections if not isinstance(c, ContourSet)]
    assert sum(c.get_offsets().shape[0] for c in points) == fit.reg.phi.shape[0]
    with pytest.raises(ValueError, match="names"):
        RegionsDisplay.from_estimator(model, fit.reg.phi, fit.names[:3]).figure_


def _argmax_regions(n_regions: int, rng: np.random.Generator) -> SimpleNamespace:
    """A fitted model as the regions figure reads it: ``n_regions`` regions of φ in R⁴,
    each where its random linear score is the largest."""
    coef = rng.normal(size=(n_regions, 4))
    regions = SimpleNamespace(n_regions_=n_regions,
                              predict=lambda x: np.argmax(x @ coef.T, axis=1),
                              halfspaces=lambda: argmax_halfspaces(coef, np.zeros(n_regions)))
    return SimpleNamespace(regions_=regions, groups_=[SimpleNamespace(regions=regions)])


def test_regions_figure_keeps_a_long_legend_inside_the_figure():
    """27 regions and their rows (as the paper's setting gives on the robot): 55 legend
    entries, drawn in columns inside the figure, and no layout warning."""
    rng = np.random.default_rng(0)
    model = _argmax_regions(27, rng)
    phi = rng.normal(size=(2000, 4))
    fig = RegionsDisplay.from_estimator(model, phi, ["a", "b", "c", "d"], labels=np.r_[-1, rng.integers(0, 27,
                                                                                                        1999)]).figure_
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "constrained_layout not applied" before the columns
        to_png(fig)  # drawn as the asset page shows it
    legend = fig.axes[0].get_legend()
    assert len(legend.legend_handles) == 27 + 28
    page = fig.bbox
    for text in legend.get_texts():
        box = text.get_window_extent()
        assert page.x0 <= box.x0 and box.x1 <= page.x1 and page.y0 <= box.y0 and \
            box.y1 <= page.y1, text.get_text()


def test_regions_figure_of_192_regions_lists_those_in_its_slice_inside_the_figure():
    """192 regions (a structure search's model of five output groups: the product of their
    regions) with rows of each: the legend lists the regions the slice shows and the rows in
    one entry, drawn inside the figure, its title saying how many of the 192 the slice
    crosses."""
    rng = np.random.default_rng(1)
    model = _argmax_regions(192, rng)
    phi = rng.normal(size=(3000, 4))
    display = RegionsDisplay.from_estimator(model, phi, ["a", "b", "c", "d"],
                                            labels=rng.integers(0, 192, 3000))
    fig = display.figure_
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        to_png(fig)
    legend = fig.axes[0].get_legend()
    in_slice = np.unique(display.z)
    texts = [t.get_text() for t in legend.get_texts()]
    assert texts == [f"H{r + 1}" for r in in_slice[:65]] + [
        "training rows, coloured by\nsub-model (colours repeat)"]
    assert legend.get_title().get_text() == f"{in_slice.size} of 192 regions\nin this slice"
    page = fig.bbox
    for text in [*legend.get_texts(), legend.get_title()]:
        box = text.get_window_extent()
        assert page.x0 <= box.x0 and box.x1 <= page.x1 and page.y0 <= box.y0 and \
            box.y1 <= page.y1, text.get_text()


def _twenty_seven_clusters():
    """Fitted local-model and clustering steps as the figure reads them: 27 clusters (the
    paper's setting on the robot) of 22–48 local models each, and 60 noise ones."""
    rng = np.random.default_rng(1)
    labels = np.r_[np.full(60, -1), np.repeat(np.arange(27), np.arange(27)[::-1] + 22)]
    theta = rng.normal(size=(labels.size, 3, 2))
    local = SimpleNamespace(theta_=theta, phi_scale_=np.ones(3))
    step = SimpleNamespace(unit_free=False, embedding="exact", labels_=labels, min_pts_=6,
                           clustered_=np.ones(labels.size, bool), eps_=1.0, eps_auto_=False)
    return local, step, labels


def test_parameter_clusters_legend_lists_the_clusters_with_their_own_colour():
    """27 clusters (the paper's setting on the robot): the 8 with a colour of their own and
    noise are listed, the rest is one line with their sizes."""
    local, step, labels = _twenty_seven_clusters()
    fig = ParameterClustersDisplay.from_steps(local, step, np.ones((labels.size, 2))).figure_
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        to_png(fig)
    texts = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert texts == ["noise (60)"] + [f"cluster {c + 1} ({48 - c})" for c in range(8)] + [
        "clusters 9–27 (22–40 each; colours repeat)"]
    assert sum(c.get_label().startswith("cluster") for c in fig.axes[0].collections) == 27


def _clusters_layout_faults(fig) -> list[str]:
    """What the parameter-clusters figure's hand layout got wrong: texts outside the figure
    or over the other panel, the legend over the x label or its tick labels."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    ax, ax_k = fig.axes
    whole = fig.bbox

    def drawn(axis):  # tick labels of the ticks within the view (the others are not drawn)
        low, high = sorted(axis.get_view_interval())
        return [t for minor in (False, True) for t, v in zip(
                    axis.get_ticklabels(minor=minor), axis.get_ticklocs(minor=minor),
                    strict=True) if low <= v <= high and t.get_text()]

    ticks = {id(t) for a in (ax, ax_k) for axis in (a.xaxis, a.yaxis)
             for t in [*axis.get_ticklabels(), *axis.get_ticklabels(minor=True)]}
    texts = [t for t in fig.findobj(lambda a: hasattr(a, "get_text") and a.get_visible())
             if id(t) not in ticks and t.get_text()]
    texts += [t for a in (ax, ax_k) for axis in (a.xaxis, a.yaxis) for t in drawn(axis)]
    faults = []
    for text in texts:
        box = text.get_window_extent(renderer)
        if not (whole.x0 - 1 <= box.x0 and box.x1 <= whole.x1 + 1 and whole.y0 - 1 <= box.y0
                and box.y1 <= whole.y1 + 1):
            faults.append(f"outside the figure: {text.get_text()!r}")
    for own, other in ((ax, ax_k), (ax_k, ax)):
        for label in (own.yaxis.label, *drawn(own.yaxis)):
            if label.get_window_extent(renderer).overlaps(
                    other.get_window_extent(renderer)):
                faults.append(f"over the other panel: {label.get_text()!r}")
    legend = ax.get_legend().get_window_extent(renderer)
    for text in (ax.xaxis.label, *drawn(ax.xaxis)):
        if legend.y1 > text.get_window_extent(renderer).y0:
            faults.append(f"legend over {text.get_text()!r}")
    return faults


def test_parameter_clusters_layout_keeps_every_text_inside_and_apart(fit):
    """The figure is laid out by hand (no constrained layout): with one legend row and with
    the longest legend (27 clusters), and with long tick labels on the log axis, nothing
    leaves the figure or covers the other panel, and the legend stays below the x label."""
    local, step, labels = _twenty_seven_clusters()
    many = ParameterClustersDisplay.from_steps(local, step, np.ones((labels.size, 2))).figure_
    one = ParameterClustersDisplay.from_steps(fit.model.steps_["local_models"],
                                              fit.model.steps_["clustering"], fit.reg.target).figure_
    assert many.get_layout_engine() is None and many.get_figheight() > one.get_figheight()
    for fig in (many, one):
        assert _clusters_layout_faults(fig) == []
    squeezed = ParameterClustersDisplay.from_steps(local, step, np.ones((labels.size, 2))).figure_
    squeezed.axes[0].set_position([0.05, 0.05, 0.9, 0.9])  # a layout that is wrong
    assert len(_clusters_layout_faults(squeezed)) > 3


def _png(markdown):
    assert markdown.startswith("![") and "](data:image/png;base64," in markdown
    assert markdown.endswith(")")
    return base64.b64decode(markdown.split("base64,", 1)[1][:-1], validate=True)


def test_to_markdown_inlines_a_small_png(fit):
    figs = [PredictionDisplay.from_evaluation(fit.ev, fit.data, WARMUP, context="pred [pwa]").figure_,
            PredictionDisplay.from_evaluation(_diverged(fit), fit.data, WARMUP, context="diverged").figure_,
            ParameterClustersDisplay.from_steps(fit.model.steps_["local_models"],
                                                fit.model.steps_["clustering"], fit.reg.target).figure_,
            SwitchingDisplay.from_estimator(fit.model, fit.test.u, fit.test.y, true_modes=fit.test.modes,
                                            true_thetas=fit.test.thetas).figure_,
            RegionsDisplay.from_estimator(fit.model, fit.reg.phi, fit.names).figure_]
    for fig in figs:
        png = _png(to_markdown(fig))
        assert png.startswith(b"\x89PNG\r\n\x1a\n")
        assert len(png) < 300_000
        width = struct.unpack(">I", png[16:20])[0]  # IHDR: width in pixels
        assert width == round(90 * fig.get_figwidth())
    assert to_markdown(figs[0]).startswith("![pred (pwa) Measured output, one-step")
    narrow = _png(to_markdown(figs[0], width=450))
    assert struct.unpack(">I", narrow[16:20])[0] == 450
    small = _png(to_markdown(figs[0], max_bytes=40_000))
    assert len(small) <= 40_000


def test_parameter_clusters_are_projected_on_their_principal_components(fit):

    step = fit.model.steps_["clustering"]
    fig = ParameterClustersDisplay.from_steps(fit.model.steps_["local_models"], step, fit.reg.target).figure_
    emb = cluster_figure._embedding(fit.model.steps_["local_models"], step, fit.reg.target)
    centred = emb - emb.mean(axis=0)
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    drawn = {c.get_label(): c.get_offsets() for c in fig.axes[0].collections}
    labels = step.labels_[step.clustered_]
    for c in np.unique(labels):
        name = next(k for k in drawn if k.startswith("noise" if c < 0 else f"cluster {c + 1} "))
        # each axis is the SVD's up to its sign
        ref = centred[labels == c] @ vt[:2].T
        np.testing.assert_allclose(np.abs(drawn[name]), np.abs(ref), rtol=1e-6, atol=1e-9)
    assert fig.axes[0].get_xlabel() == f"PC 1 ({100 * sv[0]**2 / np.sum(sv**2):.0f} % of variance)"


# --- What a control engineer reads at a glance: titles, units, the measured line, the size

CONTEXT = context_title("hure_vasak", "my_set", "PWA")


@pytest.fixture(scope="module")
def structured(fit):
    """A structured PWARX (velocity form, one model per output, offset switching on the sign
    of each output's increment) on the fit's training record."""
    from pwa_pipeline.pwa.scheduling import SignScheduling

    train_u, train_y = fit.data.u_train[0], fit.data.y_train[0]
    return PWARX(na=1, nb=1, affine=True, form="velocity", outputs="decoupled",
                 scheduling=SignScheduling(switch="offset")).fit(train_u, train_y)


@pytest.fixture(scope="module")
def robot_like():
    """The robot's channels and units: six outputs q1…q6 in degrees (the simulated system's
    two outputs and their scaled, noisy copies) and torques tau1, tau2 in N·m, scored as a
    linear ARX model, and a structured model of them."""
    from pwa_pipeline import LinearARX
    from pwa_pipeline.pwa.scheduling import SignScheduling

    rng = np.random.default_rng(3)
    record = make_hure_vasak(n_samples=900, n_test=900, snr_db=30, seed=0)
    us = [record.u_train[0], record.u_test[0]]
    ys = [np.hstack([y, 3 * y + rng.normal(0, 0.1, y.shape), -2 * y + rng.normal(0, 0.1, y.shape)])
          for y in (record.y_train[0], record.y_test[0])]
    units = {**{f"q{i}": "deg" for i in range(1, 7)}, "tau1": "N·m", "tau2": "N·m"}
    data = Dataset("robot_like", [us[0]], [ys[0]], [us[1]], [ys[1]],
                   ["tau1", "tau2"], [f"q{i}" for i in range(1, 7)], units=units)
    model = LinearARX(na=1, nb=1).fit(us[0], ys[0])
    ev = evaluate(model, us[1], ys[1], warmup=WARMUP, output_names=data.y_names)
    moving = PWARX(na=1, nb=1, affine=True, form="velocity", outputs="decoupled",
                   scheduling=SignScheduling(switch="all")).fit(us[0], ys[0])
    return SimpleNamespace(data=data, ev=ev, structured=moving)


def _reading_order(fig) -> list:
    """The figure's axes down each column, then the next (as the outputs are laid out)."""
    return sorted(fig.axes, key=lambda ax: (round(ax.get_position().x0, 3),
                                            -ax.get_position().y0))


def _pixels(fig) -> tuple[int, int]:
    """Width and height of the figure's PNG as the pipeline renders it (:func:`to_png`)."""
    png = to_png(fig)
    return struct.unpack(">II", png[16:24])


def test_every_figure_is_titled_with_its_data_set_set_and_method(fit, structured):
    """The first line of every figure's title names the data set, the hyper-parameter set
    and the method; the second says what is drawn."""
    assert CONTEXT == "hure_vasak | set my_set | PWA"
    test = fit.test
    outputs = SwitchingDisplay.compute(structured, test.u, test.y, y_names=fit.data.y_names,
                                       u_names=fit.data.u_names)
    figs = {
        "prediction": PredictionDisplay.from_evaluation(fit.ev, fit.data, WARMUP, context=CONTEXT).figure_,
        "switching": SwitchingDisplay.from_estimator(fit.model, test.u, test.y, true_modes=test.modes,
                                                     true_thetas=test.thetas, context=CONTEXT).figure_,
        "switching without truth": SwitchingDisplay.from_estimator(fit.model, test.u, test.y,
                                                                   context=CONTEXT).figure_,
        "structured switching": outputs.plot(CONTEXT).figure_,
        "regions": RegionsDisplay.from_estimator(fit.model, fit.reg.phi, fit.names, context=CONTEXT).figure_,
        "parameter clusters": ParameterClustersDisplay.from_steps(
            fit.model.steps_["local_models"], fit.model.steps_["clustering"], fit.reg.target,
            context=CONTEXT).figure_,
    }
    for name, fig in figs.items():
        lines = fig.get_suptitle().splitlines()
        # (the prediction figure's third line, when there is one, is its share outside the
        # data envelope)
        assert len(lines) == 2 + (name == "prediction" and bool(_outside_line(fit.ev))), name
        assert lines[0] == CONTEXT, name
        assert "hure_vasak" not in lines[1] and "my_set" not in lines[1], name
        assert to_markdown(fig).startswith(f"![{CONTEXT} {' '.join(lines[1:])}]("), name
    # the parameter-clusters figure is laid out by hand: its two-line title still fits
    assert _clusters_layout_faults(figs["parameter clusters"]) == []


def test_the_prediction_axes_carry_units_and_fit_a_laptop_screen(robot_like):
    """Six outputs (the robot's) in a 3 × 2 grid, each y axis ``q<i> [deg]``, at most
    900 × 650 px as rendered (the figure was 900 × 1134 px stacked)."""
    fig = PredictionDisplay.from_evaluation(robot_like.ev, robot_like.data, WARMUP, context=CONTEXT).figure_
    width, height = _pixels(fig)
    assert width <= 900 and height <= 650, (width, height)
    assert 90 * fig.get_figheight() >= 550  # six panels still readable, not squashed
    boxes = [ax.get_position() for ax in fig.axes]
    assert len({round(b.x0, 3) for b in boxes}) == 2 and len({round(b.y0, 3) for b in boxes}) == 3
    # down the first column, then the second; the lowest of each shows the sample axis
    axes = _reading_order(fig)
    assert [ax.get_ylabel() for ax in axes] == [f"q{i} [deg]" for i in range(1, 7)]
    assert [ax.get_title(loc="left").split(":")[0] for ax in axes] == [
        f"q{i}" for i in range(1, 7)]
    assert [ax.get_xlabel() for ax in axes] == ["", "", "sample k", "", "", "sample k"]


@pytest.mark.parametrize("m", [1, 4, 5, 7])
def test_the_prediction_grid_keeps_every_output_and_the_sample_axis(fit, m):
    """Any number of outputs: one axes each, three rows at most, every column's lowest axes
    labelled, the figure within the laptop bound."""
    y_test = np.tile(fit.data.y_test[0], (1, 4))[:, :m]
    names = [f"y{i + 1}" for i in range(m)]
    data = Dataset("d", fit.data.u_train, [np.tile(fit.data.y_train[0], (1, 4))[:, :m]],
                   fit.data.u_test, [y_test], fit.data.u_names, names)
    table = fit.ev.table
    rows = [{**table.iloc[0].to_dict(), "mode": mode, "output": name}
            for mode in ("one_step", "free_run") for name in names + ["mean"]]
    import pandas as pd

    ev = Evaluation(pd.DataFrame(rows), {"one_step": [y_test + 0.1], "free_run": [y_test - 0.1]})
    fig = PredictionDisplay.from_evaluation(ev, data, WARMUP, context=CONTEXT).figure_
    assert [ax.get_ylabel() for ax in _reading_order(fig)] == names
    columns = -(-m // 3)  # 3 rows at most, filled evenly: 4 outputs in 2 × 2
    assert len({round(ax.get_position().x0, 3) for ax in fig.axes}) == columns
    assert len({round(ax.get_position().y0, 3) for ax in fig.axes}) == -(-m // columns)
    labelled = [ax for ax in fig.axes if ax.get_xlabel() == "sample k"]
    assert len(labelled) == columns
    width, height = _pixels(fig)
    assert width <= 900 and height <= 650


def test_the_measured_line_is_drawn_on_top_and_stays_visible(fit, robot_like):
    """Of every line of every output's axes (one-step, free run, clipped free run and its
    exit markers) the measured one has the highest z-order; it is opaque and black, and the
    one-step line under it is wider and translucent, so both show where they coincide."""
    for fig in (PredictionDisplay.from_evaluation(robot_like.ev, robot_like.data, WARMUP,
                                                  context=CONTEXT).figure_,
                PredictionDisplay.from_evaluation(_diverged(fit), fit.data, WARMUP, context=CONTEXT).figure_):
        for ax in fig.axes:
            measured = _line(ax, "measured")
            others = [ln for ln in ax.get_lines() if ln is not measured]
            assert len(others) >= 2
            assert measured.get_zorder() > max(ln.get_zorder() for ln in others)
            assert measured.get_visible() and measured.get_alpha() in (None, 1.0)
            assert measured.get_color() == "black"
            one = _line(ax, "one-step")
            assert one.get_linewidth() > 2 * measured.get_linewidth()
            assert one.get_alpha() < 1


def test_axes_of_regions_and_regressors_carry_units(fit):
    units = {"y1": "V", "y2": "V", "u1": "A"}
    ax = RegionsDisplay.from_estimator(fit.model, fit.reg.phi, fit.names, units=units).figure_.axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("y1(k-1) [V]", "y2(k-1) [V]")
    data = Dataset("d", [], [], [], [], ["u1", "u2"], ["y1", "y2"], units=units)
    assert [data.label(n) for n in ("y1", "u1(k-2)", "u2", "1")] == [
        "y1 [V]", "u1(k-2) [A]", "u2", "1"]


def test_the_robots_channels_carry_their_units(robot):
    from pwa_pipeline.datasets import load_dataset

    data = load_dataset("kuka_robot")
    assert [data.label(n) for n in data.y_names] == [f"q{i} [deg]" for i in range(1, 7)]
    assert [data.label(n) for n in data.u_names] == [f"tau{i} [N·m]" for i in range(1, 7)]


def test_units_are_not_part_of_the_digest(fit):
    """Caches keyed by the digest stay valid: a unit names the numbers, it changes none."""
    import dataclasses
    import pickle

    with_units = dataclasses.replace(fit.data, units={"y1": "V"})
    assert with_units.digest == fit.data.digest
    assert dataclasses.replace(fit.data, y_names=["a", "b"]).digest != fit.data.digest
    # a data set stored (pickled by the IO manager) before units existed loads with none
    old = dataclasses.replace(fit.data)
    del old.__dict__["units"]
    restored = pickle.loads(pickle.dumps(old))
    assert restored.units == {} and restored.label("y1") == "y1"
    assert restored.digest == fit.data.digest
    again = pickle.loads(pickle.dumps(with_units))
    assert again.units == {"y1": "V"} and again.label("y1(k-1)") == "y1(k-1) [V]"


def test_the_structured_switching_figure_shows_each_outputs_regions(fit, structured):
    test = fit.test
    outputs = SwitchingDisplay.compute(structured, test.u, test.y, y_names=["q1", "q2"], u_names=["tau1",
                                                                                                  "tau2"])
    fig = outputs.plot(CONTEXT).figure_
    assert len(fig.axes) == 2
    lags = structured.output_lags_
    phi = lagged_matrix(test.u, test.y, lags, 1, True)
    for j, ax in enumerate(fig.axes):
        region = structured.structure_fit_.outputs[j].regions(phi)
        assert region.min() == 0 and region.max() == 1  # both signs occur
        drawn = ax.collections[0].get_offsets()
        assert np.array_equal(drawn[:, 0], np.arange(lags, MAX_SAMPLES))
        assert np.array_equal(drawn[:, 1], region[:MAX_SAMPLES - lags])
        assert [t.get_text() for t in ax.get_yticklabels()] == ["z ≤ 0", "z > 0"]
        assert ax.get_title(loc="left") == (
            f"q{j + 1}: {structured.structures_[j]}, regions by the sign of "
            f"z = q{j + 1}(k-1) − q{j + 1}(k-2)")
    assert fig.get_suptitle().splitlines()[1] == (
        f"Region of each output group's model, held-out experiment 1, the first "
        f"{MAX_SAMPLES - lags} of {phi.shape[0]} samples shown")


def test_a_long_oblique_boundary_wraps_inside_the_figure(fit):
    """Two oblique boundaries of every regressor (as the structure search writes them):
    each panel's title wraps onto lines drawn inside the figure's width, and says all of
    what it said on one line; a combination's leading coefficient keeps its minus sign."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    from pwa_pipeline.pwa.scheduling import SignScheduling

    names = ["y1(k-1)", "y2(k-1)", "u1(k-1)", "u2(k-1)"]
    variables = [{**dict(zip(names, [0.9891, -0.2043, 0.2714, -0.1382], strict=True)), "1": -0.3471},
                 {**dict(zip(names, [-0.4125, 0.8832, -0.0519, 0.3364], strict=True)), "1": 0.1287}]
    model = PWARX(na=1, nb=1, affine=True, outputs="decoupled",
                  scheduling=SignScheduling(variables=variables, switch="all")).fit(
        fit.data.u_train[0], fit.data.y_train[0])
    display = SwitchingDisplay.compute(model, fit.test.u, fit.test.y)
    assert "z2 = −0.412·y1(k-1) + 0.883·y2(k-1)" in display.lanes[0].variables  # a leading minus
    assert "− 0.138·u2(k-1) − 0.3471, z2" in display.lanes[0].variables  # the constant alone
    fig = display.plot(CONTEXT).figure_
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    texts = {t.get_text(): t for t in fig.findobj(Text)}
    for ax, lane in zip(fig.axes, display.lanes, strict=True):
        title = ax.get_title(loc="left")
        assert "\n" in title
        assert title.replace("\n", " ") == (
            f"{lane.outputs}: {lane.structure}, regions by the sign of {lane.variables}")
        box = texts[title].get_window_extent(renderer)
        assert fig.bbox.x0 <= box.x0 and box.x1 <= fig.bbox.x1, title


def test_a_searched_structure_leaves_its_boundary_list_to_the_signs():
    """A search's structure lists its boundaries in the model's names (``[ŷ1: y1(k-1) …]``);
    the panel's title writes them once, as the signs in the data's names, and a structure
    with no signs written keeps its own text."""
    from pwa_pipeline.plotting.switching import Lane

    k = np.arange(2, 50)
    structure = ("level (1, 2), all on [ŷ1: y1(k-1) + 0.274·u1(k-2) - 0.207·u1(k-1) > "
                 "8.566, u1(k-1) > 3.72] (4 regions)")
    lanes = [Lane(k % 4, 4, "level", structure,
                  "z1 = 0.989·level(k-1) − 0.204·pump(k-1) − 8.47, z2 = pump(k-1) − 3.72"),
             Lane(np.zeros(k.size, int), 1, "flow", "level (1, 2), linear")]
    fig = SwitchingDisplay(k, lanes).plot(CONTEXT).figure_
    assert [ax.get_title(loc="left").replace("\n", " ") for ax in fig.axes] == [
        "level: level (1, 2), all (4 regions), regions by the sign of z1 = 0.989·level(k-1) "
        "− 0.204·pump(k-1) − 8.47, z2 = pump(k-1) − 3.72", "flow: level (1, 2), linear"]


def test_every_figure_fits_a_laptop_screen(fit, robot_like):
    """At 90 dpi no figure is wider than 900 px or higher than 650 px: six outputs of a
    structured model, the regions figure with its longest legend, the clusters figure."""
    data = robot_like.data
    outputs = SwitchingDisplay.compute(robot_like.structured, data.u_test[0], data.y_test[0],
                                       y_names=data.y_names, u_names=data.u_names)
    assert len(outputs.regions) == 6
    rng = np.random.default_rng(0)
    many = _argmax_regions(27, rng)
    local, step, labels = _twenty_seven_clusters()
    figs = [outputs.plot(CONTEXT).figure_,
            RegionsDisplay.from_estimator(many, rng.normal(size=(2000, 4)), ["a", "b", "c", "d"],
                                          labels=np.r_[-1, rng.integers(0, 27,
                                                                        1999)], context=CONTEXT).figure_,
            ParameterClustersDisplay.from_steps(local, step, np.ones((labels.size, 2)),
                                                context=CONTEXT).figure_,
            SwitchingDisplay.from_estimator(fit.model, fit.test.u, fit.test.y, true_modes=fit.test.modes,
                                            true_thetas=fit.test.thetas, context=CONTEXT).figure_]
    for fig in figs:
        width, height = _pixels(fig)
        assert width <= 900 and height <= 650, (fig.get_suptitle(), width, height)


def test_a_model_without_switching_says_so_in_place_of_empty_lanes(fit):
    """A linear model (one region per output group, as a structure search that kept the
    linear model): no lanes over a 0–1 axis, but a title that says there is no switching
    and each group's structure."""
    from pwa_pipeline import LinearARX
    from pwa_pipeline.plotting.switching import NO_SWITCHING

    data, test = fit.data, fit.test
    for outputs in ("joint", "decoupled"):
        model = LinearARX(na=1, nb=1, outputs=outputs).fit(data.u_train, data.y_train)
        display = SwitchingDisplay.compute(model, test.u, test.y, y_names=data.y_names)
        assert not display.switches
        fig = display.plot("hure_vasak | set auto | PWA").figure_
        assert fig.axes == []
        assert fig.get_suptitle() == (f"hure_vasak | set auto | PWA\n{NO_SWITCHING}, held-out "
                                      f"experiment 1 ({test.y.shape[0] - 1} samples)")
        (text,) = [t for t in fig.texts if t.get_text() != fig.get_suptitle()]
        assert text.get_text().splitlines() == [
            f"{lane.outputs}: {lane.structure}" for lane in display.lanes]
        assert "linear" in text.get_text()
    assert SwitchingDisplay.compute(fit.model, test.u, test.y).switches
