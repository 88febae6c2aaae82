"""Draw a parking scene with its planned path: obstacles, start and goal, the coarse
(Hybrid A*) and refined paths, footprints at intervals and the cusps."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from parknss.report.style import figure, save
from parknss.sim.geometry import footprint
from parknss.sim.scenarios import VIEW_ZOOM_ABOVE_M, VIEW_ZOOM_PAD_M
from parknss.sim.trajectory import Trajectory
from parknss.vehicle import VehicleGeometry

OBSTACLE_COLOURS = {"car": "#9aa5b1", "curb": "#6b4f3a", "barrier": "#c0392b"}


def outline(ax, poly: np.ndarray, **kw) -> None:
    """Draw the closed outline of polygon ``poly`` (M, 2) on ``ax``."""
    closed = np.vstack([poly, poly[:1]])
    ax.plot(closed[:, 0], closed[:, 1], **kw)


ZOOM_ABOVE_M = VIEW_ZOOM_ABOVE_M
"""Maps larger than this (m, either side) are drawn zoomed to the plan, start and goal."""
ZOOM_PAD_M = VIEW_ZOOM_PAD_M
"""...with this border around them, m (the web view zooms the same way)."""


def scene_axes(scene, frame: bool = False):
    """(fig, ax) of a 12 in wide figure of ``scene`` with its obstacles filled (and the
    map rectangle outlined when ``frame``)."""
    xmin, ymin, xmax, ymax = scene.bounds
    width = 12.0
    height = max(3.0, min(9.0, width * (ymax - ymin) / max(xmax - xmin, 1e-9)))
    from matplotlib.patches import Rectangle

    fig = figure((width, height + 1.0))
    ax = fig.subplots()
    if frame:
        ax.add_patch(Rectangle((xmin, ymin), xmax - xmin, ymax - ymin, fill=False, ec="k", lw=0.8))
    for ob in scene.obstacles:
        colour = OBSTACLE_COLOURS.get(ob.kind, "#7f8c8d")
        ax.fill(ob.vertices[:, 0], ob.vertices[:, 1], color=colour, alpha=0.8, lw=0)
    return fig, ax


def finish_scene(fig, ax, scene, geom: VehicleGeometry, title: str, path, lw: float) -> Path:
    """Outline the start (solid) and goal (dotted) footprints with line width ``lw``, fit
    the map with a 0.5 m border (a map beyond :data:`ZOOM_ABOVE_M`: the drawn lines, plan
    start and goal, with :data:`ZOOM_PAD_M`), label, add the legend and save the PNG."""
    xmin, ymin, xmax, ymax = scene.bounds
    outline(ax, footprint(scene.start, geom), color="#2471a3", lw=lw, label="start")
    outline(ax, footprint(scene.goal, geom), color="#1e8449", lw=lw, ls=":", label="goal")
    ax.set_aspect("equal")
    if max(xmax - xmin, ymax - ymin) > ZOOM_ABOVE_M:  # a large map: the problem's region
        pts = np.concatenate([ln.get_xydata() for ln in ax.get_lines()])
        lo, hi = pts.min(axis=0) - ZOOM_PAD_M, pts.max(axis=0) + ZOOM_PAD_M
        xmin, ymin = max(xmin, lo[0]), max(ymin, lo[1])
        xmax, ymax = min(xmax, hi[0]), min(ymax, hi[1])
    ax.set_xlim(xmin - 0.5, xmax + 0.5)
    ax.set_ylim(ymin - 0.5, ymax + 0.5)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=8)
    return save(fig, path)


def _draw_path(ax, traj: Trajectory, colour: str, label: str, lw: float) -> None:
    first = True
    for seg in traj.segments:
        style = "-" if seg.direction > 0 else "--"
        ax.plot(
            seg.poses[:, 0],
            seg.poses[:, 1],
            style,
            color=colour,
            lw=lw,
            label=label if first else None,
        )
        first = False


def _footprints_along(traj: Trajectory, every: float) -> list[np.ndarray]:
    """Poses spaced ``every`` m along a trajectory (arc length), plus each segment end."""
    out = []
    for seg in traj.segments:
        s = seg.arc_length
        targets = np.arange(0.0, s[-1], every)
        idx = np.unique(np.searchsorted(s, targets).clip(0, len(s) - 1))
        out.extend(seg.poses[i] for i in idx)
        out.append(seg.poses[-1])
    return out


def draw_plan(
    scene,
    path: str | Path,
    coarse: Trajectory | None = None,
    refined: Trajectory | None = None,
    geom: VehicleGeometry | None = None,
    title: str | None = None,
    footprint_every_m: float = 1.0,
) -> Path:
    """Draw ``scene`` with the coarse and refined paths to a PNG at ``path``.

    Forward driving is drawn solid, reverse dashed; footprints every
    ``footprint_every_m`` m (of the refined path if given, else the coarse one); cusps
    are marked with x. Returns the PNG path.
    """
    geom = geom or VehicleGeometry()
    fig, ax = scene_axes(scene, frame=True)
    main = refined if refined is not None and refined.segments else coarse
    if main is not None and main.segments:
        for pose in _footprints_along(main, footprint_every_m):
            outline(ax, footprint(pose, geom), color="#2e86c1", lw=0.4, alpha=0.5)
    if coarse is not None and coarse.segments:
        _draw_path(ax, coarse, "#27ae60", "coarse (Hybrid A*)", 1.6)
    if refined is not None and refined.segments:
        _draw_path(ax, refined, "#8e44ad", f"refined ({refined.source})", 1.2)
    if main is not None:
        for seg in main.segments[:-1]:
            ax.plot(*seg.poses[-1, :2], "kx", ms=8, mew=2)
    return finish_scene(fig, ax, scene, geom, title or scene.meta.name, path, 1.8)
