"""The regions figure: a fitted model's regions in the 2-D slice of φ where they differ
most ([`RegionsDisplay`][pwa_pipeline.plotting.RegionsDisplay])."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..datasets.dataset import with_unit
from .style import MAX_WIDTH, colour, figure, suptitle

#: Entries of a legend column (more fit beside the 5.2-inch axes).
_LEGEND_ROWS = 22
#: Legend columns at most: the axes and their legend within ``MAX_WIDTH``.
_LEGEND_COLUMNS = 3


@dataclass
class RegionsDisplay:
    """The regions H_i of a fitted model as eq. (1) (``model.regions_``) in a 2-D slice of
    φ, in the manner of scikit-learn's displays: [`compute`][pwa_pipeline.plotting.RegionsDisplay.compute]
    gives the numbers (plain arrays, what the pipeline caches),
    [`plot`][pwa_pipeline.plotting.RegionsDisplay.plot] draws them (``figure_``),
    [`from_estimator`][pwa_pipeline.plotting.RegionsDisplay.from_estimator] does both.

    The regions are filled, and training rows drawn on top coloured by their sub-model
    (−1 grey). Rows lie off the slice in the other regressors, so some sit in a region other
    than their own. A long legend takes further columns to the right, the figure widened for
    each (at most 900 px at 90 dpi); one longer than three columns (a model of several
    output groups has the product of their regions) lists the regions the slice shows and
    the rows in one entry.

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
        Their sub-model (−1 noise).
    d : int
        Regressors in φ.
    figure_ : matplotlib.figure.Figure
        After [`plot`][pwa_pipeline.plotting.RegionsDisplay.plot].
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

    @classmethod
    def compute(cls, model, phi: np.ndarray, labels: np.ndarray | None = None,
                max_points: int = 3000) -> RegionsDisplay:
        """The numbers of the figure: the slice where the regions differ most.

        The two regressors are those along which the region boundaries vary most: the
        largest coefficient of that regressor over every boundary of every output group's
        regions (``halfspaces()``) times the regressor's standard deviation in ``phi`` (for
        the SVM's argmax regions, the spread of its ``coef_`` column); the others are held
        at their median. The regions are evaluated on a 200 × 200 grid over the 0.5–99.5 %
        range of the two regressors (widened by 5 %), and at most ``max_points`` training
        rows (a seeded subset) are kept with their label.

        Parameters
        ----------
        model : fitted PWARX or LinearARX (any route)
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
        return cls(int(i), int(j), gx, gy, z, int(regions.n_regions_), phi[rows][:, [i, j]],
                       labels[rows], phi.shape[1])

    @classmethod
    def from_estimator(cls, model, phi: np.ndarray, names: list[str], *,
                       labels: np.ndarray | None = None, max_points: int = 3000,
                       context: str = "", units: Mapping[str, str] | None = None
                       ) -> RegionsDisplay:
        """[`compute`][pwa_pipeline.plotting.RegionsDisplay.compute] then
        [`plot`][pwa_pipeline.plotting.RegionsDisplay.plot] (whose parameters these are)."""
        if len(names) != np.shape(phi)[1]:
            raise ValueError(f"{len(names)} names for {np.shape(phi)[1]} regressors")
        return cls.compute(model, phi, labels, max_points).plot(names, context, units)

    def plot(self, names: list[str], context: str = "",
             units: Mapping[str, str] | None = None) -> RegionsDisplay:
        """Draw the figure (``figure_``); returns self.

        Parameters
        ----------
        names : list of str
            The d regressor names (`regressor_names`).
        context : str, optional
            The title's first line (data set, set, method).
        units : mapping of str to str, optional
            Channel units: the axes read ``q1(k-1) [deg]``.

        Raises
        ------
        ValueError
            ``names`` not of the slice's d regressors.
        """
        if len(names) != self.d:
            raise ValueError(f"{len(names)} names for {self.d} regressors")
        units = units or {}
        s, labels = self.n_regions, self.labels
        kinds, in_slice = np.unique(labels), np.unique(self.z)
        # every region and every sub-model's rows when they fit in _LEGEND_COLUMNS columns;
        # past that (a search's model of several groups has the product of their regions,
        # e.g. 192) the regions the slice shows, and the rows in one entry
        listed = s + kinds.size <= _LEGEND_COLUMNS * _LEGEND_ROWS
        shown = np.arange(s) if listed else in_slice[:_LEGEND_COLUMNS * _LEGEND_ROWS - 1]
        columns = -(-(shown.size + (kinds.size if listed else 1)) // _LEGEND_ROWS)
        fig = figure(min(7.4 + 1.3 * (columns - 1), MAX_WIDTH), 5.2)
        ax = fig.subplots()
        ax.contourf(self.gx, self.gy, self.z, levels=np.arange(s + 1) - 0.5,
                    colors=[colour(r) for r in range(s)], alpha=0.25)
        from matplotlib.patches import Patch

        handles = [Patch(color=colour(r), alpha=0.4, label=f"H{r + 1}") for r in shown]
        for c in kinds:
            at = labels == c
            dots = ax.scatter(self.points[at, 0], self.points[at, 1], s=6, color=colour(c),
                              lw=0.2, edgecolor="black", alpha=0.8,
                              label="noise" if c < 0 else f"rows of θ{c + 1}")
            if listed:
                handles.append(dots)
        if not listed:
            handles.append(ax.scatter([], [], s=6, color="0.5", lw=0.2, edgecolor="black",
                                      label="training rows, coloured by\nsub-model "
                                            "(colours repeat)"))
        ax.set_xlim(self.gx.min(), self.gx.max())
        ax.set_ylim(self.gy.min(), self.gy.max())
        ax.set_xlabel(with_unit(names[self.i], units))
        ax.set_ylabel(with_unit(names[self.j], units))
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
                  frameon=False, ncols=columns,
                  title=None if listed else f"{in_slice.size} of {s} regions\nin this slice",
                  title_fontsize=8)
        others = "others at their median" if self.d > 2 else "no other regressors"
        suptitle(fig, context, f"Step 6: regions H_i in the slice ({names[self.i]}, {names[self.j]}), "
                                f"{others}", fontsize=10)
        self.figure_ = fig
        return self
