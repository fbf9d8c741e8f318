"""The partition figure: a PWA state-space model's polyhedral regions in a 2-D slice of
z = [x; u] ([`PartitionDisplay`][pwa_pipeline.plotting.PartitionDisplay])."""

from __future__ import annotations

import textwrap

import numpy as np

from .style import colour, figure, suptitle

#: Entries of a legend column.
_LEGEND_ROWS = 22


class PartitionDisplay:
    """The polyhedral partition of a PWA state-space model
    ([`PWAStateSpace`][pwa_pipeline.control.PWAStateSpace]) in a 2-D slice of z = [x; u], drawn from
    the H-representations of its regions (not from a classifier), in the manner of
    scikit-learn's displays: [`from_state_space`][pwa_pipeline.plotting.PartitionDisplay.from_state_space]
    draws it, the figure is ``figure_``.

    The two coordinates are those the region boundaries lean on most (largest sum over the
    rows of |H_c| times the envelope's half-width in c, rows normalised); the others are held
    at ``fixed``. Each region's slice {(a, b) : H_ab (a, b) ≤ h − H_rest z_rest} is cut with
    the envelope and drawn as its polygon (vertices by half-space intersection around its
    Chebyshev centre); modes whose slice is empty are listed as such.

    Parameters
    ----------
    state_space : PWAStateSpace
    fixed : ndarray of shape (n + r,)
        Where the other coordinates are held (e.g. the median training z).
    labels : list of str, optional
        Axis label of each coordinate of z (default the state's and inputs' names).

    Attributes
    ----------
    figure_ : matplotlib.figure.Figure
        One axes (after [`plot`][pwa_pipeline.plotting.PartitionDisplay.plot]).
    """

    def __init__(self, state_space, fixed: np.ndarray, labels: list[str] | None = None):
        self.state_space, self.fixed, self.labels = state_space, np.asarray(fixed), labels

    @classmethod
    def from_state_space(cls, state_space, fixed: np.ndarray, context: str = "",
                         labels: list[str] | None = None) -> PartitionDisplay:
        """The display drawn with ``context`` (data set, set, method) as the title's first
        line."""
        return cls(state_space, fixed, labels).plot(context)

    def plot(self, context: str = "") -> PartitionDisplay:
        """Draw the figure (``figure_``); returns self."""
        from matplotlib.patches import Polygon
        from scipy.optimize import linprog
        from scipy.spatial import HalfspaceIntersection

        ss, fixed, labels = self.state_space, self.fixed, self.labels
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
        fig = figure(9.0, 5.6)
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
            ax.add_patch(Polygon(vertices[order], closed=True, facecolor=colour(mode), alpha=0.35,
                                 edgecolor=colour(mode), lw=1.2, label=f"mode {mode + 1}"))
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
            what += (f"\n{len(empty)} of {ss.n_modes} modes "
                     f"{'does' if len(empty) == 1 else 'do'} not meet this slice")
        suptitle(fig, context, what, fontsize=10)
        self.figure_ = fig
        return self
