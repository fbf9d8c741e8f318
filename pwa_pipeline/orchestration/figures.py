"""Diagnostic figures of a fitted PWARX model and its scores, for Dagster metadata and MLflow.

Every function returns a :class:`matplotlib.figure.Figure` drawn without pyplot (no global
state, no display); :func:`to_markdown` turns one into Markdown for
``dagster.MetadataValue.md``. Colours are shared: sub-model / region i is ``_colour(i)`` in
every figure, DBSCAN noise is grey.

What a control engineer reads at a glance:

- every title opens with the line :func:`context_title` (data set, hyper-parameter set and
  method), so that a figure seen alone in MLflow or a screenshot says what it shows;
- axes carry the data's units, ``name [unit]`` (:attr:`~pwa_pipeline.datasets.Dataset.units`);
- every figure fits a laptop screen (about 1366 × 768) at the 90 dpi of :func:`to_png`:
  at most 10 inches (900 px) wide and :data:`MAX_HEIGHT` inches (650 px) high.

The numbers a figure draws are computed apart from the drawing where they are worth caching
(:func:`switching_inputs`, :func:`region_slice`): the pipeline caches those and draws the
figure, titled for its own set, every time, so that sets sharing a model never show each
other's titles.
"""

from __future__ import annotations

import base64
import functools
import io
import textwrap
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._arrays import column_rms
from ..datasets.registry import with_unit
from ..pwa.steps.clustering import k_distances
from ..pwa.steps.embedding import EMBEDDINGS
from ..regressors import lagged_matrix, n_initial, regressor_names
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
#: Largest figure height in inches: 650 px at the 90 dpi of :func:`to_png`, which leaves a
#: 768-pixel laptop screen room for the browser and the page around the figure.
MAX_HEIGHT = 650 / 90
#: Largest figure width in inches: 900 px at 90 dpi.
MAX_WIDTH = 10.0
#: Most outputs stacked in one column of the prediction figure; more go in further columns.
_GRID_ROWS = 3
#: Inches of each row of the prediction figure.
_ROW_HEIGHT = 1.9
#: tab10 without its grey (grey is DBSCAN noise) and its red (red flags a diverged run).
_PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#bcbd22",
            "#17becf")
_NOISE = "#9a9a9a"
_DIVERGED = "#d62728"
_OUTSIDE = {"one_step": ("one-step", "C0", "\\\\\\"), "free_run": ("free run", "C1", "///")}
"""Label, colour and hatch of the prediction figure's stretches where a mode's regressor
leaves the data envelope (hatched, so that they are not read as the free run's solid
out-of-range shading)."""
_LEGEND_ROWS = 22
"""Entries of a legend column of the regions figure (more fit beside its 5.2-inch axes)."""
_MAX_LEVELS = 10
"""Regions the switching figure labels on its 2-inch axis without overlap."""
_AXES_HEIGHT = 2.45
"""Inches of the parameter-clusters figure's axes (its height grows with its legend)."""
_TICKS_AND_LABEL = 0.5
"""Inches below those axes for their tick labels and x label, above the legend."""
_LEGEND_COLUMNS = 3
_Z_ONE_STEP, _Z_FREE, _Z_MEASURED = 2.0, 2.5, 3.0
"""Drawing order of the prediction figure's lines: the measured output on top."""
_CURVE_POINTS = 1000
"""Points queried for the parameter-clusters figure's k-distance curve: its shape, at a
fifth of the cost of the 5,000 that choose ε (:func:`~pwa_pipeline.pwa.steps.clustering.k_distances`)."""


@functools.cache
def figures_fingerprint() -> str:
    """Hash of this module's source: part of the key of cached figures, so that figures drawn
    by other code are never shown."""
    return source_fingerprint([Path(__file__)])


def context_title(dataset: str, hparams: str, method: str) -> str:
    """The first line of every figure's title: ``<data set> | set <set> | <method>``.

    Parameters
    ----------
    dataset, hparams : str
        The partition's data set and hyper-parameter set.
    method : str
        The method's label (:attr:`pwa_pipeline.methods.Method.label`).

    Examples
    --------
    >>> context_title("kuka_robot", "default", "PWA")
    'kuka_robot | set default | PWA'
    """
    return f"{dataset} | set {hparams} | {method}"


def _suptitle(fig: Figure, context: str, what: str, **kwargs) -> None:
    """``context`` (:func:`context_title`) above ``what`` as the figure's title; ``what``
    alone without a context."""
    fig.suptitle(f"{context}\n{what}" if context else what, **kwargs)


def _colour(i: int) -> str:
    """Colour of sub-model / region / cluster ``i`` (0-based); grey for −1 (noise)."""
    return _NOISE if i < 0 else _PALETTE[i % len(_PALETTE)]


def _figure(width: float, height: float, layout: str | None = "constrained") -> Figure:
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), layout=layout)


def _legend_below(fig: Figure) -> None:
    """One legend for every axes of ``fig`` (each label once, in the order first drawn),
    below them in at most two rows, so that it never covers data and leaves the axes the
    figure's whole width."""
    entries: dict[str, object] = {}
    for ax in fig.axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    fig.legend(list(entries.values()), list(entries), loc="outside lower center", fontsize=8,
               frameon=False, ncols=min(len(entries), 4))


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
        ax.plot(k, free, color="C1", lw=1.0, zorder=_Z_FREE, label="free run")
        return
    inside = ~out
    near = inside | np.r_[False, inside[:-1]] | np.r_[inside[1:], False]
    line = np.where(near, np.clip(v, lo, hi), np.nan)
    colour = _DIVERGED if diverged else "C1"
    ax.plot(k, line, color=colour, lw=1.0, zorder=_Z_FREE,
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
                        ls="none", clip_on=False, zorder=_Z_FREE)
    pad = 0.03 * (hi - lo)
    ax.set_ylim(lo - pad, hi + pad)


def prediction_figure(data: Dataset, evaluation: Evaluation, context: str,
                      warmup: int) -> Figure:
    """Measured output, one-step prediction and free run of the first held-out experiment.

    One subplot per output, over the experiment's first 606 samples at most (one KUKA robot
    experiment), each titled with that output's one-step and free-run NRMSE (eq. 21) from
    ``evaluation.table`` (4 significant digits) and its y axis labelled ``name [unit]``.
    Up to three outputs are stacked; more are laid out three rows high in further columns
    (the robot's six in 3 × 2), so that the figure fits a laptop screen (at most 900 × 650
    px at 90 dpi, :data:`MAX_HEIGHT`).

    The measured output is drawn last, on top of everything (a thin black line), and the
    one-step prediction under it as a wider, light blue band: where the two agree (most of
    the time, one step ahead) the measured line runs inside the band and both stay visible.
    A free run flagged ``diverged`` in the table, or with non-finite values, is drawn in red
    as "free run (diverged, clipped)": clipped to the measured range ± 50 % of its span,
    the line stops at the edge where the run leaves that range (a triangle marks each exit,
    the time outside is shaded) instead of lying flat on the clip value. The warm-up window,
    excluded from the scores, is shaded grey. The stretches where the one-step prediction's
    or the free run's regressor φ(k) leaves the model's data envelope
    (``evaluation.outside``: the model is used outside its training data there) are hatched
    in that mode's colour, "<mode> outside the training data", and the title's third line
    gives each mode's share of scored samples outside it (``outside_share`` of the table,
    over all held-out experiments) when one is above 0. One legend below the axes lists
    what any subplot draws.

    Parameters
    ----------
    data : Dataset
        Its ``y_test``, ``y_names`` and ``units``.
    evaluation : Evaluation
        From :func:`pwa_pipeline.scoring.evaluation.evaluate` on ``data``'s held-out
        experiments; its ``table`` (rows per output in order, then ``mean``) and
        ``predictions``.
    context : str
        The title's first line (:func:`context_title`: data set, set, method); the second
        says what is drawn.
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
    n_cols = -(-m // _GRID_ROWS)
    n_rows = -(-m // n_cols)
    fig = _figure(MAX_WIDTH, min(_ROW_HEIGHT * n_rows + 1.15, MAX_HEIGHT))
    grid = fig.subplots(n_rows, n_cols, sharex=True, squeeze=False)
    axes = list(grid.T.ravel()[:m])  # down the first column, then the next
    for ax in grid.T.ravel()[m:]:  # cells left over in the last column
        ax.remove()
    bottoms = [axes[min((c + 1) * n_rows, m) - 1] for c in range(n_cols)]
    for ax in bottoms:  # the lowest axes of each column shows the sample axis
        ax.xaxis.set_tick_params(labelbottom=True)
        ax.set_xlabel("sample k")
    k = np.arange(n)
    outside = {mode: np.asarray(flags[0][:n], bool)
               for mode, flags in (evaluation.outside or {}).items()
               if mode in _OUTSIDE and np.any(flags[0][:n])}
    for j, ax in enumerate(axes):
        one, free_row = rows["one_step"].iloc[j], rows["free_run"].iloc[j]
        free = evaluation.predictions["free_run"][0][:n, j]
        diverged = bool(free_row["diverged"]) or not np.isfinite(free).all()
        ax.axvspan(0, warmup, color="0.85", alpha=0.6, lw=0, label="warm-up")
        # (listed first in the legend, drawn last: the z-order decides what lies on top)
        ax.plot(k, y[:, j], color="black", lw=0.9, zorder=_Z_MEASURED, label="measured")
        ax.plot(k, evaluation.predictions["one_step"][0][:n, j], color="C0", lw=3.0,
                alpha=0.5, solid_capstyle="butt", zorder=_Z_ONE_STEP, label="one-step")
        _free_run(ax, k, free, y[:, j], diverged)
        for mode, mask in outside.items():
            label, colour, hatch = _OUTSIDE[mode]
            # each flagged sample k covers [k − ½, k + ½], so that a lone one shows too
            ax.fill_between(np.repeat(k, 2) + np.tile([-0.5, 0.5], n), 0, 1,
                            where=np.repeat(mask, 2), transform=ax.get_xaxis_transform(),
                            facecolor="none", edgecolor=colour, hatch=hatch, lw=0,
                            alpha=0.45, label=f"{label} outside the training data")
        ax.set_title(f"{data.y_names[j]}: NRMSE one-step {one['nrmse']:.4g}, free run "
                     f"{free_row['nrmse']:.4g}" + (" (diverged)" if diverged else ""),
                     fontsize=8.5, loc="left")
        ax.set_ylabel(data.label(data.y_names[j]))
        ax.set_xlim(0, n - 1)
    _legend_below(fig)
    shown = f"samples 0–{n - 1}" + (f" of {data.y_test[0].shape[0]}" if n < len(data.y_test[0])
                                     else "")
    _suptitle(fig, context, f"Measured output, one-step prediction and free run: held-out "
                            f"experiment 1 of {len(data.y_test)}, {shown}"
                            + _outside_line(evaluation), fontsize=11)
    return fig


def _outside_line(evaluation: Evaluation) -> str:
    """The prediction figure's title line of each mode's share of scored samples outside
    the data envelope (``outside_share``), or "" when none is above 0 or known."""
    if "outside_share" not in evaluation.table:
        return ""
    means = evaluation.table[evaluation.table["output"] == "mean"].set_index("mode")
    shares = {mode: float(means.loc[mode, "outside_share"]) for mode in _OUTSIDE
              if mode in means.index}
    shown = [f"{_OUTSIDE[mode][0]} {100 * v:.3g} %" for mode, v in shares.items()]
    if not any(np.isfinite(v) and v > 0 for v in shares.values()):
        return ""
    return ("\nRegressor outside the training data (hatched): " + ", ".join(shown)
            + " of the scored samples")


def _clustering_embedding(local, step, target: np.ndarray) -> np.ndarray:
    """The clustered θ_k embedded as the clustering step embedded them (eq. 8–10), unit-free
    (θ_k·rms(φ)/rms(y)) when the step was."""
    theta = local.theta_[step.clustered_]
    if step.unit_free:
        theta = theta * local.phi_scale_[None, :, None] / column_rms(np.asarray(target))
    return EMBEDDINGS[step.embedding](theta)


def parameter_clusters_figure(local, clustering, target: np.ndarray,
                              context: str = "") -> Figure:
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
    context : str, optional
        The title's first line (:func:`context_title`: data set, set, method).

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
    # in inches: the axes 2.45 high under 0.65 of titles (0.87 with the context line), above
    # the tick labels, the x label and the legend's rows; 0.75 left of the axes, 1.0 between
    # them, 0.15 right of them
    below = _TICKS_AND_LABEL + 0.05 + 0.17 * -(-len(listed) // _LEGEND_COLUMNS)
    above = 0.87 if context else 0.65
    height = _AXES_HEIGHT + below + above
    fig.set_figheight(height)
    fig.subplots_adjust(left=0.075, right=0.985, bottom=below / height, top=1 - above / height,
                        wspace=1.0 / ((10 - 0.75 - 0.15 - 1.0) / 2))
    _suptitle(fig, context, "Step 4: local models θ_k in the DBSCAN embedding (PCA) and the "
                            "k-distance curve", y=1 - 0.08 / height, va="top", fontsize=11)
    return fig


@dataclass(frozen=True)
class Switching:
    """What the switching figure draws (:func:`switching_inputs`): plain arrays, cached by
    the ``pwa_model`` asset and drawn by :func:`draw_switching`.

    Attributes
    ----------
    k : ndarray of shape (n,)
        The sample of each regressor row of the experiment (from max(na, nb)).
    region : ndarray of shape (n,)
        The estimated region of each row (0-based).
    n_regions : int
        The model's regions s.
    true : ndarray of shape (n,) or None
        The true mode of each row (simulated data).
    mode_of : ndarray of shape (s,) or None
        The true mode each region is paired with (−1: unpaired), with ``true``.
    n_modes : int
        True modes (0 without ``true``).
    """

    k: np.ndarray
    region: np.ndarray
    n_regions: int
    true: np.ndarray | None = None
    mode_of: np.ndarray | None = None
    n_modes: int = 0

    @property
    def agreement(self) -> float:
        """Percent of all the experiment's rows whose region is paired with their true mode
        (NaN without the truth)."""
        if self.true is None:
            return float("nan")
        return 100.0 * float(np.mean(self.mode_of[self.region] == self.true))


def switching_inputs(model: PWARX, u: np.ndarray, y: np.ndarray,
                     true_modes: np.ndarray | None = None,
                     true_thetas: np.ndarray | None = None) -> Switching:
    """The estimated region H_i (step 6, eq. 1) of each sample of one experiment.

    The region is ``model.regions_.predict(φ(k))`` with φ built from (u, y) as in eq. (2)–(3).
    With the true modes (simulated data) the estimated regions are paired with true
    sub-models by their parameters (:func:`~pwa_pipeline.scoring.metrics.match_submodels`).

    Parameters
    ----------
    model : fitted PWARX
        Any route (``regions_`` and ``thetas_``, the model as eq. 1).
    u : ndarray of shape (N, r)
    y : ndarray of shape (N, m)
        One experiment.
    true_modes : ndarray of shape (N,) or (N − max(na, nb),), optional
        True mode of each sample (0-based, as ``make_hure_vasak(...).modes``), or of each
        regressor row.
    true_thetas : ndarray of shape (s_true, d, m), optional
        True parameter matrices; required with ``true_modes``.

    Raises
    ------
    ValueError
        ``true_modes`` without ``true_thetas``, or of a length that fits neither the samples
        nor the rows.
    """
    u, y = np.asarray(u, float), np.asarray(y, float)
    phi = lagged_matrix(u, y, model.output_lags_, model.nb, model.affine)
    n0 = n_initial(model.output_lags_, model.nb)
    region = np.asarray(model.regions_.predict(phi))
    k = np.arange(n0, y.shape[0])
    s = model.thetas_.shape[0]
    if true_modes is None:
        return Switching(k, region, s)
    if true_thetas is None:
        raise ValueError("true_thetas is needed with true_modes (to pair regions with modes)")
    true = np.asarray(true_modes)
    if true.shape[0] == y.shape[0]:
        true = true[n0:]
    if true.shape[0] != phi.shape[0]:
        raise ValueError(f"true_modes has {np.asarray(true_modes).shape[0]} entries; expected "
                         f"{y.shape[0]} (one per sample) or {phi.shape[0]} (one per row)")
    mode_of = match_submodels(model.thetas_, np.asarray(true_thetas))[0]
    return Switching(k, region, s, true, np.asarray(mode_of), np.asarray(true_thetas).shape[0])


def _shown(k: np.ndarray) -> tuple[np.ndarray, str]:
    """The rows of the samples shown (those before :data:`MAX_SAMPLES`), and what a title
    says of them: ``""`` when all are shown, else ``", the first 605 of 3999 samples
    shown"``."""
    shown = k < MAX_SAMPLES
    if shown.all():
        return shown, ""
    return shown, f", the first {shown.sum()} of {k.size} samples shown"


def draw_switching(sw: Switching, context: str = "") -> Figure:
    """The switching figure of :func:`switching_inputs`' numbers.

    At most the first 606 samples are shown, and the title says which. Without the true
    modes, a model of more than ``_MAX_LEVELS`` regions gets a level for each region visited
    in them (every n-th labelled if those are still more). With the true modes a panel above
    shows them, the estimated regions sit at the level of the mode they are paired with,
    coloured as it, samples where the two disagree are marked ×, and the title gives the
    share of all the experiment's samples (not only those shown) that agree.

    Parameters
    ----------
    sw : Switching
    context : str, optional
        The title's first line (:func:`context_title`: data set, set, method).

    Returns
    -------
    Figure
        One axes, or two (true mode above) with the true modes.
    """
    k, region, s = sw.k, sw.region, sw.n_regions
    shown, which = _shown(k)
    if sw.true is None:
        fig = _figure(MAX_WIDTH, 2.8 if context else 2.6)
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
        _suptitle(fig, context, "Estimated region H_i, held-out experiment 1"
                                + (which or f", all {k.size} samples"), fontsize=11)
        return fig
    true, mode_of, s_true = sw.true, sw.mode_of, sw.n_modes
    mapped = mode_of[region]
    # Paired regions sit at the level of their mode (as in the panel above), unpaired
    # regions above them.
    level = mode_of.copy()
    level[mode_of < 0] = s_true + np.arange(np.sum(mode_of < 0))
    n_levels = max(s_true, int(level.max()) + 1)
    fig = _figure(MAX_WIDTH, 4.6 if context else 4.4)
    ax_true, ax = fig.subplots(2, 1, sharex=True)
    ax_true.scatter(k[shown], true[shown], c=[_colour(t) for t in true[shown]], marker="|",
                    s=60, lw=1.2)
    ax_true.set_yticks(range(s_true), [f"mode {i + 1}" for i in range(s_true)])
    ax_true.set_ylabel("true")
    ax.scatter(k[shown], level[region[shown]], c=[_colour(t) for t in mapped[shown]],
               marker="|", s=60, lw=1.2)
    wrong = shown & (mapped != true)
    ax.plot(k[wrong], level[region[wrong]], "x", color="black", ms=4, mew=0.8, ls="none",
            label=f"disagrees with the true mode ({wrong.sum()} of the {shown.sum()} samples "
                  f"shown)")
    ax.set_yticks(level, [f"H{i + 1} ≙ mode {mode_of[i] + 1}" if mode_of[i] >= 0
                          else f"H{i + 1} (unpaired)" for i in range(s)])
    for a in (ax_true, ax):
        a.set_ylim(-0.6, n_levels - 0.4)
    ax.set_ylabel("estimated")
    ax.set_xlabel("sample k")
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.28), fontsize=8, frameon=False)
    _suptitle(fig, context, f"Estimated region vs true mode, held-out experiment 1: agreement "
                            f"{sw.agreement:.1f} % over all {k.size} samples"
                            + (f", the first {shown.sum()} shown" if which else ""), fontsize=11)
    return fig


def switching_figure(model: PWARX, u: np.ndarray, y: np.ndarray,
                     true_modes: np.ndarray | None = None,
                     true_thetas: np.ndarray | None = None,
                     context: str = "") -> Figure:
    """The estimated region H_i (step 6, eq. 1) of each sample of one experiment over time:
    :func:`draw_switching` of :func:`switching_inputs` (see both for the parameters).

    Returns
    -------
    Figure
        One axes, or two (true mode above) with ``true_modes``.
    """
    return draw_switching(switching_inputs(model, u, y, true_modes, true_thetas), context)


@dataclass(frozen=True)
class OutputSwitching:
    """What the switching figure of a model of several output groups draws
    (:func:`structured_switching_inputs`).

    Attributes
    ----------
    k : ndarray of shape (n,)
        The sample of each regressor row of the experiment.
    regions : list of ndarrays of shape (n,)
        Per output group, the region of each row (its own region map).
    n_regions : list of int
        Per output group, its number of regions.
    structures : list of str
        Per group, its outputs' structures in words (``model.structures_``).
    variables : list of str
        Per group, what its regions are the signs of (``z = q1(k-1) − q1(k-2)``), or ``""``
        (one region, or regions of the paper's steps).
    outputs : list of str
        Per group, its outputs' names.
    """

    k: np.ndarray
    regions: list[np.ndarray]
    n_regions: list[int]
    structures: list[str]
    variables: list[str]
    outputs: list[str]


def _combination(weights: np.ndarray, names: list[str]) -> str:
    """``w·φ`` written out, e.g. ``q1(k-1) − q1(k-2)``."""
    terms = []
    for w, name in zip(weights, names, strict=True):
        if w == 0:
            continue
        sign = "−" if w < 0 else "+"
        size = "" if abs(w) == 1 else f"{abs(w):.3g}·"
        terms.append(f"{sign} {size}{name}")
    text = " ".join(terms)
    return text[2:] if text.startswith("+ ") else text


def structured_switching_inputs(model: PWARX, u: np.ndarray, y: np.ndarray,
                                y_names: list[str], u_names: list[str]) -> OutputSwitching:
    """The region of each output group of a model (``model.groups_``) at each sample of one
    experiment.

    Each group has its own region map over φ (:mod:`~pwa_pipeline.pwa.partitions`): the
    signs of scheduling variables, the paper's steps 2–6 run on its regressors (clustered),
    or one region (a linear model).

    Parameters
    ----------
    model : fitted PWARX
    u : ndarray of shape (N, r)
    y : ndarray of shape (N, m)
        One experiment.
    y_names, u_names : list of str
        The channel names, to write the scheduling variables and the groups with.
    """
    u, y = np.asarray(u, float), np.asarray(y, float)
    lags = model.output_lags_
    phi = lagged_matrix(u, y, lags, model.nb, model.affine)
    names = regressor_names(list(y_names), list(u_names), lags, model.nb, model.affine)
    variables = []
    for group in model.groups_:
        w = getattr(group.regions, "weights", None)
        variables.append("" if w is None else ", ".join(
            f"z{v + 1 if len(w) > 1 else ''} = {_combination(row, names)}"
            for v, row in enumerate(w)))
    return OutputSwitching(
        k=np.arange(n_initial(lags, model.nb), y.shape[0]),
        regions=[np.asarray(g.regions.predict(phi)) for g in model.groups_],
        n_regions=[g.n_regions for g in model.groups_],
        structures=["; ".join(model.structures_[j] for j in g.outputs)
                    for g in model.groups_],
        variables=variables,
        outputs=[", ".join(y_names[j] for j in g.outputs) for g in model.groups_])


def _sign_labels(n_regions: int) -> list[str]:
    """Region labels of sign regions: ``z ≤ 0``, ``z > 0`` for one variable, the signs of
    each for more (region Σ_v 2^v [z_v > 0])."""
    v = int(np.log2(n_regions))
    if v == 1:
        return ["z ≤ 0", "z > 0"]
    return [", ".join(f"z{b + 1} {'>' if r >> b & 1 else '≤'} 0" for b in range(v))
            for r in range(n_regions)]


def draw_structured_switching(sw: OutputSwitching, context: str = "") -> Figure:
    """The switching figure of a model of several output groups: one panel per group, its
    region at each of the first 606 samples of the experiment.

    Each panel is titled with the group's outputs, their structure and what its regions are
    (the sign of a scheduling variable, written with the data's channel names); a group with
    one region (a linear model) says so instead of drawing a flat line. The panels share the
    sample axis and fit a laptop screen (at most :data:`MAX_HEIGHT` inches).

    Parameters
    ----------
    sw : OutputSwitching
    context : str, optional
        The title's first line (:func:`context_title`: data set, set, method).

    Returns
    -------
    Figure
        One axes per output group.
    """
    k = sw.k
    shown, which = _shown(k)
    m = len(sw.regions)
    levels = [np.arange(s) if s <= _MAX_LEVELS else np.unique(r[shown])
              for r, s in zip(sw.regions, sw.n_regions, strict=True)]
    heights = [0.3 + 0.22 * max(lv.size, 1) for lv in levels]
    body = min(sum(heights), MAX_HEIGHT - 1.3)
    fig = _figure(MAX_WIDTH, body + 1.3)
    axes = fig.subplots(m, 1, sharex=True, squeeze=False, height_ratios=heights)[:, 0]
    for j, ax in enumerate(axes):
        region, s, lv = sw.regions[j], sw.n_regions[j], levels[j]
        if s == 1:
            ax.text(0.5, 0.5, "one region: a single linear model at every sample",
                    transform=ax.transAxes, ha="center", va="center", fontsize=8,
                    color="0.35")
            ax.set_yticks([])
            ax.set_ylim(-0.6, 0.6)
        else:
            ax.scatter(k[shown], np.searchsorted(lv, region[shown]),
                       c=[_colour(r) for r in region[shown]], marker="|", s=40, lw=1.0)
            labels = _sign_labels(s) if sw.variables[j] and s & (s - 1) == 0 else [
                f"H{r + 1}" for r in range(s)]
            ticks = np.arange(0, lv.size, -(-lv.size // _MAX_LEVELS))
            ax.set_yticks(ticks, [labels[lv[i]] for i in ticks], fontsize=7.5)
            ax.set_ylim(-0.6, lv.size - 0.4)
        regions = f", regions by the sign of {sw.variables[j]}" if sw.variables[j] and s > 1 \
            else ""
        ax.set_title(f"{sw.outputs[j]}: {sw.structures[j]}{regions}", fontsize=8.5,
                     loc="left", pad=2)
    axes[-1].set_xlabel("sample k")
    _suptitle(fig, context, "Region of each output group's model, held-out experiment 1"
                            + (which or f", all {k.size} samples"), fontsize=11)
    return fig


@dataclass(frozen=True)
class RegionSlice:
    """What the regions figure draws (:func:`region_slice`): plain arrays, cached by the
    ``pwa_model`` asset and drawn by :func:`draw_regions`.

    Attributes
    ----------
    i, j : int
        The two regressors of the slice (indices into φ, i < j).
    gx, gy : ndarray of shape (g,)
        The grid along them.
    z : ndarray of shape (g, g)
        The region of each grid point (rows along ``gy``).
    n_regions : int
    points : ndarray of shape (n, 2)
        The training rows drawn (a seeded subset), in the two regressors.
    labels : ndarray of shape (n,)
        Their sub-model (``model.labels_``; −1 noise).
    d : int
        Regressors in φ.
    """

    i: int
    j: int
    gx: np.ndarray
    gy: np.ndarray
    z: np.ndarray
    n_regions: int
    points: np.ndarray
    labels: np.ndarray
    d: int


def region_slice(model: PWARX, phi: np.ndarray, labels: np.ndarray | None = None,
                 max_points: int = 3000) -> RegionSlice:
    """The regions H_i of the model as eq. (1) (``model.regions_``) in the 2-D slice of φ
    where they differ most.

    The two regressors are those along which the region boundaries vary most: the largest
    coefficient of that regressor over every boundary of every output group's regions
    (``halfspaces()``) times the regressor's standard deviation in ``phi`` (for the SVM's
    argmax regions, the spread of its ``coef_`` column); the others are held at their
    median. The regions are evaluated on a 200 × 200 grid over the 0.5–99.5 % range of the
    two regressors (widened by 5 %), and at most ``max_points`` training rows (a seeded
    subset) are kept with their label.

    Parameters
    ----------
    model : fitted PWARX (any route)
    phi : ndarray of shape (n, d)
        The training regressors at the model's lags.
    labels : ndarray of shape (n,), optional
        The rows' sub-models as the fit assigned them (step 5's ``labels_``, −1 noise);
        default: their region.
    max_points : int, default 3000

    Raises
    ------
    ValueError
        Fewer than 2 regressors.
    """
    phi = np.asarray(phi, float)
    if phi.shape[1] < 2:
        raise ValueError("a 2-D slice needs at least 2 regressors")
    regions = model.regions_
    rows = [h[0] for g in model.groups_ for h in g.regions.halfspaces() if h is not None]
    normals = np.vstack([np.zeros((1, phi.shape[1])), *rows])
    spread = np.abs(normals).max(axis=0) * phi.std(axis=0)
    i, j = np.sort(np.argsort(-spread, kind="stable")[:2])
    lo, hi = np.quantile(phi[:, [i, j]], [0.005, 0.995], axis=0)
    pad = 0.05 * (hi - lo)
    gx = np.linspace(lo[0] - pad[0], hi[0] + pad[0], 200)
    gy = np.linspace(lo[1] - pad[1], hi[1] + pad[1], 200)
    mx, my = np.meshgrid(gx, gy)
    grid = np.tile(np.median(phi, axis=0), (mx.size, 1))
    grid[:, i], grid[:, j] = mx.ravel(), my.ravel()
    z = np.asarray(regions.predict(grid)).reshape(mx.shape)
    labels = np.asarray(regions.predict(phi)) if labels is None else np.asarray(labels)
    rng = np.random.default_rng(0)
    rows = np.sort(rng.choice(phi.shape[0], max_points, replace=False)) \
        if phi.shape[0] > max_points else np.arange(phi.shape[0])
    return RegionSlice(int(i), int(j), gx, gy, z, int(regions.n_regions_), phi[rows][:, [i, j]],
                       labels[rows], phi.shape[1])


def draw_regions(sl: RegionSlice, names: list[str], context: str = "",
                 units: Mapping[str, str] | None = None) -> Figure:
    """The regions figure of :func:`region_slice`'s numbers.

    The regions are filled, and the training rows drawn on top coloured by their sub-model
    (−1 grey). Rows lie off the slice in the other regressors, so some sit in a region other
    than their own. A long legend takes further columns to the right, the figure widened for
    each (at most 900 px at 90 dpi).

    Parameters
    ----------
    sl : RegionSlice
    names : list of str
        The d regressor names (:func:`~pwa_pipeline.regressors.regressor_names`).
    context : str, optional
        The title's first line (:func:`context_title`: data set, set, method).
    units : mapping of str to str, optional
        Channel units (:attr:`~pwa_pipeline.datasets.Dataset.units`): the axes read
        ``q1(k-1) [deg]``.

    Raises
    ------
    ValueError
        ``names`` not of the slice's d regressors.
    """
    if len(names) != sl.d:
        raise ValueError(f"{len(names)} names for {sl.d} regressors")
    units = units or {}
    s, labels = sl.n_regions, sl.labels
    # one legend column per _LEGEND_ROWS entries, the figure widened for each further one
    columns = -(-(s + np.unique(labels).size) // _LEGEND_ROWS)
    fig = _figure(min(7.4 + 1.3 * (columns - 1), MAX_WIDTH), 5.2)
    ax = fig.subplots()
    ax.contourf(sl.gx, sl.gy, sl.z, levels=np.arange(s + 1) - 0.5,
                colors=[_colour(r) for r in range(s)], alpha=0.25)
    from matplotlib.patches import Patch

    handles = [Patch(color=_colour(r), alpha=0.4, label=f"H{r + 1}") for r in range(s)]
    for c in np.unique(labels):
        at = labels == c
        handles.append(ax.scatter(sl.points[at, 0], sl.points[at, 1], s=6, color=_colour(c),
                                  lw=0.2, edgecolor="black", alpha=0.8,
                                  label="noise" if c < 0 else f"rows of θ{c + 1}"))
    ax.set_xlim(sl.gx.min(), sl.gx.max())
    ax.set_ylim(sl.gy.min(), sl.gy.max())
    ax.set_xlabel(with_unit(names[sl.i], units))
    ax.set_ylabel(with_unit(names[sl.j], units))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              frameon=False, ncols=columns)
    others = "others at their median" if sl.d > 2 else "no other regressors"
    _suptitle(fig, context, f"Step 6: regions H_i in the slice ({names[sl.i]}, {names[sl.j]}), "
                            f"{others}", fontsize=10)
    return fig


def regions_figure(model: PWARX, phi: np.ndarray, names: list[str], context: str = "",
                   max_points: int = 3000, units: Mapping[str, str] | None = None,
                   labels: np.ndarray | None = None) -> Figure:
    """The regions H_i (step 6) in the 2-D slice of φ where they differ most:
    :func:`draw_regions` of :func:`region_slice` (see both for the parameters).

    Returns
    -------
    Figure
        One axes.
    """
    if len(names) != np.shape(phi)[1]:
        raise ValueError(f"{len(names)} names for {np.shape(phi)[1]} regressors")
    return draw_regions(region_slice(model, phi, labels, max_points), names, context, units)


def to_png(fig: Figure, width: int | None = None, max_bytes: int = 300_000) -> bytes:
    """The figure as PNG bytes, at most ``max_bytes`` (the PNG of :func:`to_markdown`).

    Saved at 90 dpi by default, where the figures of this module are at most 900 × 650 px
    (a laptop screen's page without scrolling); they then come out at about 15–250 kB.
    A PNG over ``max_bytes`` is saved again at a lower resolution until it fits (down to
    about 30 dpi).

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


def partition_figure(ss, fixed: np.ndarray, title: str, labels: list[str] | None = None
                     ) -> Figure:
    """The polyhedral partition of a PWA state-space model in a 2-D slice of z = [x; u],
    drawn from the H-representations of its regions (not from the classifier).

    The two coordinates are those the region boundaries lean on most (largest sum over the
    rows of |H_c| times the envelope's half-width in c, rows normalised); the others are held
    at ``fixed``. Each region's slice {(a, b) : H_ab (a, b) ≤ h − H_rest z_rest} is cut with
    the envelope and drawn as its polygon (vertices by half-space intersection around its
    Chebyshev centre); modes whose slice is empty are listed as such.

    Parameters
    ----------
    ss : PWAStateSpace
    fixed : ndarray of shape (n + r,)
        Where the other coordinates are held (e.g. the median training z).
    title : str
        First line of the title (data set, set, method).
    labels : list of str, optional
        Axis label of each coordinate of z (default the state's and inputs' names).

    Returns
    -------
    Figure
        One axes.
    """
    from matplotlib.patches import Polygon
    from scipy.optimize import linprog
    from scipy.spatial import HalfspaceIntersection

    lower, upper = ss.envelope
    half = (upper - lower) / 2
    names = labels or [*ss.state_names, *ss.input_names]
    weight = np.zeros(lower.size)
    for H, _ in ss.regions:
        if H.size:
            weight += (np.abs(H) * half / np.linalg.norm(H * half, axis=1, keepdims=True)
                       ).sum(axis=0)
    i, j = np.sort(np.argsort(-weight, kind="stable")[:2])
    rest = np.setdiff1d(np.arange(lower.size), [i, j])
    box = np.array([[1.0, 0], [-1, 0], [0, 1], [0, -1]]), np.array(
        [upper[i], -lower[i], upper[j], -lower[j]])
    fig = _figure(9.0, 5.6)
    ax = fig.subplots()
    empty = []
    for mode, (H, h) in enumerate(ss.regions):
        A2 = np.vstack([H[:, [i, j]], box[0]])
        b2 = np.concatenate([h - H[:, rest] @ fixed[rest], box[1]])
        norms = np.linalg.norm(A2, axis=1)
        # the Chebyshev centre: the largest disc inside, an interior point for the intersection
        lp = linprog([0, 0, -1], A_ub=np.column_stack([A2, norms]), b_ub=b2,
                     bounds=[(None, None), (None, None), (0, None)], method="highs")
        if lp.status != 0 or lp.x[2] <= 1e-9 * max(half[i], half[j]):
            empty.append(mode + 1)
            continue
        # rows on the other coordinates only are 0 ≤ b here, met (the LP found a point):
        # qhull takes none of them
        keep = norms > 1e-12 * norms.max()
        hull = HalfspaceIntersection(np.column_stack([A2[keep], -b2[keep]]), lp.x[:2])
        vertices = hull.intersections
        centre = vertices.mean(axis=0)
        order = np.argsort(np.arctan2(*(vertices - centre).T[::-1]))
        ax.add_patch(Polygon(vertices[order], closed=True, facecolor=_colour(mode), alpha=0.35,
                             edgecolor=_colour(mode), lw=1.2, label=f"mode {mode + 1}"))
    ax.set_xlim(lower[i], upper[i])
    ax.set_ylim(lower[j], upper[j])
    ax.set_xlabel(names[i])
    ax.set_ylabel(names[j])
    if ax.patches:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False,
                  ncols=-(-len(ax.patches) // _LEGEND_ROWS))
    others = "the other coordinates at their training median" if rest.size else \
        "no other coordinates"
    what = textwrap.fill(f"Regions of the state-space model in the slice ({names[i]}, "
                         f"{names[j]}), {others}", width=90)
    if empty:
        what += f"\n{len(empty)} of {ss.n_modes} modes do not meet this slice"
    _suptitle(fig, title, what, fontsize=10)
    return fig
