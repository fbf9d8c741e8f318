"""The switching figure: the region of each output group at each sample of a held-out
experiment ([`SwitchingDisplay`][pwa_pipeline.plotting.SwitchingDisplay])."""

from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..pwa.limits import LIMITED, all_bounds
from ..regressors import lagged_matrix, n_initial, regressor_names
from ..scoring.metrics import match_submodels
from .style import MAX_HEIGHT, MAX_LEVELS, MAX_WIDTH, colour, figure, shown, suptitle

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: A panel title's font size (points).
PANEL_FONT = 8.5
#: Characters of a panel title's line: the axes' width (a figure of ``MAX_WIDTH`` less its
#: margins) at ``PANEL_FONT``, whose characters are about 0.064 inch wide on average.
PANEL_CHARACTERS = int((MAX_WIDTH - 1.2) / 0.064)
#: Height of a panel title's extra line (inches).
TITLE_LINE = 0.15


@dataclass(frozen=True)
class Lane:
    """One output group's region at each sample.

    Attributes
    ----------
    region : ndarray of shape (n,)
        The region of each regressor row (0-based).
    n_regions : int
    outputs : str
        The group's outputs, named.
    structure : str
        Their structures in words (``model.structures_``, without their limits).
    variables : str
        What its regions are the signs of (``z = q1(k-1) − q1(k-2)``), or ``""``.
    limits : str
        Their limits (``"y ≤ 10"``, `pwa_pipeline.pwa.limits`), or ``""``.
    """

    region: np.ndarray
    n_regions: int
    outputs: str
    structure: str
    variables: str = ""
    limits: str = ""


class SwitchingDisplay:
    """The region of each output group (``model.groups_``) at each sample of one
    experiment, in the manner of scikit-learn's displays:
    [`compute`][pwa_pipeline.plotting.SwitchingDisplay.compute] gives the numbers (plain arrays, what the
    pipeline caches), [`plot`][pwa_pipeline.plotting.SwitchingDisplay.plot] draws them (``figure_``),
    [`from_estimator`][pwa_pipeline.plotting.SwitchingDisplay.from_estimator] does both.

    A model of one output group (the paper's route) is one lane: the estimated region H_i
    over time, or, with the true modes of a simulated system, the true mode above and each
    region at the level of the mode it is paired with (× where they disagree), titled with
    the share of samples that agree. A model of several groups is one panel per group,
    titled with its outputs, their structure and what its regions are the signs of; a group
    of one region says so instead of drawing a flat line. At most the first 606 samples are
    shown, and the title says which; a lane of more than 10 regions gets a level for each
    region visited. A model of one region in every group (a linear model, e.g. the one a
    structure search kept) has no switching to draw: its figure says so in its title
    (`NO_SWITCHING`) above each group's structure, without axes.

    Parameters
    ----------
    k : ndarray of shape (n,)
        The sample of each regressor row of the experiment (from max(output lags, nb)).
    lanes : list of Lane
        One per output group.
    true : ndarray of shape (n,), optional
        The true mode of each row (simulated data; one lane only).
    mode_of : ndarray of shape (s,), optional
        The true mode each region is paired with (−1: unpaired), with ``true``.
    n_modes : int, default 0
        True modes.

    Attributes
    ----------
    figure_ : matplotlib.figure.Figure
        After [`plot`][pwa_pipeline.plotting.SwitchingDisplay.plot].
    """

    def __init__(self, k: np.ndarray, lanes: list[Lane], true: np.ndarray | None = None,
                 mode_of: np.ndarray | None = None, n_modes: int = 0):
        self.k, self.lanes = k, list(lanes)
        self.true, self.mode_of, self.n_modes = true, mode_of, n_modes

    @property
    def regions(self) -> list[np.ndarray]:
        """Each lane's regions."""
        return [lane.region for lane in self.lanes]

    @property
    def n_regions(self) -> list[int]:
        """Each lane's region count."""
        return [lane.n_regions for lane in self.lanes]

    @property
    def agreement(self) -> float:
        """Percent of all the experiment's rows whose region is paired with their true mode
        (NaN without the truth)."""
        if self.true is None:
            return float("nan")
        return 100.0 * float(np.mean(self.mode_of[self.lanes[0].region] == self.true))

    @classmethod
    def compute(cls, model, u: np.ndarray, y: np.ndarray, *, y_names: list[str] | None = None,
                u_names: list[str] | None = None, true_modes: np.ndarray | None = None,
                true_thetas: np.ndarray | None = None) -> SwitchingDisplay:
        """The numbers of the figure for a fitted model (any route) on one experiment.

        Each group's region is ``group.regions.predict(φ(k))`` with φ built from (u, y) as
        in eq. (2)–(3) at the model's lags. With the true modes (simulated data, a model of
        one group) its regions are paired with the true sub-models by their parameters
        ([`match_submodels`][pwa_pipeline.scoring.match_submodels]).

        Parameters
        ----------
        model : fitted PWARX or LinearARX
        u : ndarray of shape (N, r)
        y : ndarray of shape (N, m)
        y_names, u_names : list of str, optional
            The channels' names, for the lanes' titles (default ``y1…``, ``u1…``).
        true_modes : ndarray of shape (N,) or (N − max(lags, nb),), optional
            True mode of each sample (0-based), or of each regressor row.
        true_thetas : ndarray of shape (s_true, d, m), optional
            True parameter matrices; required with ``true_modes``.

        Raises
        ------
        ValueError
            ``true_modes`` without ``true_thetas``, for a model of several output groups, or
            of a length that fits neither the samples nor the rows.
        """
        u, y = np.asarray(u, float), np.asarray(y, float)
        lags, nb, affine = model.output_lags_, model.nb, model.affine
        y_names = y_names or [f"y{j + 1}" for j in range(y.shape[1])]
        u_names = u_names or [f"u{q + 1}" for q in range(u.shape[1])]
        phi = lagged_matrix(u, y, lags, nb, affine)
        names = regressor_names(list(y_names), list(u_names), lags, nb, affine)
        lanes = []
        limits = getattr(model, "output_limits_", None)
        for group in model.groups_:
            w = getattr(group.regions, "weights", None)
            lanes.append(Lane(
                region=np.asarray(group.regions.predict(phi)), n_regions=group.n_regions,
                outputs=", ".join(y_names[j] for j in group.outputs),
                structure="; ".join(dict.fromkeys(model.structures_[j].partition(LIMITED)[0]
                                                  for j in group.outputs)),
                variables="" if w is None else ", ".join(
                    f"z{v + 1 if len(w) > 1 else ''} = {_combination(row, names)}"
                    for v, row in enumerate(w)),
                limits=all_bounds(limits, y_names, group.outputs)))
        k = np.arange(n_initial(lags, nb), y.shape[0])
        if true_modes is None:
            return cls(k, lanes)
        if true_thetas is None:
            raise ValueError("true_thetas is needed with true_modes (to pair regions with modes)")
        if len(lanes) > 1:
            raise ValueError("true modes pair with the regions of a model of one output group; "
                             f"this one has {len(lanes)}")
        true = np.asarray(true_modes)
        if true.shape[0] == y.shape[0]:
            true = true[k[0]:]
        if true.shape[0] != phi.shape[0]:
            raise ValueError(f"true_modes has {np.asarray(true_modes).shape[0]} entries; "
                             f"expected {y.shape[0]} (one per sample) or {phi.shape[0]} (one "
                             f"per row)")
        mode_of = match_submodels(model.thetas_, np.asarray(true_thetas))[0]
        return cls(k, lanes, true, np.asarray(mode_of), np.asarray(true_thetas).shape[0])

    @classmethod
    def from_estimator(cls, model, u: np.ndarray, y: np.ndarray, *, context: str = "",
                       **kwargs) -> SwitchingDisplay:
        """[`compute`][pwa_pipeline.plotting.SwitchingDisplay.compute] (whose keyword parameters these are)
        then [`plot`][pwa_pipeline.plotting.SwitchingDisplay.plot]."""
        return cls.compute(model, u, y, **kwargs).plot(context)

    @property
    def switches(self) -> bool:
        """Whether any output group has more than one region (the model is piecewise)."""
        return any(s > 1 for s in self.n_regions)

    @property
    def held(self) -> str:
        """The outputs' limits in words, a line of its own at a title's end (``"\noutputs
        held at their limits (y ≤ 10)"``: the titles are already a figure's width), empty
        without any."""
        limits = ", ".join(lane.limits for lane in self.lanes if lane.limits)
        return f"\noutputs held at their limits ({limits})" if limits else ""

    def plot(self, context: str = "") -> SwitchingDisplay:
        """Draw the figure (``figure_``) with ``context`` (data set, set, method) as the
        title's first line; returns self. A model of one region per output group (a
        linear model) gets a line saying so, and its structure, in place of lanes with
        nothing to draw."""
        one = len(self.lanes) == 1 and not self.lanes[0].variables
        if not self.switches and self.true is None:
            self.figure_ = _no_switching(self, context)
        else:
            self.figure_ = _one_lane(self, context) if one else _panels(self, context)
        return self


#: The title of the switching figure of a model with one region per output group.
NO_SWITCHING = "No switching: one mode (a single linear model) at every sample"


def _no_switching(sw: SwitchingDisplay, context: str) -> Figure:
    """The figure of a model without switching: its title says so, its body each output
    group's structure, and no axes (there is no region to draw over the samples)."""
    fig = figure(MAX_WIDTH, 1.2 + 0.25 * len(sw.lanes) + (0.3 if context else 0.0)
                 + (0.25 if sw.held else 0.0))
    lines = [f"{lane.outputs}: {lane.structure}" for lane in sw.lanes]
    fig.text(0.5, 0.35, "\n".join(lines), ha="center", va="center", fontsize=9, color="0.3")
    suptitle(fig, context, f"{NO_SWITCHING}, held-out experiment 1 ({sw.k.size} samples)"
                           f"{sw.held}", fontsize=11)
    return fig


def _one_lane(sw: SwitchingDisplay, context: str) -> Figure:
    """The figure of a model of one output group (with the true modes when given)."""
    k, region, s = sw.k, sw.regions[0], sw.n_regions[0]
    rows, which = shown(k)
    if sw.true is None:
        fig = figure(MAX_WIDTH, 2.8 if context else 2.6)
        ax = fig.subplots()
        # more regions than labels fit: a level for each region visited, every n-th labelled
        levels = np.arange(s) if s <= MAX_LEVELS else np.unique(region[rows])
        ax.scatter(k[rows], np.searchsorted(levels, region[rows]),
                   c=[colour(r) for r in region[rows]], marker="|", s=60, lw=1.2)
        ticks = np.arange(0, levels.size, -(-levels.size // MAX_LEVELS))
        ax.set_yticks(ticks, [f"H{levels[i] + 1}" for i in ticks])
        ax.set_ylim(-0.6, levels.size - 0.4)
        ax.set_ylabel("estimated region" if levels.size == s else
                      f"estimated region\n({levels.size} of {s} visited)")
        ax.set_xlabel("sample k")
        suptitle(fig, context, "Estimated region H_i, held-out experiment 1"
                                + (which or f", all {k.size} samples") + sw.held, fontsize=11)
        return fig
    true, mode_of, s_true = sw.true, sw.mode_of, sw.n_modes
    mapped = mode_of[region]
    # Paired regions sit at the level of their mode (as in the panel above), unpaired
    # regions above them.
    level = mode_of.copy()
    level[mode_of < 0] = s_true + np.arange(np.sum(mode_of < 0))
    n_levels = max(s_true, int(level.max()) + 1)
    fig = figure(MAX_WIDTH, 4.6 if context else 4.4)
    ax_true, ax = fig.subplots(2, 1, sharex=True)
    ax_true.scatter(k[rows], true[rows], c=[colour(t) for t in true[rows]], marker="|",
                    s=60, lw=1.2)
    ax_true.set_yticks(range(s_true), [f"mode {i + 1}" for i in range(s_true)])
    ax_true.set_ylabel("true")
    ax.scatter(k[rows], level[region[rows]], c=[colour(t) for t in mapped[rows]],
               marker="|", s=60, lw=1.2)
    wrong = rows & (mapped != true)
    ax.plot(k[wrong], level[region[wrong]], "x", color="black", ms=4, mew=0.8, ls="none",
            label=f"disagrees with the true mode ({wrong.sum()} of the {rows.sum()} samples "
                  f"shown)")
    ax.set_yticks(level, [f"H{i + 1} ≙ mode {mode_of[i] + 1}" if mode_of[i] >= 0
                          else f"H{i + 1} (unpaired)" for i in range(s)])
    for a in (ax_true, ax):
        a.set_ylim(-0.6, n_levels - 0.4)
    ax.set_ylabel("estimated")
    ax.set_xlabel("sample k")
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.28), fontsize=8, frameon=False)
    suptitle(fig, context, f"Estimated region vs true mode, held-out experiment 1: agreement "
                            f"{sw.agreement:.1f} % over all {k.size} samples"
                            + (f", the first {rows.sum()} shown" if which else "") + sw.held,
             fontsize=11)
    return fig


def _panels(sw: SwitchingDisplay, context: str) -> Figure:
    """One panel per output group, its region at each of the first 606 samples; the panels
    share the sample axis and fit a laptop screen."""
    k = sw.k
    rows, which = shown(k)
    m = len(sw.regions)
    levels = [np.arange(s) if s <= MAX_LEVELS else np.unique(r[rows])
              for r, s in zip(sw.regions, sw.n_regions, strict=True)]
    titles = [_panel_title(lane) for lane in sw.lanes]
    heights = [0.3 + 0.22 * max(lv.size, 1) + TITLE_LINE * title.count("\n")
               for lv, title in zip(levels, titles, strict=True)]
    body = min(sum(heights), MAX_HEIGHT - 1.3)
    fig = figure(MAX_WIDTH, body + 1.3)
    axes = fig.subplots(m, 1, sharex=True, squeeze=False, height_ratios=heights)[:, 0]
    for j, ax in enumerate(axes):
        region, s, lv = sw.lanes[j].region, sw.lanes[j].n_regions, levels[j]
        if s == 1:
            ax.text(0.5, 0.5, "one region: a single linear model at every sample",
                    transform=ax.transAxes, ha="center", va="center", fontsize=8,
                    color="0.35")
            ax.set_yticks([])
            ax.set_ylim(-0.6, 0.6)
        else:
            ax.scatter(k[rows], np.searchsorted(lv, region[rows]),
                       c=[colour(r) for r in region[rows]], marker="|", s=40, lw=1.0)
            labels = _sign_labels(s) if sw.lanes[j].variables and s & (s - 1) == 0 else [
                f"H{r + 1}" for r in range(s)]
            ticks = np.arange(0, lv.size, -(-lv.size // MAX_LEVELS))
            ax.set_yticks(ticks, [labels[lv[i]] for i in ticks], fontsize=7.5)
            ax.set_ylim(-0.6, lv.size - 0.4)
        ax.set_title(titles[j], fontsize=PANEL_FONT, loc="left", pad=2)
    axes[-1].set_xlabel("sample k")
    suptitle(fig, context, "Region of each output group's model, held-out experiment 1"
                            + (which or f", all {k.size} samples") + sw.held, fontsize=11)
    return fig


def _panel_title(lane: Lane) -> str:
    """A panel's title: its outputs, their structure and what its regions are the signs
    of, wrapped to the figure's width (an oblique boundary's combination is long). Where
    the signs are written out, the structure's own list of its boundaries (``… all on
    [ŷ1: y1(k-1) + … > 8.566, …]``, in the model's names y1, u1) is left out: the signs
    say the same in the data's names."""
    if lane.variables and lane.n_regions > 1:
        structure = re.sub(r" (on|at) \[.*\]", "", lane.structure)
        text = f"{lane.outputs}: {structure}, regions by the sign of {lane.variables}"
    else:
        text = f"{lane.outputs}: {lane.structure}"
    return textwrap.fill(text, PANEL_CHARACTERS)


def _combination(weights: np.ndarray, names: list[str]) -> str:
    """``w·φ`` written out, e.g. ``q1(k-1) − q1(k-2)``; the constant entry ``1`` as its
    coefficient alone, to 4 digits as the structures write a threshold
    (``q1(k-1) − 8.471``)."""
    terms = []
    for w, name in zip(weights, names, strict=True):
        if w == 0:
            continue
        sign = "−" if w < 0 else "+"
        if name == "1":  # to 4 digits, as the structures write a threshold
            terms.append(f"{sign} {abs(w):.4g}")
            continue
        size = "" if abs(w) == 1 else f"{abs(w):.3g}·"
        terms.append(f"{sign} {size}{name}")
    text = " ".join(terms)  # the first term's sign joined to it: "x", "−x", not "+ x", "− x"
    if text.startswith(("+ ", "− ")):
        return text[2:] if text[0] == "+" else "−" + text[2:]
    return text


def _sign_labels(n_regions: int) -> list[str]:
    """Region labels of sign regions: ``z ≤ 0``, ``z > 0`` for one variable, the signs of
    each for more (region Σ_v 2^v [z_v > 0])."""
    v = int(np.log2(n_regions))
    if v == 1:
        return ["z ≤ 0", "z > 0"]
    return [", ".join(f"z{b + 1} {'>' if r >> b & 1 else '≤'} 0" for b in range(v))
            for r in range(n_regions)]
