"""Figures for a page or a paper: one style, and every figure saved as PNG, SVG and PDF.

``save_figure(fig, "x.png")`` writes ``x.png`` (for Markdown), ``x.svg`` (the HTML report inlines
it) and ``x.pdf`` (for a paper) side by side, each cropped to what is drawn.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: The formats every figure is written in, the first one being the path the caller names.
FORMATS = ("png", "svg", "pdf")
DPI = 150
_NO_DATE: dict[str, dict[str, Any]] = {".svg": {"Date": None}, ".pdf": {"CreationDate": None}}


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (no display), with the figures' shared style."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update(
        {
            "font.size": 9,
            "axes.titlesize": 9,
            "axes.labelsize": 9,
            "legend.fontsize": 8,
            "axes.spines.top": False,
            "axes.spines.right": False,
            "axes.grid": True,
            "grid.alpha": 0.3,
            # SVG text stays text (searchable, small); the PDF embeds TrueType fonts.
            "svg.fonttype": "none",
            "pdf.fonttype": 42,
            # No creation date in the SVG or PDF: the same data gives the same bytes.
            "svg.hashsalt": "objsearch",
        }
    )
    return plt


def save_figure(fig: Any, png: Path) -> list[Path]:
    """Write ``fig`` as ``png`` and as SVG and PDF beside it; close it; return the paths."""
    plt = pyplot()
    paths = [png.with_suffix(f".{fmt}") for fmt in FORMATS]
    for path in paths:
        meta = _NO_DATE.get(path.suffix, {})
        fig.savefig(path, dpi=DPI, bbox_inches="tight", pad_inches=0.05, metadata=meta)
    plt.close(fig)
    return paths


__all__ = ["FORMATS", "pyplot", "save_figure"]
