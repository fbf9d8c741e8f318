"""Diagnostic figures of a fitted PWARX model and its scores, for Dagster metadata and MLflow.

Every function returns a :class:`matplotlib.figure.Figure` drawn without pyplot (no global
state, no display); :func:`to_markdown` turns one into Markdown for
``dagster.MetadataValue.md``. Colours are shared: sub-model / region i is ``_colour(i)`` in
every figure, DBSCAN noise is grey.
"""

from __future__ import annotations

import base64
import functools
import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._arrays import column_rms
from ..pwa.clustering import k_distances
from ..pwa.embedding import EMBEDDINGS
from ..pwa.regressors import lagged_matrix, n_initial
from ..scoring.metrics import match_submodels
from .caches import source_fingerprint

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from ..datasets import Dataset
    from ..pwa import PWARX
    from ..scoring.evaluation import Evaluation

#: Samples shown of one experiment (one KUKA robot experiment).
MAX_SAMPLES = 606
#: tab10 without its grey (grey is DBSCAN noise) and its red (red flags a diverged run).
_PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#bcbd22",
            "#17becf")
_NOISE = "#9a9a9a"
_DIVERGED = "#d62728"
_LEGEND_ROWS = 22
"""Entries of a legend column of the regions figure (more fit beside its 5.2-inch axes)."""
_MAX_LEVELS = 10
"""Regions the switching figure labels on its 2-inch axis without overlap."""
_AXES_HEIGHT = 2.45
"""Inches of the parameter-clusters figure's axes (its height grows with its legend)."""
_TICKS_AND_LABEL = 0.5
"""Inches below those axes for their tick labels and x label, above the legend."""
_LEGEND_COLUMNS = 3
_CURVE_POINTS = 1000
"""Points queried for the parameter-clusters figure's k-distance curve: its shape, at a
fifth of the cost of the 5,000 that choose ε (:func:`~pwa_pipeline.pwa.clustering.k_distances`)."""


@functools.cache
def figures_fingerprint() -> str:
    """Hash of this module's source: part of the key of cached figures, so that figures drawn
    by other code are never shown."""
    return source_fingerprint([Path(__file__)])


def _colour(i: int) -> str:
    """Colour of sub-model / region / cluster ``i`` (0-based); grey for −1 (noise)."""
    return _NOISE if i < 0 else _PALETTE[i % len(_PALETTE)]


def _figure(width: float, height: float, layout: str | None = "constrained") -> Figure:
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), layout=layout)


def _legend_right(fig: Figure) -> None:
    """One legend for every axes of ``fig`` (each label once, in the order first drawn),
    outside them on the upper right, so that it never covers data."""
    entries: dict[str, object] = {}
    for ax in fig.axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    fig.legend(list(entries.values()), list(entries), loc="outside right upper", fontsize=8,
               frameon=False)


def clip_range(measured: np.ndarray) -> tuple[float, float]:
    """The measured range widened by 50 % of its span on each side (where runs are clipped)."""
    lo, hi = float(np.min(measured)), float(np.max(measured))
    span = hi - lo if hi > lo else max(abs(hi), 1.0)
    return lo - 0.5 * span, hi + 0.5 * span


def _free_run(ax: Axes, k: np.ndarray, free: np.ndarray, measured: np.ndarray,
              diverged: bool) -> None:
    """Draw a free run clipped to :func:`clip_range`: the line reaches the edge where the run
    leaves the range and comes back where it returns, never runs along the edge; samples out
    of range (NaN counts as above) are shaded and each exit is marked by a triangle."""
    lo, hi = clip_range(measured)
    v = np.where(np.isnan(free), np.inf, free)
    above, below = v > hi, v < lo
    out = above | below
    if not out.any() and not diverged:
        ax.plot(k, free, color="C1", lw=0.9, label="free run")
        return
    inside = ~out
    near = inside | np.r_[False, inside[:-1]] | np.r_[inside[1:], False]
    line = np.where(near, np.clip(v, lo, hi), np.nan)
    colour = _DIVERGED if diverged else "C1"
    ax.plot(k, line, color=colour, lw=0.9,
            label="free run (diverged, clipped)" if diverged else "free run (clipped)")
    if out.any():
        ax.fill_between(k, 0, 1, where=out, transform=ax.get_xaxis_transform(), step="mid",
                        color=colour, alpha=0.10, lw=0,
                        label=f"{'diverged ' if diverged else ''}free run out of range")
        exits = out & ~np.r_[False, out[:-1]]
        for side, edge, marker in ((above, hi, "^"), (below, lo, "v")):
            at = exits & side
            if at.any():  # (an empty unclipped line would stretch the layout to the origin)
                ax.plot(k[at], np.full(at.sum(), edge), marker, color=colour, ms=6,
                        ls="none", clip_on=False)
    pad = 0.03 * (hi - lo)
    ax.set_ylim(lo - pad, hi + pad)


def prediction_figure(data: Dataset, evaluation: Evaluation, title: str,
                      warmup: int) -> Figure:
    """Measured output, one-step prediction and free run of the first held-out experiment.

    One subplot per output, over the experiment's first 606 samples at most (one KUKA robot
    experiment), each titled with that output's one-step and free-run NRMSE (eq. 21) from
    ``evaluation.table`` (4 significant digits). A free run flagged ``diverged`` in the table,
    or with non-finite values, is drawn in red as "free run (diverged, clipped)": clipped to
    the measured range ± 50 % of its span, the line stops at the edge where the run leaves
    that range (a triangle marks each exit, the time outside is shaded) instead of lying flat
    on the clip value. The warm-up window, excluded from the scores, is shaded grey. One
    legend on the right lists what any subplot draws.

    Parameters
    ----------
    data : Dataset
        Its ``y_test[0]`` and ``y_names``.
    evaluation : Evaluation
        From :func:`pwa_pipeline.scoring.evaluation.evaluate` on ``data``'s held-out
        experiments; its ``table`` (rows per output in order, then ``mean``) and
        ``predictions``.
    title : str
    warmup : int
        Warm-up samples of the evaluation.

    Returns
    -------
    Figure
        One axes per output.
    """
    n = min(data.y_test[0].shape[0], MAX_SAMPLES)
    y = data.y_test[0][:n]
    m = y.shape[1]
    table = evaluation.table[evaluation.table["output"] != "mean"]
    rows = {mode: table[table["mode"] == mode] for mode in ("one_step", "free_run")}
    fig = _figure(10, 2.0 * m + 0.6)
    axes = fig.subplots(m, 1, sharex=True, squeeze=False)[:, 0]
    k = np.arange(n)
    for j, ax in enumerate(axes):
        one, free_row = rows["one_step"].iloc[j], rows["free_run"].iloc[j]
        free = evaluation.predictions["free_run"][0][:n, j]
        diverged = bool(free_row["diverged"]) or not np.isfinite(free).all()
        ax.axvspan(0, warmup, color="0.85", alpha=0.6, lw=0, label="warm-up")
        ax.plot(k, y[:, j], color="black", lw=1.2, label="measured")
        ax.plot(k, evaluation.predictions["one_step"][0][:n, j], color="C0", lw=0.9,
                label="one-step")
        _free_run(ax, k, free, y[:, j], diverged)
        ax.set_title(f"{data.y_names[j]}: one-step NRMSE {one['nrmse']:.4g}, free run NRMSE "
                     f"{free_row['nrmse']:.4g}" + (" (diverged)" if diverged else ""),
                     fontsize=9, loc="left")
        ax.set_ylabel(data.y_names[j])
        ax.set_xlim(0, n - 1)
    _legend_right(fig)
    axes[-1].set_xlabel("sample k of the first held-out experiment")
    fig.suptitle(title)
    return fig


def _clustering_embedding(local, step, target: np.ndarray) -> np.ndarray:
    """The clustered θ_k embedded as the clustering step embedded them (eq. 8–10), unit-free
    (θ_k·rms(φ)/rms(y)) when the step was."""
    theta = local.theta_[step.clustered_]
    if step.unit_free:
        theta = theta * local.phi_scale_[None, :, None] / column_rms(np.asarray(target))
    return EMBEDDINGS[step.embedding](theta)


def parameter_clusters_figure(local, clustering, target: np.ndarray,
                              title: str | None = None) -> Figure:
    """The local parameter matrices θ_k as DBSCAN clustered them (step 4), and its ε.

    Left: the clustered θ_k (unit-free when the step was, embedded as in eq. 8–10, so that
    distances are those DBSCAN used) projected on their first two principal components,
    coloured by cluster, noise grey; local models left out of the clustering (mixed local
    sets, the subset cap, degenerate ones) are not drawn. Right: the k-distance curve
    (distance of each point to its MinPts-th neighbour, sorted, against the share of points;
    at most ``_CURVE_POINTS`` of them queried, a seeded subset) with ε as a horizontal line;
    its label says whether ε was chosen from the data or given.

    Parameters
    ----------
    local, clustering : the fitted local-model and clustering steps
        (``PWARX.local_models_`` and ``clustering_``, or the ``local_models`` and
        ``clusters`` assets).
    target : ndarray of shape (n, m)
        The training targets y(k) the clustering step was fitted with
        (``Regressors.target``); their RMS makes θ_k unit-free.
    title : str, optional

    Returns
    -------
    Figure
        Two axes: the projection and the k-distance curve.
    """
    step = clustering
    emb = _clustering_embedding(local, step, target)
    labels = step.labels_[step.clustered_]
    centred = emb - emb.mean(axis=0)
    # principal axes from the d·m × d·m scatter matrix: an SVD of the rows would also form
    # their n × d·m left factor (6.5 s on the robot's 24,732 clustered local models)
    var, axes = np.linalg.eigh(centred.T @ centred)
    var, axes = np.maximum(var[::-1], 0), axes[:, ::-1]
    pcs = np.zeros((emb.shape[0], 2))
    pcs[:, :min(2, axes.shape[1])] = centred @ axes[:, :2]
    share = 100 * var / max(float(np.sum(var)), np.finfo(float).tiny)
    # laid out by hand (below, once the legend's rows are known): the constrained layout
    # measures every text first, and took 1.7× as long to render this figure, which is
    # drawn for every set of a sweep (benchmarks/figure_layout.py)
    fig = _figure(10, 4.0, layout=None)
    ax, ax_k = fig.subplots(1, 2, width_ratios=(1.25, 1))
    listed = []
    for c in np.unique(labels):  # (labels run by decreasing size: small clusters on top)
        rows = labels == c
        dots = ax.scatter(pcs[rows, 0], pcs[rows, 1], s=5 if c < 0 else 7, color=_colour(c),
                          alpha=0.5 if c < 0 else 0.8, lw=0, zorder=1 if c < 0 else 2 + c / 100,
                          label=f"noise ({rows.sum()})" if c < 0 else
                          f"cluster {c + 1} ({rows.sum()})")
        if c < len(_PALETTE):  # beyond, colours repeat: the rest is one legend line
            listed.append(dots)
    if labels.max() >= len(_PALETTE):
        from matplotlib.lines import Line2D

        sizes = np.bincount(labels[labels >= len(_PALETTE)])[len(_PALETTE):]
        listed.append(Line2D([], [], ls="none", label=(
            f"clusters {len(_PALETTE) + 1}–{labels.max() + 1} ({sizes.min()}–{sizes.max()} "
            f"each; colours repeat)")))
    ax.set_xlabel(f"PC 1 ({share[0]:.0f} % of variance)")
    ax.set_ylabel(f"PC 2 ({share[1] if share.size > 1 else 0:.0f} % of variance)")
    scale = "unit-free θ_k·rms(φ)/rms(y)" if getattr(step, "unit_free", False) else "θ_k"
    ax.set_title(f"{labels.size} of {step.labels_.size} local models clustered ({scale})",
                 fontsize=9, loc="left")
    ax.legend(handles=listed, fontsize=8, markerscale=2, loc="upper center",
              bbox_to_anchor=(0.5, -_TICKS_AND_LABEL / _AXES_HEIGHT),
              ncols=min(_LEGEND_COLUMNS, len(listed)), frameon=False)
    dist = k_distances(emb, step.min_pts_, max_query=_CURVE_POINTS)
    ax_k.plot(100 * (np.arange(dist.size) + 0.5) / dist.size, dist, color="black", lw=1.0,
              label="k-distance")
    how = "chosen from the data" if step.eps_auto_ else "given"
    ax_k.axhline(step.eps_, color=_DIVERGED, ls="--", lw=1.0,
                 label=f"ε = {step.eps_:.4g} ({how})")
    ax_k.set_yscale("log")
    ax_k.set_xlabel("% of the clustered local models, sorted")
    ax_k.set_ylabel("distance to the MinPts-th neighbour")
    queried = f"; {dist.size:,} of {labels.size:,} queried" if dist.size < labels.size else ""
    ax_k.set_title(f"k-distance curve (MinPts = {step.min_pts_}{queried})", fontsize=9,
                   loc="left")
    ax_k.legend(fontsize=8, loc="upper left")
    # in inches: the axes 2.45 high under 0.65 of titles, above the tick labels, the x label
    # and the legend's rows; 0.75 left of the axes, 1.0 between them, 0.15 right of them
    below = _TICKS_AND_LABEL + 0.05 + 0.17 * -(-len(listed) // _LEGEND_COLUMNS)
    height = _AXES_HEIGHT + below + 0.65
    fig.set_figheight(height)
    fig.subplots_adjust(left=0.075, right=0.985, bottom=below / height, top=1 - 0.65 / height,
                        wspace=1.0 / ((10 - 0.75 - 0.15 - 1.0) / 2))
    fig.suptitle(title or "Step 4: local models θ_k in the DBSCAN embedding (PCA)",
                 y=1 - 0.08 / height, va="top")
    return fig


def switching_figure(model: PWARX, u: np.ndarray, y: np.ndarray,
                     true_modes: np.ndarray | None = None,
                     true_thetas: np.ndarray | None = None,
                     title: str | None = None) -> Figure:
    """The estimated region H_i (step 6, eq. 1) of each sample of one experiment over time.

    The region is ``model.regions_.predict(φ(k))`` with φ built from (u, y) as in eq. (2)–(3);
    at most the first 606 samples are shown. Without the true modes, a model of more than
    ``_MAX_LEVELS`` regions gets a level for each region visited in them (every n-th
    labelled if those are still more). With the true modes (simulated data) a panel
    above shows them, the estimated regions are paired with true sub-models by their
    parameters (:func:`~pwa_pipeline.scoring.metrics.match_submodels`), coloured as the mode
    they are paired with, samples where the two disagree are marked ×, and the title gives
    the share of samples (all of the experiment's regressor rows) that agree.

    Parameters
    ----------
    model : fitted PWARX
    u : ndarray of shape (N, r)
    y : ndarray of shape (N, m)
        One experiment.
    true_modes : ndarray of shape (N,) or (N − max(na, nb),), optional
        True mode of each sample (0-based, as ``make_hure_vasak(...).modes``), or of each
        regressor row.
    true_thetas : ndarray of shape (s_true, d, m), optional
        True parameter matrices; required with ``true_modes``.
    title : str, optional

    Returns
    -------
    Figure
        One axes, or two (true mode above) with ``true_modes``.
    """
    u, y = np.asarray(u, float), np.asarray(y, float)
    phi = lagged_matrix(u, y, model.na, model.nb, model.affine)
    n0 = n_initial(model.na, model.nb)
    region = model.regions_.predict(phi)
    k = np.arange(n0, y.shape[0])
    shown = k < MAX_SAMPLES
    s = model.thetas_.shape[0]
    if true_modes is None:
        fig = _figure(10, 2.6)
        ax = fig.subplots()
        # more regions than labels fit: a level for each region visited, every n-th labelled
        levels = np.arange(s) if s <= _MAX_LEVELS else np.unique(region[shown])
        ax.scatter(k[shown], np.searchsorted(levels, region[shown]),
                   c=[_colour(r) for r in region[shown]], marker="|", s=60, lw=1.2)
        ticks = np.arange(0, levels.size, -(-levels.size // _MAX_LEVELS))
        ax.set_yticks(ticks, [f"H{levels[i] + 1}" for i in ticks])
        ax.set_ylim(-0.6, levels.size - 0.4)
        ax.set_ylabel("estimated region" if levels.size == s else
                      f"estimated region\n({levels.size} of {s} visited)")
        ax.set_xlabel("sample k")
        fig.suptitle(title or "Estimated region H_i over time")
        return fig
    if true_thetas is None:
        raise ValueError("true_thetas is needed with true_modes (to pair regions with modes)")
    true = np.asarray(true_modes)
    if true.shape[0] == y.shape[0]:
        true = true[n0:]
    if true.shape[0] != phi.shape[0]:
        raise ValueError(f"true_modes has {np.asarray(true_modes).shape[0]} entries; expected "
                         f"{y.shape[0]} (one per sample) or {phi.shape[0]} (one per row)")
    mode_of = match_submodels(model.thetas_, np.asarray(true_thetas))[0]
    mapped = mode_of[region]
    agreement = 100.0 * float(np.mean(mapped == true))
    s_true = np.asarray(true_thetas).shape[0]
    # Paired regions sit at the level of their mode (as in the panel above), unpaired
    # regions above them.
    level = mode_of.copy()
    level[mode_of < 0] = s_true + np.arange(np.sum(mode_of < 0))
    n_levels = max(s_true, int(level.max()) + 1)
    fig = _figure(10, 4.4)
    ax_true, ax = fig.subplots(2, 1, sharex=True)
    ax_true.scatter(k[shown], true[shown], c=[_colour(t) for t in true[shown]], marker="|",
                    s=60, lw=1.2)
    ax_true.set_yticks(range(s_true), [f"mode {i + 1}" for i in range(s_true)])
    ax_true.set_ylabel("true")
    ax.scatter(k[shown], level[region[shown]], c=[_colour(t) for t in mapped[shown]],
               marker="|", s=60, lw=1.2)
    wrong = shown & (mapped != true)
    ax.plot(k[wrong], level[region[wrong]], "x", color="black", ms=4, mew=0.8, ls="none",
            label=f"disagrees with the true mode ({wrong.sum()} of {shown.sum()} shown)")
    ax.set_yticks(level, [f"H{i + 1} ≙ mode {mode_of[i] + 1}" if mode_of[i] >= 0
                          else f"H{i + 1} (unpaired)" for i in range(s)])
    for a in (ax_true, ax):
        a.set_ylim(-0.6, n_levels - 0.4)
    ax.set_ylabel("estimated")
    ax.set_xlabel("sample k")
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.28), fontsize=8, frameon=False)
    fig.suptitle(title or f"Estimated region vs true mode: agreement {agreement:.1f} % "
                          f"of {true.size} samples")
    return fig


def regions_figure(model: PWARX, phi: np.ndarray, names: list[str],
                   title: str | None = None, max_points: int = 3000) -> Figure:
    """The regions H_i (step 6) in the 2-D slice of φ where they differ most.

    The two regressors are those along which the region classifier varies most: largest
    spread (max − min over regions) of the ``regions_.coef_`` column times the standard
    deviation of that regressor in ``phi``; the others are held at their median. The regions
    are filled on a grid over the 0.5–99.5 % range of the two regressors, and the training
    rows (a seeded subset of at most ``max_points``) are drawn on top coloured by their
    sub-model (``model.labels_``; −1 grey). Rows lie off the slice in the other regressors,
    so some sit in a region other than their own.

    Parameters
    ----------
    model : fitted PWARX
    phi : ndarray of shape (n, d)
        The training regressors (``Regressors.phi``), one row per ``model.labels_`` entry.
    names : list of str
        The d regressor names (:func:`~pwa_pipeline.pwa.regressors.regressor_names`).
    title : str, optional
    max_points : int, default 3000

    Returns
    -------
    Figure
        One axes.
    """
    phi = np.asarray(phi, float)
    if phi.shape[1] < 2:
        raise ValueError("a 2-D slice needs at least 2 regressors")
    if len(names) != phi.shape[1]:
        raise ValueError(f"{len(names)} names for {phi.shape[1]} regressors")
    regions = model.regions_
    spread = np.ptp(regions.coef_, axis=0) * phi.std(axis=0)
    i, j = np.sort(np.argsort(-spread, kind="stable")[:2])
    lo, hi = np.quantile(phi[:, [i, j]], [0.005, 0.995], axis=0)
    pad = 0.05 * (hi - lo)
    gx, gy = np.meshgrid(np.linspace(lo[0] - pad[0], hi[0] + pad[0], 200),
                         np.linspace(lo[1] - pad[1], hi[1] + pad[1], 200))
    grid = np.tile(np.median(phi, axis=0), (gx.size, 1))
    grid[:, i], grid[:, j] = gx.ravel(), gy.ravel()
    z = regions.predict(grid).reshape(gx.shape)
    s = regions.n_regions_
    rng = np.random.default_rng(0)
    rows = np.sort(rng.choice(phi.shape[0], max_points, replace=False)) \
        if phi.shape[0] > max_points else np.arange(phi.shape[0])
    labels = np.asarray(model.labels_)[rows]
    # one legend column per _LEGEND_ROWS entries, the figure widened for each further one
    columns = -(-(s + np.unique(labels).size) // _LEGEND_ROWS)
    fig = _figure(7.5 + 1.3 * (columns - 1), 5.2)
    ax = fig.subplots()
    ax.contourf(gx, gy, z, levels=np.arange(s + 1) - 0.5, colors=[_colour(r) for r in range(s)],
                alpha=0.25)
    from matplotlib.patches import Patch

    handles = [Patch(color=_colour(r), alpha=0.4, label=f"H{r + 1}") for r in range(s)]
    for c in np.unique(labels):
        at = rows[labels == c]
        handles.append(ax.scatter(phi[at, i], phi[at, j], s=6, color=_colour(c), lw=0.2,
                                  edgecolor="black", alpha=0.8,
                                  label="noise" if c < 0 else f"rows of θ{c + 1}"))
    ax.set_xlim(gx.min(), gx.max())
    ax.set_ylim(gy.min(), gy.max())
    ax.set_xlabel(names[i])
    ax.set_ylabel(names[j])
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              frameon=False, ncols=columns)
    others = "others at their median" if phi.shape[1] > 2 else "no other regressors"
    fig.suptitle(title or f"Step 6: regions H_i in the slice ({names[i]}, {names[j]}), {others}",
                 fontsize=10)
    return fig


def to_png(fig: Figure, width: int | None = None, max_bytes: int = 300_000) -> bytes:
    """The figure as PNG bytes, at most ``max_bytes`` (the PNG of :func:`to_markdown`).

    Saved at 90 dpi by default; the figures of this module then come out at about 15–250 kB
    (prediction of two outputs ≈ 145 kB, of six noisy outputs ≈ 250 kB; parameter clusters
    ≈ 65 kB; regions ≈ 65 kB; switching ≈ 15–35 kB). A PNG over ``max_bytes`` is saved again
    at a lower resolution until it fits (down to about 30 dpi).

    Parameters
    ----------
    fig : Figure
    width : int, optional
        Width of the PNG in pixels; None: 90 dpi (900 px for a 10-inch figure).
    max_bytes : int, default 300_000
        Size limit of the PNG (the base64 text is 4/3 of it).
    """
    dpi = 90.0 if width is None else width / fig.get_figwidth()
    while True:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi)
        png = buf.getvalue()
        if len(png) <= max_bytes or dpi < 30:
            return png
        dpi *= 0.75


def to_markdown(fig: Figure, width: int | None = None, max_bytes: int = 300_000) -> str:
    """The figure as a Markdown image with the PNG inlined (base64), for
    ``dagster.MetadataValue.md``: :func:`png_markdown` of its :func:`to_png`, the suptitle as
    alternative text.

    Parameters
    ----------
    fig : Figure
    width, max_bytes
        As in :func:`to_png`.
    """
    return png_markdown(to_png(fig, width, max_bytes), fig.get_suptitle() or "figure")


def png_markdown(png: bytes, alt: str) -> str:
    """A rendered PNG as a Markdown image inlined in base64:
    ``![<alt>](data:image/png;base64,...)`` (brackets in ``alt`` made parentheses)."""
    alt = " ".join(alt.replace("[", "(").replace("]", ")").split())
    return f"![{alt}](data:image/png;base64,{base64.b64encode(png).decode('ascii')})"
