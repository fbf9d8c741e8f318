"""The local models as the clustering step clustered them, and its ε
([`ParameterClustersDisplay`][pwa_pipeline.plotting.ParameterClustersDisplay], paper step 4)."""

from __future__ import annotations

import numpy as np

from .._arrays import column_rms
from ..pwa.steps.clustering import k_distances
from ..pwa.steps.embedding import EMBEDDINGS
from .style import DIVERGED, PALETTE, colour, figure, suptitle

#: Inches of the axes (the figure's height grows with its legend).
_AXES_HEIGHT = 2.45
#: Inches below those axes for their tick labels and x label, above the legend.
_TICKS_AND_LABEL = 0.5
_LEGEND_COLUMNS = 3
#: Points queried for the k-distance curve: its shape, at a fifth of the cost of the 5,000
#: that choose ε (`k_distances`).
_CURVE_POINTS = 1000


def _embedding(local, step, target: np.ndarray) -> np.ndarray:
    """The clustered θ_k embedded as the clustering step embedded them (eq. 8–10), unit-free
    (θ_k·rms(φ)/rms(y)) when the step was."""
    theta = local.theta_[step.clustered_]
    if step.unit_free:
        theta = theta * local.phi_scale_[None, :, None] / column_rms(np.asarray(target))
    return EMBEDDINGS[step.embedding](theta)


class ParameterClustersDisplay:
    """The local parameter matrices θ_k as DBSCAN clustered them (step 4), and its ε, in the
    manner of scikit-learn's displays:
    [`from_steps`][pwa_pipeline.plotting.ParameterClustersDisplay.from_steps] draws it, the figure is
    ``figure_``.

    Left: the clustered θ_k (unit-free when the step was, embedded as in eq. 8–10, so that
    distances are those DBSCAN used) projected on their first two principal components,
    coloured by cluster, noise grey; local models left out of the clustering (mixed local
    sets, the subset cap, degenerate ones) are not drawn. Right: the k-distance curve
    (distance of each point to its MinPts-th neighbour, sorted, against the share of points;
    at most 1,000 of them queried, a seeded subset) with ε as a horizontal line; its label
    says whether ε was chosen from the data or given.

    Parameters
    ----------
    local, clustering : the fitted local-model and clustering steps
        (``model.steps_["local_models"]`` and ``["clustering"]`` of a model fitted on the
        paper's route).
    target : ndarray of shape (n, m)
        The training targets y(k) the clustering step was fitted with; their RMS makes θ_k
        unit-free.

    Attributes
    ----------
    figure_ : matplotlib.figure.Figure
        Two axes: the projection and the k-distance curve (after
        [`plot`][pwa_pipeline.plotting.ParameterClustersDisplay.plot]).
    """

    def __init__(self, local, clustering, target: np.ndarray):
        self.local, self.clustering, self.target = local, clustering, np.asarray(target)

    @classmethod
    def from_steps(cls, local, clustering, target: np.ndarray, context: str = ""
                   ) -> ParameterClustersDisplay:
        """The display of the fitted steps, drawn with ``context`` as the title's first
        line."""
        return cls(local, clustering, target).plot(context)

    def plot(self, context: str = "") -> ParameterClustersDisplay:
        """Draw the figure (``figure_``); returns self."""
        step = self.clustering
        emb = _embedding(self.local, step, self.target)
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
        fig = figure(10, 4.0, layout=None)
        ax, ax_k = fig.subplots(1, 2, width_ratios=(1.25, 1))
        listed = []
        for c in np.unique(labels):  # (labels run by decreasing size: small clusters on top)
            rows = labels == c
            dots = ax.scatter(pcs[rows, 0], pcs[rows, 1], s=5 if c < 0 else 7, color=colour(c),
                              alpha=0.5 if c < 0 else 0.8, lw=0, zorder=1 if c < 0 else 2 + c / 100,
                              label=f"noise ({rows.sum()})" if c < 0 else
                              f"cluster {c + 1} ({rows.sum()})")
            if c < len(PALETTE):  # beyond, colours repeat: the rest is one legend line
                listed.append(dots)
        if labels.max() >= len(PALETTE):
            from matplotlib.lines import Line2D

            sizes = np.bincount(labels[labels >= len(PALETTE)])[len(PALETTE):]
            listed.append(Line2D([], [], ls="none", label=(
                f"clusters {len(PALETTE) + 1}–{labels.max() + 1} ({sizes.min()}–{sizes.max()} "
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
        ax_k.axhline(step.eps_, color=DIVERGED, ls="--", lw=1.0,
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
        suptitle(fig, context, "Step 4: local models θ_k in the DBSCAN embedding (PCA) and the "
                                "k-distance curve", y=1 - 0.08 / height, va="top", fontsize=11)
        self.figure_ = fig
        return self
