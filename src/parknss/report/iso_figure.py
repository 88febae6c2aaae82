"""Fig. 7: box plot of the ISO/TS 18571 ratings per channel, raw and filtered."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from parknss.metrics.rating_report import RatingTable
from parknss.report.style import save

CHANNEL_LABELS: dict[str, str] = {
    "vx": r"$v_x$",
    "yaw_rate": r"$\omega_z$",
    "ax": r"$a_x$",
    "ay": r"$a_y$",
}
COLORS = {"raw": "C0", "filtered": "C1"}


def draw_iso_boxplot(table: RatingTable, path: str | Path, title: str | None = None) -> Path:
    """Per channel a raw and a filtered box of the trials' overall ratings (each trial a
    dot), dashed lines at the grade thresholds; saved as PNG at ``path``."""
    iso = table.config.iso
    fig, ax = plt.subplots(figsize=(7.0, 4.2))
    rng = np.random.default_rng(0)  # jitter of the dots only
    ticks = []
    for k, ch in enumerate(table.channels):
        centre = 3.0 * k + 1.5
        ticks.append(centre)
        for off, cond in ((-0.45, "raw"), (0.45, "filtered")):
            vals = table.values(ch, cond)
            if vals.size == 0:
                continue
            pos = centre + off
            bp = ax.boxplot(vals, positions=[pos], widths=0.7, patch_artist=True, showfliers=False)
            for box in bp["boxes"]:
                box.set(facecolor=COLORS[cond], alpha=0.35, edgecolor=COLORS[cond])
            for part in ("whiskers", "caps", "medians"):
                for line in bp[part]:
                    line.set(color=COLORS[cond])
            ax.scatter(
                pos + rng.uniform(-0.15, 0.15, vals.size), vals, s=10, color=COLORS[cond], zorder=3
            )
    for level, name in (
        (iso.grade_excellent, "Excellent"),
        (iso.grade_good, "Good"),
        (iso.grade_fair, "Fair"),
    ):
        ax.axhline(level, ls="--", lw=0.9, color="0.4", zorder=1)
        ax.text(
            3.0 * len(table.channels) + 0.05, level, f" {name} > {level:g}", va="center", fontsize=7
        )
    ax.set_xticks(ticks, [CHANNEL_LABELS.get(c, c) for c in table.channels])
    ax.set_xlim(0, 3.0 * len(table.channels))
    ax.set_ylim(0.0, 1.02)
    ax.set_ylabel("ISO/TS 18571 overall rating R")
    handles = [plt.Rectangle((0, 0), 1, 1, color=COLORS[c], alpha=0.5) for c in COLORS]
    cutoff = table.config.lowpass.cutoff_hz
    ax.legend(handles, ["raw", f"filtered ({cutoff:g} Hz zero-phase)"], loc="lower left")
    n = len(table.trial_ids())
    ax.set_title(title or f"ISO/TS 18571 rating over {n} trials")
    return save(fig, path)
