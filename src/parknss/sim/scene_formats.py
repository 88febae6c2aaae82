"""Benchmark scene formats read as parknss scenes: TPCAP case CSVs and CommonRoad XML.

**TPCAP** (Trajectory Planning Competition for Automated Parking; one CSV line per case,
../shared/planning/tpcap/README.md): start pose x0, y0, θ0, goal pose xf, yf, θf (rear
axle, m, rad), the number of obstacles N, the vertex count of each, then every obstacle's
vertices as x, y pairs (m). Obstacles are polygons as drawn (non-convex ones and walls
drawn as lines included; :mod:`parknss.sim.obstacles`). The map is, as in the source's
plotting convention, the box of start and goal widened by ``tpcap_map_margin_m`` (8 m) on
every side, drawn in the goal's frame (:func:`tpcap_map`: the scene's ``map_outline``, its
bounding box the scene's ``bounds``) so that a moved case keeps its map.

**CommonRoad** (XML, 2020a layout; read with lxml, not commonroad-io): every
``staticObstacle`` (shapes ``rectangle``, ``circle``, ``polygon`` in its own frame, moved
by its initial state's position and orientation; a circle becomes the regular polygon
with ``circle_segments`` sides *around* it, so the polygon contains the circle and
clearances are never overestimated), optionally the lanelets' left and right bounds as
walls (``commonroad_lanelet_walls``), and the first planning problem: the initial state
and the goal region (the centre of its position shape, the middle of its orientation
interval). CommonRoad states place the car by its centre; the reader moves start and goal
to the rear axle of the run's car (``geom``: centre minus (length/2 - rear overhang)
along the heading). The map is the bounding box of everything widened by
``commonroad_map_margin_m``.

Coordinates farther than ``local_frame_beyond_m`` from the origin (TPCAP cases 13-15 lie
near 4e9 m) are shifted into a local frame whose origin, in the source's coordinates, is
``meta.origin_m``: the refinement's solver and every geometric test work on small
numbers. One-line PlanningError for malformed files.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from parknss.errors import PlanningError
from parknss.sim.obstacles import ObstacleInputConfig, SceneImportConfig, check_counts
from parknss.sim.scenarios import (
    Obstacle,
    ScenariosConfig,
    Scene,
    SceneMeta,
    load_scenarios_config,
    obstacle_from_drawing,
    resolve_scene,
)
from parknss.vehicle import VehicleGeometry


def _shift(points: list[np.ndarray], cfg: SceneImportConfig) -> np.ndarray:
    """The local frame's origin (2,) m: 0 near the origin, else the floor of the minimum."""
    allp = np.concatenate([np.atleast_2d(p)[:, :2] for p in points])
    if np.max(np.abs(allp)) <= cfg.local_frame_beyond_m:
        return np.zeros(2)
    return np.floor(allp.min(axis=0))


def _build(
    name: str,
    source: str,
    drawn: list[tuple[str, np.ndarray, str]],
    start: np.ndarray,
    goal: np.ndarray,
    bounds: tuple[float, float, float, float],
    cfg: SceneImportConfig,
    ocfg: ObstacleInputConfig,
    outline: np.ndarray | None = None,
) -> Scene:
    """A scene from drawn obstacles (kind, (M, 2) vertices m, shape), poses and bounds (or
    a map ``outline``, (M, 2) CCW, whose bounding box ``bounds`` is), all in the source's
    coordinates; shifted to a local frame when far from the origin."""
    origin = _shift([start[None, :2], goal[None, :2], *[v for _, v, _ in drawn]], cfg)
    check_counts(len(drawn), sum(len(v) for _, v, _ in drawn), source, ocfg)
    obstacles: list[Obstacle] = []
    notes: list[str] = []
    for i, (kind, verts, shape) in enumerate(drawn):
        ob, note = obstacle_from_drawing(
            kind, np.asarray(verts, float) - origin, f"{source}: obstacle {i} ({kind})", shape, ocfg
        )
        obstacles.append(ob)
        if note:
            notes.append(note)
    ox, oy = origin
    b = (bounds[0] - ox, bounds[1] - oy, bounds[2] - ox, bounds[3] - oy)
    pose = lambda p: (float(p[0] - ox), float(p[1] - oy), float(p[2]))  # noqa: E731
    shifted = bool(np.any(origin))
    meta = SceneMeta(name=name, source=source, origin_m=(float(ox), float(oy)) if shifted else None)
    if outline is not None:
        outline = tuple((float(x - ox), float(y - oy)) for x, y in outline)
    return Scene(b, tuple(obstacles), pose(start), pose(goal), meta, tuple(notes), outline)


# ---------------------------------------------------------------------------------------
# TPCAP


def read_tpcap(
    path: str | Path,
    cfg: SceneImportConfig | None = None,
    ocfg: ObstacleInputConfig | None = None,
) -> Scene:
    """The scene of a TPCAP case CSV (module docstring); named ``tpcap-<file stem>``."""
    cfg, ocfg = cfg or SceneImportConfig(), ocfg or ObstacleInputConfig()
    p = Path(path)
    if not p.is_file():
        raise PlanningError(f"{p}: TPCAP case file not found")
    try:
        text = p.read_text().replace("\n", ",")
        v = np.array([float(t) for t in text.split(",") if t.strip()], dtype=float)
    except (ValueError, UnicodeDecodeError) as exc:
        raise PlanningError(f"{p}: not a TPCAP case (numbers separated by commas)") from exc
    if len(v) < 7 or not np.all(np.isfinite(v)):
        raise PlanningError(f"{p}: not a TPCAP case (need finite start, goal and counts)")
    n = int(v[6])
    if n < 0 or v[6] != n or len(v) < 7 + n:
        raise PlanningError(f"{p}: obstacle count {v[6]!r} does not fit the file")
    counts = v[7 : 7 + n]
    if np.any(counts < 2) or np.any(counts != np.round(counts)):
        raise PlanningError(f"{p}: vertex counts must be integers >= 2")
    need = 7 + n + 2 * int(counts.sum())
    if len(v) != need:
        raise PlanningError(f"{p}: expected {need} numbers for {n} obstacles, found {len(v)}")
    xy = v[7 + n :].reshape(-1, 2)
    ends = np.concatenate([[0], np.cumsum(counts.astype(int))])
    drawn = [("obstacle", xy[ends[i] : ends[i + 1]], "polygon") for i in range(n)]
    start, goal = v[0:3], v[3:6]
    outline = tpcap_map(start, goal, cfg.tpcap_map_margin_m)
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    bounds = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    name = f"tpcap-{p.stem.lower()}"
    return _build(name, str(p), drawn, start, goal, bounds, cfg, ocfg, outline)


def tpcap_map(start, goal, margin: float) -> np.ndarray:
    """The TPCAP map (4, 2) CCW, m: the box of start and goal widened by ``margin`` on
    every side, drawn in the goal's frame (axes along and across the goal heading), so
    that it moves with the scene (a rotated case keeps its map)."""
    gx, gy, gth = (float(t) for t in goal[:3])
    c, s = math.cos(gth), math.sin(gth)
    dx, dy = float(start[0]) - gx, float(start[1]) - gy
    sx, sy = c * dx + s * dy, -s * dx + c * dy  # the start in the goal's frame
    x0, x1 = min(0.0, sx) - margin, max(0.0, sx) + margin
    y0, y1 = min(0.0, sy) - margin, max(0.0, sy) + margin
    local = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    return np.column_stack(
        [gx + c * local[:, 0] - s * local[:, 1], gy + s * local[:, 0] + c * local[:, 1]]
    )


# ---------------------------------------------------------------------------------------
# CommonRoad


def _num(el, tag: str, where: str) -> float:
    node = el.find(tag)
    try:
        value = float(node.text)
    except (AttributeError, TypeError, ValueError) as exc:
        raise PlanningError(f"{where}: missing or bad <{tag}>") from exc
    if not math.isfinite(value):
        raise PlanningError(f"{where}: <{tag}> is not finite")
    return value


def _point(el, where: str) -> np.ndarray:
    return np.array([_num(el, "x", where), _num(el, "y", where)])


def _value(el, where: str) -> float:
    """A CommonRoad value: <exact> or the middle of <intervalStart>/<intervalEnd>."""
    if el.find("exact") is not None:
        return _num(el, "exact", where)
    return 0.5 * (_num(el, "intervalStart", where) + _num(el, "intervalEnd", where))


def _shapes(shape_el, where: str, cfg: SceneImportConfig) -> list[np.ndarray]:
    """(M, 2) polygons (m) of a <shape> or <position> element's rectangles, circles and
    polygons, in that element's frame."""
    out = []
    for i, el in enumerate(shape_el):
        w = f"{where} {el.tag} {i}"
        if el.tag == "rectangle":
            length, width = _num(el, "length", w), _num(el, "width", w)
            c = _point(el.find("center"), w) if el.find("center") is not None else np.zeros(2)
            a = _num(el, "orientation", w) if el.find("orientation") is not None else 0.0
            ca, sa = math.cos(a), math.sin(a)
            local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [0.5 * length, 0.5 * width]
            out.append(local @ np.array([[ca, sa], [-sa, ca]]) + c)
        elif el.tag == "circle":
            r = _num(el, "radius", w)
            c = _point(el.find("center"), w) if el.find("center") is not None else np.zeros(2)
            k = cfg.circle_segments
            ang = 2 * math.pi * np.arange(k) / k
            rr = r / math.cos(math.pi / k)  # circumscribed: the polygon contains the circle
            out.append(c + rr * np.column_stack([np.cos(ang), np.sin(ang)]))
        elif el.tag == "polygon":
            out.append(np.array([_point(pt, w) for pt in el.findall("point")]))
        elif el.tag == "point":
            out.append(_point(el, w)[None, :])
    return out


def area_centre(shapes: list[np.ndarray]) -> np.ndarray:
    """(2,) area centroid (m) of the union of disjoint shapes (M, 2), each an open or closed
    polygon (a repeated first point is dropped); shapes without area (points, segments)
    count by their vertex mean only when no shape has area."""
    cents, areas = [], []
    for poly in shapes:
        q = np.asarray(poly, dtype=float)
        if len(q) > 1 and np.array_equal(q[0], q[-1]):
            q = q[:-1]
        x, y = q[:, 0] - q[0, 0], q[:, 1] - q[0, 1]  # about the first vertex: no cancellation
        xn, yn = np.roll(x, -1), np.roll(y, -1)
        cross = x * yn - xn * y
        a = 0.5 * float(cross.sum())
        if len(q) >= 3 and abs(a) > 1e-12:
            c = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * a)
            cents.append(c + q[0])
            areas.append(abs(a))
    if not areas:
        return np.concatenate(shapes).mean(axis=0)
    w = np.array(areas)
    return (np.array(cents) * w[:, None]).sum(axis=0) / w.sum()


def _lanelets(root, where: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Lanelet id -> (left bound (N, 2), right bound (M, 2)), m."""
    out = {}
    for ll in root.findall("lanelet"):
        w = f"{where}: lanelet {ll.get('id')}"
        sides = [ll.find(side) for side in ("leftBound", "rightBound")]
        if any(b is None for b in sides):
            continue
        left, right = (np.array([_point(pt, w) for pt in b.findall("point")]) for b in sides)
        if len(left) >= 2 and len(right) >= 2:
            out[str(ll.get("id"))] = (left, right)
    return out


def _lanelet_pose(refs, lanelets, where: str) -> tuple[np.ndarray, float | None]:
    """The area centroid of the referenced lanelets (m) and the heading (rad) of the
    first one's centre line at its segment nearest to that centroid."""
    polys = []
    for ref in refs:
        if ref not in lanelets:
            raise PlanningError(f"{where}: goal lanelet {ref!r} is not in the file")
        left, right = lanelets[ref]
        polys.append(np.concatenate([right, left[::-1]]))
    xy = area_centre(polys)
    left, right = lanelets[refs[0]]
    n = min(len(left), len(right))
    centre = 0.5 * (left[:n] + right[:n]) if len(left) == len(right) else np.array(
        [left[0] + right[0], left[-1] + right[-1]]
    ) / 2
    mids = 0.5 * (centre[1:] + centre[:-1])
    k = int(np.argmin(np.hypot(*(mids - xy).T)))
    d = centre[k + 1] - centre[k]
    return xy, math.atan2(d[1], d[0])


def _state_pose(state, where: str, lanelets=None) -> tuple[np.ndarray, float]:
    pos = state.find("position")
    if pos is None:
        raise PlanningError(f"{where}: state without <position>")
    pt = pos.find("point")
    refs = [str(el.get("ref")) for el in pos.findall("lanelet")]
    heading = None
    if pt is not None:
        xy = _point(pt, where)
    elif refs and lanelets is not None:
        xy, heading = _lanelet_pose(refs, lanelets, where)
    else:
        shapes = _shapes(pos, where, SceneImportConfig())
        if not shapes:
            raise PlanningError(f"{where}: position without a point or shape")
        xy = area_centre(shapes)
    ori = state.find("orientation")
    if ori is not None:
        return xy, _value(ori, where)
    return xy, heading if heading is not None else 0.0


def read_commonroad(
    path: str | Path,
    geom: VehicleGeometry | None = None,
    cfg: SceneImportConfig | None = None,
    ocfg: ObstacleInputConfig | None = None,
    problem_id: str | None = None,
) -> Scene:
    """The scene of a CommonRoad XML scenario (module docstring); named
    ``commonroad-<file stem>-<planning problem id>`` (the file's ``benchmarkID`` may
    disagree with its name). ``problem_id``: the ``planningProblem`` to plan
    (default the first; an unknown id is refused with the list of the file's ids)."""
    from lxml import etree

    cfg, ocfg = cfg or SceneImportConfig(), ocfg or ObstacleInputConfig()
    geom = geom or VehicleGeometry()
    p = Path(path)
    if not p.is_file():
        raise PlanningError(f"{p}: CommonRoad file not found")
    try:
        root = etree.parse(str(p), etree.XMLParser(resolve_entities=False, no_network=True))
    except (etree.XMLSyntaxError, OSError) as exc:
        raise PlanningError(f"{p}: not valid XML ({exc.__class__.__name__})") from exc
    root = root.getroot()
    if root.tag != "commonRoad":
        raise PlanningError(f"{p}: root element is <{root.tag}>, not <commonRoad>")
    drawn: list[tuple[str, np.ndarray, str]] = []
    for ob in root.findall("staticObstacle"):
        where = f"{p}: staticObstacle {ob.get('id')}"
        kind = (ob.findtext("type") or "obstacle").strip() or "obstacle"
        shape = ob.find("shape")
        if shape is None:
            raise PlanningError(f"{where}: no <shape>")
        state = ob.find("initialState")
        xy, th = _state_pose(state, where) if state is not None else (np.zeros(2), 0.0)
        c, s = math.cos(th), math.sin(th)
        for poly in _shapes(shape, where, cfg):
            drawn.append((kind, poly @ np.array([[c, s], [-s, c]]) + xy, "polygon"))
    if cfg.commonroad_lanelet_walls:
        for ll in root.findall("lanelet"):
            for side in ("leftBound", "rightBound"):
                bound = ll.find(side)
                if bound is not None:
                    w = f"{p}: lanelet {ll.get('id')} {side}"
                    pts = np.array([_point(pt, w) for pt in bound.findall("point")])
                    drawn.append(("lanelet bound", pts, "polyline"))
    problems = root.findall("planningProblem")
    if not problems:
        raise PlanningError(f"{p}: no <planningProblem>")
    problem = problems[0]
    if problem_id is not None:
        chosen = [q for q in problems if q.get("id") == str(problem_id)]
        if not chosen:
            ids = ", ".join(str(q.get("id")) for q in problems)
            raise PlanningError(f"{p}: no planning problem {problem_id!r} (the file has: {ids})")
        problem = chosen[0]
    where = f"{p}: planningProblem {problem.get('id')}"
    init, goal_el = problem.find("initialState"), problem.find("goalState")
    if init is None or goal_el is None:
        raise PlanningError(f"{where}: needs an <initialState> and a <goalState>")
    back = 0.5 * geom.length - geom.rear_overhang  # centre -> rear axle, m

    def rear_axle(xy, th):
        return np.array([xy[0] - back * math.cos(th), xy[1] - back * math.sin(th), th])

    lanes = _lanelets(root, str(p))
    start = rear_axle(*_state_pose(init, where))
    goal = rear_axle(*_state_pose(goal_el, where, lanes))
    pts = [start[None, :2], goal[None, :2], *[v for _, v, _ in drawn]]
    allp = np.concatenate(pts)
    m = cfg.commonroad_map_margin_m + geom.length
    lo, hi = allp.min(axis=0) - m, allp.max(axis=0) + m
    name = f"commonroad-{p.stem}-{problem.get('id')}"  # the file and the problem planned
    bounds = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    return _build(name, str(p), drawn, start, goal, bounds, cfg, ocfg)


def load_scene(
    spec: str, cfg: ScenariosConfig | None = None, geom: VehicleGeometry | None = None
) -> Scene:
    """A Scene from any ``--scene`` value: a TPCAP case ``.csv``, a CommonRoad ``.xml``
    (``FILE.xml#ID``: its planning problem ID), a scene JSON file, a grid cell 0-35 or
    ``robust:N`` (:func:`~parknss.sim.scenarios.resolve_scene`); grid scenes and
    CommonRoad poses for the car ``geom``."""
    cfg = cfg if cfg is not None else load_scenarios_config()
    text = spec.strip()
    path, _, problem = text.rpartition("#") if "#" in text else (text, "", None)
    if Path(path).suffix.lower() == ".xml":  # FILE.xml#ID: planning problem ID
        return read_commonroad(path, geom, cfg.imports, cfg.obstacles, problem or None)
    if Path(text).suffix.lower() in (".csv", ".xml"):
        return read_scene_file(text, cfg.obstacles, cfg.imports, geom)
    return resolve_scene(text, cfg, geom)


def read_scene_file(
    path: str | Path,
    ocfg: ObstacleInputConfig | None = None,
    cfg: SceneImportConfig | None = None,
    geom: VehicleGeometry | None = None,
) -> Scene:
    """A TPCAP ``.csv`` or CommonRoad ``.xml`` file as a scene."""
    p = Path(path)
    if p.suffix.lower() == ".csv":
        return read_tpcap(p, cfg, ocfg)
    if p.suffix.lower() == ".xml":
        return read_commonroad(p, geom, cfg, ocfg)
    raise PlanningError(f"{p}: not a TPCAP .csv or CommonRoad .xml file")
