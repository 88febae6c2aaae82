"""Draw a parking scene with its planned path: obstacles, start and goal, the coarse
(Hybrid A*) and refined paths, footprints at intervals and the cusps.

:func:`draw_plan` (``parknss plan``'s figure) writes SVG through :mod:`parknss.report.svg`
and imports no matplotlib; :func:`scene_axes`, :func:`finish_scene` and :func:`outline`
are the matplotlib versions that Figs. 8/9 and the gym environment's frames draw on
(matplotlib imported when they are called). Both fit the view by :func:`view_box`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from parknss.report.svg import Stroke, SvgAxes
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


def view_box(bounds, pts: np.ndarray) -> tuple[float, float, float, float]:
    """(xmin, ymin, xmax, ymax) m a scene figure shows: the map ``bounds`` with a 0.5 m
    border, or for a map beyond :data:`ZOOM_ABOVE_M` the drawn lines' points ``pts``
    (N, 2) (plan, start and goal) with :data:`ZOOM_PAD_M`, inside the map."""
    xmin, ymin, xmax, ymax = bounds
    if max(xmax - xmin, ymax - ymin) > ZOOM_ABOVE_M and len(pts):
        lo, hi = pts.min(axis=0) - ZOOM_PAD_M, pts.max(axis=0) + ZOOM_PAD_M
        xmin, ymin = max(xmin, lo[0]), max(ymin, lo[1])
        xmax, ymax = min(xmax, hi[0]), min(ymax, hi[1])
    return xmin - 0.5, ymin - 0.5, xmax + 0.5, ymax + 0.5


def scene_axes(scene, frame: bool = False):
    """(fig, ax) of a 12 in wide figure of ``scene`` with its obstacles filled (and the
    map rectangle outlined when ``frame``)."""
    xmin, ymin, xmax, ymax = scene.bounds
    width = 12.0
    height = max(3.0, min(9.0, width * (ymax - ymin) / max(xmax - xmin, 1e-9)))
    from matplotlib.patches import Rectangle

    from parknss.report.style import figure

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
    start and goal, with :data:`ZOOM_PAD_M`: :func:`view_box`), label, add the legend
    and save the PNG."""
    from parknss.report.style import save

    outline(ax, footprint(scene.start, geom), color="#2471a3", lw=lw, label="start")
    outline(ax, footprint(scene.goal, geom), color="#1e8449", lw=lw, ls=":", label="goal")
    ax.set_aspect("equal")
    x0, y0, x1, y1 = view_box(scene.bounds,
                              np.concatenate([ln.get_xydata() for ln in ax.get_lines()]))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=8)
    return save(fig, path)


def _footprints_along(traj: Trajectory, every: float) -> list[np.ndarray]:
    """Poses spaced ``every`` m along a trajectory (arc length), plus each segment end."""
    out = []
    for seg in traj.segments:
        s = seg.arc_length
        targets = np.arange(0.0, s[-1], every)
        idx = np.searchsorted(s, targets).clip(0, len(s) - 1)  # non-decreasing
        idx = idx[np.diff(idx, prepend=-1) > 0]  # unique (np.unique imports numpy.ma)
        out.extend(seg.poses[i] for i in idx)
        out.append(seg.poses[-1])
    return out


PLAN_COLOURS = {"start": "#2471a3", "goal": "#1e8449", "footprint": "#2e86c1",
                "coarse": "#27ae60", "refined": "#8e44ad", "cusp": "#000000"}


def draw_plan(
    scene,
    path: str | Path,
    coarse: Trajectory | None = None,
    refined: Trajectory | None = None,
    geom: VehicleGeometry | None = None,
    title: str | None = None,
    footprint_every_m: float = 1.0,
) -> Path:
    """Draw ``scene`` with the coarse and refined paths as an SVG at ``path``.

    The map's rectangle (or outline), the obstacles filled by kind; forward driving drawn solid,
    reverse dashed; footprints every ``footprint_every_m`` m (of the refined path if
    given, else the coarse one); cusps marked with x; start (solid) and goal (dotted)
    footprints; a large map zoomed to the problem (:func:`view_box`); the legend below
    the plot, so it hides nothing. Each layer carries a class (``obstacle``, ``map``,
    ``footprint``, ``path-coarse``, ``path-refined``, ``cusp``, ``start``, ``goal``).
    Returns the SVG path.
    """
    geom = geom or VehicleGeometry()
    main = refined if refined is not None and refined.segments else coarse
    main = main if main is not None and main.segments else None
    prints = ([footprint(p, geom) for p in _footprints_along(main, footprint_every_m)]
              if main else [])
    paths = [(t, k) for t, k in ((coarse, "coarse"), (refined, "refined"))
             if t is not None and t.segments]
    start, goal = footprint(scene.start, geom), footprint(scene.goal, geom)
    lines = [start, goal, *prints, *(s.poses[:, :2] for t, _ in paths for s in t.segments)]
    x0, y0, x1, y1 = view_box(scene.bounds, np.concatenate(lines))
    ax = SvgAxes((x0, x1), (y0, y1), title=title or scene.meta.name)
    bx0, by0, bx1, by1 = scene.bounds
    rim = scene.map_outline or [[bx0, by0], [bx1, by0], [bx1, by1], [bx0, by1]]
    ax.polygon(rim, stroke=Stroke("#000000", 1.0), cls="map")
    kinds = []
    for ob in scene.obstacles:
        colour = OBSTACLE_COLOURS.get(ob.kind, "#7f8c8d")
        ax.polygon(ob.vertices, fill=colour, opacity=0.8, cls="obstacle")
        if ob.kind not in kinds:
            kinds.append(ob.kind)
    for corners in prints:
        ax.polygon(corners, stroke=Stroke(PLAN_COLOURS["footprint"], 0.6, opacity=0.5),
                   cls="footprint")
    widths = {"coarse": 1.9, "refined": 1.4}
    for traj, kind in paths:
        for seg in traj.segments:
            dash = "solid" if seg.direction > 0 else "dashed"
            ax.polyline(seg.poses, Stroke(PLAN_COLOURS[kind], widths[kind], dash),
                        cls=f"path-{kind}")
    if main:
        for seg in main.segments[:-1]:
            ax.cross(seg.poses[-1, 0], seg.poses[-1, 1], Stroke(PLAN_COLOURS["cusp"], 2.2),
                     cls="cusp")
    ax.polygon(start, stroke=Stroke(PLAN_COLOURS["start"], 2.0), cls="start")
    ax.polygon(goal, stroke=Stroke(PLAN_COLOURS["goal"], 2.0, "dotted"), cls="goal")
    for kind in kinds:
        ax.legend(kind, fill=OBSTACLE_COLOURS.get(kind, "#7f8c8d"))
    ax.legend("start", stroke=Stroke(PLAN_COLOURS["start"], 2.0))
    ax.legend("goal", stroke=Stroke(PLAN_COLOURS["goal"], 2.0, "dotted"))
    labels = {"coarse": "coarse (Hybrid A*)", "refined": f"refined ({refined.source})"
              if refined is not None else ""}
    for _, kind in paths:
        ax.legend(labels[kind], stroke=Stroke(PLAN_COLOURS[kind], widths[kind]))
    if main:
        ax.legend("reverse (dashed)", stroke=Stroke("#555555", 1.4, "dashed"))
        ax.legend(f"footprint every {footprint_every_m:g} m",
                  stroke=Stroke(PLAN_COLOURS["footprint"], 1.0, opacity=0.5))
        if len(main.segments) > 1:
            ax.legend("cusp", marker=True)
    return ax.save(path)
