"""Figures of the actuator study: Fig. 6 (fidelity vs closed-loop value), Fig. 3 (replay)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from parknss.report.style import save

COLORS = {"drive": "tab:blue", "brake": "tab:red", "steering": "tab:green"}


def draw_fidelity(points: list[dict], stars: dict, reference: float, corr: dict,
                  path: str | Path) -> Path:
    """Fig. 6: held-out NMSE vs per-channel-substitution vx MSE (log-log), 1 s NARX stars."""
    fig, ax = plt.subplots(figsize=(6.0, 4.4))
    for p in points:
        ax.scatter(p["nmse"], p["vx_full"], color=COLORS[p["channel"]], s=30, zorder=3)
        ax.annotate(p["arch"], (p["nmse"], p["vx_full"]), fontsize=7, xytext=(3, 3),
                    textcoords="offset points")
    for lab, (x, y) in stars.items():
        ax.scatter(x, y, marker="*", s=160, color="k" if "after" in lab else "0.6",
                   zorder=4, label=lab)
    ax.axhline(reference, color="0.4", ls="--", lw=1, label="all measured")
    for ch, c in COLORS.items():
        ax.scatter([], [], color=c, label=ch)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("signal fidelity: held-out NMSE of the actual [-]")
    ax.set_ylabel("closed-loop value: chained $v_x$ MSE [(km/h)$^2$]")
    ax.set_title(f"command-only candidates, Pearson r = {corr['pearson']:+.2f} "
                 f"(log: {corr['pearson_log10']:+.2f})", fontsize=9)
    ax.legend(fontsize=7, loc="best")
    return save(fig, path)


def autohold_mask(decel_cmd: np.ndarray, pressure: np.ndarray, bar: float = 1.0) -> np.ndarray:
    """Samples with pressure but no braking command (what no command explains)."""
    return (pressure >= bar) & (decel_cmd > -1e-6)


def draw_replay(t: np.ndarray, rows: list[dict], hold: np.ndarray, title: str,
                path: str | Path) -> Path:
    """Fig. 3: per channel, command, recorded actual and the replayed submodel.

    rows: [{"name", "unit", "cmd", "cmd_unit", "actual", "replay"}], arrays (T,).
    """
    fig, axes = plt.subplots(len(rows), 1, figsize=(7.5, 2.2 * len(rows)), sharex=True)
    edges = np.flatnonzero(np.diff(np.r_[0, hold.astype(int), 0]))
    for ax, r in zip(np.atleast_1d(axes), rows, strict=True):
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            ax.axvspan(t[a], t[min(b, len(t) - 1)], color="gold", alpha=0.3, lw=0)
        if r["cmd_unit"] == r["unit"]:
            ax.plot(t, r["cmd"], color="0.5", lw=1, label="command")
        else:
            ax2 = ax.twinx()
            ax2.plot(t, r["cmd"], color="0.5", lw=1)
            ax2.set_ylabel(f"command [{r['cmd_unit']}]", fontsize=8, color="0.4")
        ax.plot(t, r["actual"], color="k", lw=1.2, label="recorded")
        ax.plot(t, r["replay"], color="tab:orange", lw=1.2, ls="--", label="submodel")
        ax.set_ylabel(f"{r['name']} [{r['unit']}]", fontsize=8)
    np.atleast_1d(axes)[0].legend(fontsize=7, loc="upper right")
    np.atleast_1d(axes)[0].set_title(title + " (shaded: auto-hold pressure)", fontsize=9)
    np.atleast_1d(axes)[-1].set_xlabel("t [s]")
    return save(fig, path)
