"""Shared figure helpers: a headless backend, reverse-gear shading, saving."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
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


def save(fig, path: str | Path, dpi: int = 120) -> Path:
    """Save a figure as PNG (creating folders; atomically, so an earlier figure at
    ``path`` stays whole if saving fails) and close it."""
    p = Path(path)
    try:
        with atomic_file(p) as tmp:
            fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
    return p
