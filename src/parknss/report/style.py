"""Shared figure helpers: a headless backend, reverse-gear shading, saving, and
:func:`figure`, a figure without pyplot (whose import costs a command ~0.3 s)."""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np

from parknss.outputs import atomic_file


def shade_reverse(ax, t: np.ndarray, gear: np.ndarray, color: str = "0.85") -> None:
    """Shade the time spans where gear == -1 on a matplotlib axis. t in s, shape (T,)."""
    rev = np.asarray(gear) < -0.5
    if not rev.any():
        return
    edges = np.flatnonzero(np.diff(np.concatenate([[0], rev.astype(int), [0]])))
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        ax.axvspan(t[start], t[min(stop, len(t) - 1)], color=color, lw=0, zorder=0)


def figure(figsize: tuple[float, float]):
    """A matplotlib Figure on the Agg canvas, not registered with pyplot (close is a
    no-op for it; it goes when it is no longer referenced)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def save(fig, path: str | Path, dpi: int = 120) -> Path:
    """Save a figure as PNG (creating folders; atomically, so an earlier figure at
    ``path`` stays whole if saving fails) and close it."""
    p = Path(path)
    try:
        with atomic_file(p) as tmp:
            fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    finally:
        plt = sys.modules.get("matplotlib.pyplot")  # a pyplot figure is closed
        if plt is not None:
            plt.close(fig)
    return p
