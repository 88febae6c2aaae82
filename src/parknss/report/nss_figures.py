"""NSS figures: the loss history with its optimum (Fig. 4) and open-loop rollouts (Fig. 5)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from parknss.data.trial import Trial
from parknss.report.style import save, shade_reverse
from parknss.signals import ms_to_kmh, rad_to_deg


def draw_history(
    epochs: Sequence[int],
    raw: Sequence[float],
    smooth: Sequence[float],
    path: str | Path,
    output: Sequence[float] | None = None,
    best_epoch: int | None = None,
    criterion: str = "held-out state loss",
) -> Path:
    """Fig. 4: the criterion raw and smoothed over epochs, the output loss, the optimum.

    All series are per criterion point (same length as ``epochs``); losses are in the
    scaled space of the training objective.
    """
    fig, ax = plt.subplots(figsize=(8, 4.2))
    ax.plot(epochs, raw, color="C0", alpha=0.35, lw=0.8, label=f"{criterion} (raw)")
    ax.plot(epochs, smooth, color="C0", lw=1.6, label=f"{criterion} (smoothed)")
    if output is not None and len(output) == len(epochs):
        ax.plot(epochs, output, color="0.5", lw=1.0, label="held-out output loss")
    if best_epoch:
        i = int(np.argmin(np.abs(np.asarray(epochs) - best_epoch)))
        ax.axvline(best_epoch, color="C3", ls="--", lw=1.0)
        ax.plot([best_epoch], [smooth[i]], "o", color="C3", label=f"optimum, epoch {best_epoch}")
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss (scaled units)")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Convergence")
    return save(fig, path)


def pick_maneuvers(trials: Sequence[Trial]) -> list[Trial]:
    """The first multi-segment park-in and the first park-out (Fig. 5's two maneuvers)."""
    park_in = [tr for tr in trials if tr.maneuver.startswith("park_in")]
    park_out = [tr for tr in trials if tr.maneuver.startswith("park_out")]
    chosen = park_in[:1] + park_out[:1]
    return chosen or list(trials[:2])


def draw_rollouts(
    trials: Sequence[Trial],
    predictions: Mapping[str, Mapping[str, np.ndarray]],
    path: str | Path,
    horizon: int | None = None,
    title: str = "Open-loop rollout on held-out maneuvers",
) -> Path:
    """Fig. 5: measured vs predicted vx, ω_z, ax, ay; one column per trial, shared time.

    Reverse-gear segments are shaded; the training-window horizon (``horizon`` samples
    from the trial start) is a green dashed line.
    """
    rows = (
        ("vx", "vx [km/h]", ms_to_kmh),
        ("yaw_rate", "ω_z [°/s]", rad_to_deg),
        ("ax", "ax [m/s²]", np.asarray),
        ("ay", "ay [m/s²]", np.asarray),
    )
    n = max(len(trials), 1)
    fig, axes = plt.subplots(
        len(rows), n, figsize=(5.5 * n, 8.5), sharex=True, sharey="row", squeeze=False
    )
    t_max = max(tr["t"][-1] for tr in trials)
    for j, tr in enumerate(trials):
        t = tr["t"]
        pred = predictions[tr.id]
        for i, (ch, label, conv) in enumerate(rows):
            ax = axes[i][j]
            shade_reverse(ax, t, tr["gear"])
            ax.plot(t, conv(tr[ch]), color="k", lw=0.8, label="measured")
            ax.plot(t, conv(pred[ch]), color="C3", lw=1.0, label="predicted")
            if horizon is not None and horizon < tr.n:
                ax.axvline(t[horizon], color="C2", ls="--", lw=1.0, label="training horizon")
            if j == 0:
                ax.set_ylabel(label)
            ax.set_xlim(0.0, t_max)
            ax.grid(alpha=0.25)
        axes[0][j].set_title(f"{tr.id} ({tr.maneuver})", fontsize=9)
        axes[-1][j].set_xlabel("t [s]")
    axes[0][0].legend(fontsize=7, loc="upper right")
    fig.suptitle(f"{title}; reverse shaded")
    return save(fig, path)
