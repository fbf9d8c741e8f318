"""What every figure of `pwa_pipeline.plotting` shares: sizes that fit a laptop screen,
one colour per sub-model, and titles that say what a figure shows.

- Every title opens with the line `context_title` (data set, hyper-parameter set and
  method), so that a figure seen alone in MLflow or a screenshot says what it shows.
- Axes carry the data's units, ``name [unit]``.
- Every figure fits a laptop screen (about 1366 × 768) at 90 dpi: at most `MAX_WIDTH`
  inches (900 px) wide and `MAX_HEIGHT` inches (650 px) high.
- Sub-model / region / cluster i is `colour` (i) in every figure; DBSCAN noise grey.

Figures are built without pyplot (no global state, no display), matplotlib imported only
when one is drawn: the library imports without it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._optional import require

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: Samples shown of one experiment (one KUKA robot experiment).
MAX_SAMPLES = 606
#: Largest figure height in inches: 650 px at 90 dpi, which leaves a 768-pixel laptop
#: screen room for the browser and the page around the figure.
MAX_HEIGHT = 650 / 90
#: Largest figure width in inches: 900 px at 90 dpi.
MAX_WIDTH = 10.0
#: tab10 without its grey (grey is DBSCAN noise) and its red (red flags a diverged run).
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#bcbd22",
           "#17becf")
NOISE = "#9a9a9a"
DIVERGED = "#d62728"
#: Regions a switching lane labels on its axis without overlap.
MAX_LEVELS = 10


def context_title(dataset: str, hparams: str, method: str) -> str:
    """The first line of every figure's title: ``<data set> | set <set> | <method>``.

    Parameters
    ----------
    dataset, hparams : str
        The data set and hyper-parameter set.
    method : str
        The method's label (`pwa_pipeline.methods.Method.label`).

    Examples
    --------
    >>> context_title("kuka_robot", "default", "PWA")
    'kuka_robot | set default | PWA'
    """
    return f"{dataset} | set {hparams} | {method}"


def suptitle(fig: Figure, context: str, what: str, **kwargs) -> None:
    """``context`` (`context_title`) above ``what`` as the figure's title; ``what``
    alone without a context."""
    fig.suptitle(f"{context}\n{what}" if context else what, **kwargs)


def colour(i: int) -> str:
    """Colour of sub-model / region / cluster ``i`` (0-based); grey for −1 (noise)."""
    return NOISE if i < 0 else PALETTE[i % len(PALETTE)]


def figure(width: float, height: float, layout: str | None = "constrained") -> Figure:
    """A matplotlib figure of that size in inches, outside pyplot."""
    figures = require("matplotlib.figure", "plot", "Drawing a figure")
    return figures.Figure(figsize=(width, height), layout=layout)


def legend_below(fig: Figure) -> None:
    """One legend for every axes of ``fig`` (each label once, in the order first drawn),
    below them in at most two rows, so that it never covers data and leaves the axes the
    figure's whole width."""
    entries: dict[str, object] = {}
    for ax in fig.axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    fig.legend(list(entries.values()), list(entries), loc="outside lower center", fontsize=8,
               frameon=False, ncols=min(len(entries), 4))


def shown(k: np.ndarray) -> tuple[np.ndarray, str]:
    """The rows of the samples shown (those before `MAX_SAMPLES`), and what a title
    says of them: ``""`` when all are shown, else ``", the first 605 of 3999 samples
    shown"``."""
    rows = k < MAX_SAMPLES
    if rows.all():
        return rows, ""
    return rows, f", the first {rows.sum()} of {k.size} samples shown"
