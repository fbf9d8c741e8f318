"""The prediction figure: measured output, one-step prediction and free run of a held-out
experiment ([`PredictionDisplay`][pwa_pipeline.plotting.PredictionDisplay])."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from ..datasets.dataset import with_unit
from ..scoring.evaluation import score_text
from .style import DIVERGED, MAX_HEIGHT, MAX_SAMPLES, MAX_WIDTH, figure, legend_below, suptitle

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from ..datasets import Dataset
    from ..scoring.evaluation import Evaluation

#: Most outputs stacked in one column; more go in further columns.
_GRID_ROWS = 3
#: Inches of each row.
_ROW_HEIGHT = 1.9
_OUTSIDE = {"one_step": ("one-step", "C0", "\\\\\\"), "free_run": ("free run", "C1", "///")}
"""Label, colour and hatch of the stretches where a mode's regressor leaves the data
envelope (hatched, so that they are not read as the free run's solid out-of-range
shading)."""
_Z_ONE_STEP, _Z_FREE, _Z_MEASURED = 2.0, 2.5, 3.0
"""Drawing order of the lines: the measured output on top."""


def clip_range(measured: np.ndarray) -> tuple[float, float]:
    """The measured range widened by 50 % of its span on each side (where runs are clipped)."""
    lo, hi = float(np.min(measured)), float(np.max(measured))
    span = hi - lo if hi > lo else max(abs(hi), 1.0)
    return lo - 0.5 * span, hi + 0.5 * span


class PredictionDisplay:
    """Measured output, one-step prediction and free run of the first held-out experiment
    of an evaluation ([`evaluate`][pwa_pipeline.scoring.evaluate]), in the manner of
    scikit-learn's displays: [`from_evaluation`][pwa_pipeline.plotting.PredictionDisplay.from_evaluation]
    builds and draws it, the figure is ``figure_``.

    One subplot per output, over the experiment's first 606 samples at most (one KUKA robot
    experiment), each titled with that output's one-step and free-run NRMSE (eq. 21, 4
    significant digits; a diverged free run's as `score_text` shows it,
    ``≥ 10 (diverged)``) and its y axis labelled ``name [unit]``. Up to three outputs are
    stacked; more are laid out three rows high in further columns (the robot's six in
    3 × 2).

    The measured output is drawn last, on top (a thin black line), the one-step prediction
    under it as a wider, light blue band. A free run flagged diverged, or with non-finite
    values, is drawn in red as "free run (diverged, clipped)": clipped to the measured range
    ± 50 % of its span, the line stops at the edge where the run leaves that range (a
    triangle marks each exit, the time outside is shaded). The warm-up window, excluded from
    the scores, is shaded grey. The stretches where a mode's regressor leaves the model's
    data envelope (``evaluation.outside``) are hatched in that mode's colour, and the
    title's third line gives each mode's share of scored samples outside it when one is
    above 0. One legend below the axes lists what any subplot draws.

    Parameters
    ----------
    evaluation : Evaluation
    y : ndarray of shape (N, m)
        The measured outputs of the first held-out experiment.
    y_names : list of str
    n_experiments : int
        Held-out experiments of the evaluation (for the title).
    warmup : int
        Warm-up samples of the evaluation.
    units : mapping of str to str, optional
        The unit of each channel that has one.

    Attributes
    ----------
    figure_ : matplotlib.figure.Figure
        One axes per output (after [`plot`][pwa_pipeline.plotting.PredictionDisplay.plot]).
    """

    def __init__(self, evaluation: Evaluation, y: np.ndarray, y_names: list[str],
                 n_experiments: int, warmup: int, units: Mapping[str, str] | None = None):
        self.evaluation, self.y, self.y_names = evaluation, np.asarray(y), list(y_names)
        self.n_experiments, self.warmup, self.units = n_experiments, warmup, dict(units or {})

    @classmethod
    def from_evaluation(cls, evaluation: Evaluation, data: Dataset, warmup: int,
                        context: str = "") -> PredictionDisplay:
        """The display of ``evaluation`` on ``data``'s held-out experiments (its ``y_test``,
        ``y_names`` and ``units``), drawn with ``context``
        (`context_title`) as the title's first line."""
        return cls(evaluation, data.y_test[0], data.y_names, len(data.y_test), warmup,
                   data.units).plot(context)

    def plot(self, context: str = "") -> PredictionDisplay:
        """Draw the figure (``figure_``); returns self."""
        ev = self.evaluation
        n = min(self.y.shape[0], MAX_SAMPLES)
        y = self.y[:n]
        m = y.shape[1]
        table = ev.table[ev.table["output"] != "mean"]
        rows = {mode: table[table["mode"] == mode] for mode in ("one_step", "free_run")}
        n_cols = -(-m // _GRID_ROWS)
        n_rows = -(-m // n_cols)
        fig = figure(MAX_WIDTH, min(_ROW_HEIGHT * n_rows + 1.15, MAX_HEIGHT))
        grid = fig.subplots(n_rows, n_cols, sharex=True, squeeze=False)
        axes = list(grid.T.ravel()[:m])  # down the first column, then the next
        for ax in grid.T.ravel()[m:]:  # cells left over in the last column
            ax.remove()
        for c in range(n_cols):  # the lowest axes of each column shows the sample axis
            bottom = axes[min((c + 1) * n_rows, m) - 1]
            bottom.xaxis.set_tick_params(labelbottom=True)
            bottom.set_xlabel("sample k")
        k = np.arange(n)
        outside = {mode: np.asarray(flags[0][:n], bool)
                   for mode, flags in (ev.outside or {}).items()
                   if mode in _OUTSIDE and np.any(flags[0][:n])}
        for j, ax in enumerate(axes):
            one, free_row = rows["one_step"].iloc[j], rows["free_run"].iloc[j]
            free = ev.predictions["free_run"][0][:n, j]
            diverged = bool(free_row["diverged"]) or not np.isfinite(free).all()
            ax.axvspan(0, self.warmup, color="0.85", alpha=0.6, lw=0, label="warm-up")
            # (listed first in the legend, drawn last: the z-order decides what lies on top)
            ax.plot(k, y[:, j], color="black", lw=0.9, zorder=_Z_MEASURED, label="measured")
            ax.plot(k, ev.predictions["one_step"][0][:n, j], color="C0", lw=3.0, alpha=0.5,
                    solid_capstyle="butt", zorder=_Z_ONE_STEP, label="one-step")
            _free_run(ax, k, free, y[:, j], diverged)
            for mode, mask in outside.items():
                label, tint, hatch = _OUTSIDE[mode]
                # each flagged sample k covers [k − ½, k + ½], so that a lone one shows too
                ax.fill_between(np.repeat(k, 2) + np.tile([-0.5, 0.5], n), 0, 1,
                                where=np.repeat(mask, 2), transform=ax.get_xaxis_transform(),
                                facecolor="none", edgecolor=tint, hatch=hatch, lw=0,
                                alpha=0.45, label=f"{label} outside the training data")
            ax.set_title(f"{self.y_names[j]}: NRMSE one-step {one['nrmse']:.4g}, free run "
                         f"{score_text(free_row['nrmse'], 'nrmse', diverged)}",
                         fontsize=8.5, loc="left")
            ax.set_ylabel(with_unit(self.y_names[j], self.units))
            ax.set_xlim(0, n - 1)
        legend_below(fig)
        which = f"samples 0–{n - 1}" + (f" of {self.y.shape[0]}" if n < len(self.y) else "")
        suptitle(fig, context, f"Measured output, one-step prediction and free run: held-out "
                               f"experiment 1 of {self.n_experiments}, {which}"
                               + _outside_line(ev), fontsize=11)
        self.figure_ = fig
        return self


def _free_run(ax: Axes, k: np.ndarray, free: np.ndarray, measured: np.ndarray,
              diverged: bool) -> None:
    """Draw a free run clipped to `clip_range`: the line reaches the edge where the run
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
    tint = DIVERGED if diverged else "C1"
    ax.plot(k, line, color=tint, lw=1.0, zorder=_Z_FREE,
            label="free run (diverged, clipped)" if diverged else "free run (clipped)")
    if out.any():
        ax.fill_between(k, 0, 1, where=out, transform=ax.get_xaxis_transform(), step="mid",
                        color=tint, alpha=0.10, lw=0,
                        label=f"{'diverged ' if diverged else ''}free run out of range")
        exits = out & ~np.r_[False, out[:-1]]
        for side, edge, marker in ((above, hi, "^"), (below, lo, "v")):
            at = exits & side
            if at.any():  # (an empty unclipped line would stretch the layout to the origin)
                ax.plot(k[at], np.full(at.sum(), edge), marker, color=tint, ms=6,
                        ls="none", clip_on=False, zorder=_Z_FREE)
    pad = 0.03 * (hi - lo)
    ax.set_ylim(lo - pad, hi + pad)


def _outside_line(evaluation: Evaluation) -> str:
    """The title line of each mode's share of scored samples outside the data envelope
    (``outside_share``), or "" when none is above 0 or known."""
    if "outside_share" not in evaluation.table:
        return ""
    means = evaluation.table[evaluation.table["output"] == "mean"].set_index("mode")
    shares = {mode: float(means.loc[mode, "outside_share"]) for mode in _OUTSIDE
              if mode in means.index}
    listed = [f"{_OUTSIDE[mode][0]} {100 * v:.3g} %" for mode, v in shares.items()]
    if not any(np.isfinite(v) and v > 0 for v in shares.values()):
        return ""
    return ("\nRegressor outside the training data (hatched): " + ", ".join(listed)
            + " of the scored samples")
