"""The fidelity figure of one cell (chain and truth overlaid) and the run's HTML page."""

from __future__ import annotations

import html
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from parknss.outputs import write_text_atomic
from parknss.report.sim_figures import PLANT_COLOURS, _smooth
from parknss.report.style import save, shade_reverse
from parknss.signals import ms_to_kmh, rad_to_deg


def draw_fidelity(
    runs: dict[str, dict[str, np.ndarray]], path: str | Path, title: str = "", dt: float = 0.01
) -> Path:
    """vx [km/h], ω_z [°/s], ax [m/s², 0.2 s average], steering-wheel angle [°] and the
    commanded gear of each run (``runs``: plant name -> closed-loop series) on one time
    axis; the truth's reverse spans shaded. Returns the PNG path."""
    fig, axes = plt.subplots(5, 1, figsize=(10, 10), sharex=True)
    rows = (
        ("vx", "v_x [km/h]", ms_to_kmh, 1),
        ("yaw_rate", "ω_z [°/s]", rad_to_deg, 1),
        ("ax", "a_x [m/s²] (0.2 s avg)", lambda v: v, max(1, round(0.2 / dt))),
        ("steer", "steering wheel [°]", lambda v: v, 1),
        ("gear_cmd", "gear command", lambda v: v, 1),
    )
    shade = runs.get("reference") or next(iter(runs.values()), None)
    for ax, (key, label, conv, width) in zip(axes, rows, strict=True):
        if shade is not None:
            shade_reverse(ax, shade["t"], shade["gear"])
        for name, s in runs.items():
            ax.plot(
                s["t"],
                _smooth(conv(np.asarray(s[key], float)), width),
                color=PLANT_COLOURS.get(name, "#34495e"),
                lw=1.0,
                label=name,
            )
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("t [s]")
    if title:
        axes[0].set_title(title, fontsize=9)
    return save(fig, path)


def write_fidelity_html(
    path: Path,
    title: str,
    summary_lines: list[str],
    columns: list[str],
    rows: list[list[str]],
    figures: list[tuple[str, str]],
) -> Path:
    """A page: the summary lines, the per-cell table, then each cell's figure (linked by
    its path relative to ``path``'s folder; ``figures``: (caption, relative path))."""
    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(v)}</td>" for v in r) + "</tr>" for r in rows
    )
    figs = "".join(
        f"<h3>{html.escape(cap)}</h3><p><img alt='{html.escape(cap)}' src='{html.escape(rel)}'"
        " style='max-width:100%'></p>"
        for cap, rel in figures
    )
    summary = "".join(f"<li>{html.escape(s)}</li>" for s in summary_lines)
    doc = (
        f"<!doctype html><meta charset='utf-8'><title>{html.escape(title)}</title>"
        "<style>body{font-family:system-ui,sans-serif;margin:2em}table{border-collapse:"
        "collapse}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}</style>"
        f"<h1>{html.escape(title)}</h1><ul>{summary}</ul><table><tr>{head}</tr>{body}"
        f"</table>{figs}"
    )  # fmt: skip
    return write_text_atomic(path, doc)
