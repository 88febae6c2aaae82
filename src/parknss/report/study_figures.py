"""Figures of the evaluation studies: the learning curve, the seed-noise floor, the
Table III ablation effects and the limiter study. Errors are moving-region MSEs in the
paper's units ((km/h)² for vx, (°/s)² for ω_z)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import NullFormatter

from parknss.report.style import save

UNITS = {"vx": "vx MSE [(km/h)²]", "yaw": "ω_z MSE [(°/s)²]"}


def draw_learning_curve(result, path: str | Path) -> Path:
    """Boxes of the fold errors per training-set size, the fold-mean line, the power-law
    fit (dashed) extrapolated to the all-trials model (diamond); one panel per channel."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    sizes = np.asarray(result.sizes(), dtype=float)
    for ax, ch in zip(axes, ("vx", "yaw"), strict=True):
        data = [np.asarray(p.values(ch), dtype=float) for p in result.points]
        data = [d[np.isfinite(d)] for d in data]
        width = 0.25 * (sizes.max() - sizes.min() + 4) / len(sizes)
        ax.boxplot(data, positions=sizes, widths=width, manage_ticks=False)
        ax.plot(sizes, result.means(ch), "o-", color="C0", label="fold mean")
        fit = result.fits.get(ch)
        if fit is not None:
            n = np.linspace(sizes.min(), result.extrapolate_to, 100)
            ax.plot(n, fit(n), "--", color="C1", label=f"fit {fit.a:.3g}·n^-{fit.b:.2f}")
            ax.plot(
                [result.extrapolate_to],
                [result.extrapolated(ch)],
                "D",
                color="C3",
                ms=8,
                label=f"all-{result.extrapolate_to} model (extrapolated)",
            )
        ax.set_xlabel("training trials")
        ax.set_ylabel(UNITS[ch])
        ax.set_xticks([*sizes, result.extrapolate_to])
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"Learning curve, leave-r-repeats-out, {result.epochs} epochs")
    return save(fig, path)


def draw_seed_noise(result, path: str | Path) -> Path:
    """Per-seed held-out errors of one split with the mean and ±1 std band."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, ch in zip(axes, ("vx", "yaw"), strict=True):
        vals = np.asarray([getattr(s, ch) for s in result.scores], dtype=float)
        ax.plot(result.seeds, vals, "o", color="C0")
        m, s = float(np.mean(vals)), float(np.std(vals, ddof=1)) if len(vals) > 1 else 0.0
        ax.axhline(m, color="C0", lw=1)
        ax.axhspan(m - s, m + s, color="C0", alpha=0.15, lw=0)
        ax.set_xlabel("seed")
        ax.set_ylabel(UNITS[ch])
        ax.set_title(f"CV {100 * getattr(result.floor, ch):.1f} %", fontsize=10)
        ax.grid(alpha=0.3)
    fig.suptitle(f"Seed-noise floor: {result.split} fold {result.index}, {result.epochs} epochs")
    return save(fig, path)


def draw_ablations(result, path: str | Path) -> Path:
    """Relative effect of every option against its axis's deployed option (%), vx and ω_z,
    with the seed-noise threshold band (±z·CV) shaded."""
    labels, vx, yaw = [], [], []
    for axis in result.axes:
        for o in axis.options:
            if o.deployed:
                continue
            labels.append(f"{axis.name}: {o.label}")
            vx.append(100 * axis.effect(o.label, "vx"))
            yaw.append(100 * axis.effect(o.label, "yaw"))
    y = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(9, 0.38 * len(labels) + 1.5))
    ax.barh(y - 0.2, vx, height=0.4, color="C0", label="vx")
    ax.barh(y + 0.2, yaw, height=0.4, color="C1", label="ω_z")
    for ch, colour in (("vx", "C0"), ("yaw", "C1")):
        thr = 100 * result.floor.threshold(ch)
        if np.isfinite(thr):
            ax.axvspan(-thr, thr, color=colour, alpha=0.08, lw=0)
    ax.axvline(0, color="k", lw=0.8)
    ax.set_yticks(y, labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("error change vs the deployed option [%] (shaded: seed-noise threshold)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="x")
    return save(fig, path)


def draw_limiter(result, path: str | Path) -> Path:
    """Fold-mean errors without a limiter, clamping the reconstructed yaw, clamping the
    residual channel (log scale: the residual clamp can be orders of magnitude worse)."""
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6))
    names = [v.variant for v in result.variants]
    for ax, ch in zip(axes, ("vx", "yaw"), strict=True):
        vals = [getattr(v, ch) for v in result.variants]
        ax.bar(names, vals, color=["0.6", "C0", "C3"])
        ax.set_yscale("log")
        ax.set_ylabel(UNITS[ch])
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle("Inference limiter on the same fold models")
    return save(fig, path)


def draw_time_to_accuracy(result, path: str | Path) -> Path:
    """Held-out criterion against the fit's CPU time, the paper recipe (C0) and each
    challenger recipe (C1, C2, ...), one panel per fold: raw points (light), smoothed line,
    the paper fit's best smoothed error, the target (dotted), and where each challenger
    reaches it (vertical)."""
    n = len(result.folds)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.8), squeeze=False,
                             constrained_layout=True)
    for ax, f in zip(axes[0], result.folds, strict=True):
        runs = [(f.paper, "C0", "paper")] + [
            (c.curve, f"C{j}", c.recipe) for j, c in enumerate(f.challengers, 1)]
        for curve, color, label in runs:
            ax.plot(curve.cpu_s, curve.raw, ".", color=color, alpha=0.2, ms=2)
            ax.plot(curve.cpu_s, curve.smooth, "-", color=color,
                    label=f"{label} ({curve.total_cpu_s:.0f} s)")
        ax.axhline(f.target, color="k", ls=":", lw=1, label=f"paper best {f.target:.4f}")
        for j, c in enumerate(f.challengers, 1):
            r = f.reach_cpu_s(c.recipe)
            if r is not None:
                ax.axvline(r, color=f"C{j}", ls="--", lw=1, label=f"{c.recipe} reaches it at "
                           f"{r:.0f} s (x{f.speedup_reach(c.recipe):.1f})")
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        lo = min(min(curve.smooth) for curve, _, _ in runs)
        ax.set_ylim(0.9 * lo, 3.0 * lo)
        ax.set_xlabel("CPU time of the fit [s]")
        if ax is axes[0][0]:
            ax.set_ylabel("held-out criterion (scaled MAE)")
        ax.set_title(f"CV fold {f.index}", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.suptitle("Time to accuracy: the paper recipe vs this toolkit's recipes")
    return save(fig, path)
