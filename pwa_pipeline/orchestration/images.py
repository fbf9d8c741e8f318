"""Figures as the pages show them: PNG bytes within a size, inlined in Markdown for
Dagster's metadata (the figures themselves are drawn by `pwa_pipeline.plotting`)."""

from __future__ import annotations

import base64
import functools
import io
from pathlib import Path
from typing import TYPE_CHECKING

from .caches import source_fingerprint

if TYPE_CHECKING:
    from matplotlib.figure import Figure


@functools.cache
def figures_fingerprint() -> str:
    """Hash of the plotting package's source: part of the key of cached figure numbers, so
    that numbers computed by other code are never drawn."""
    package = Path(__file__).resolve().parents[1] / "plotting"
    return source_fingerprint(list(package.glob("*.py")))


def to_png(fig: Figure, width: int | None = None, max_bytes: int = 300_000) -> bytes:
    """The figure as PNG bytes, at most ``max_bytes`` (the PNG of `to_markdown`).

    Saved at 90 dpi by default, where the figures of `pwa_pipeline.plotting` are at most 900 × 650 px
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
    ``dagster.MetadataValue.md``: `png_markdown` of its `to_png`, the suptitle as
    alternative text.

    Parameters
    ----------
    fig : Figure
    width, max_bytes
        As in `to_png`.
    """
    return png_markdown(to_png(fig, width, max_bytes), fig.get_suptitle() or "figure")


def png_markdown(png: bytes, alt: str) -> str:
    """A rendered PNG as a Markdown image inlined in base64:
    ``![<alt>](data:image/png;base64,...)`` (brackets in ``alt`` made parentheses)."""
    alt = " ".join(alt.replace("[", "(").replace("]", ")").split())
    return f"![{alt}](data:image/png;base64,{base64.b64encode(png).decode('ascii')})"
