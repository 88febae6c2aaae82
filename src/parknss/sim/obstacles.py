"""Obstacles as users draw them: any simple polygon, a wall drawn as a line, split into the
convex parts that the planner, the dense check and the refinement use.

An obstacle is given as vertices (m) and a shape: ``"polygon"`` (a closed ring, either
orientation, convex or not) or ``"polyline"`` (an open line: a wall). :func:`drawn_obstacle`
turns one into an :class:`Outline` (the shape as drawn, CCW, m) and its convex parts:

1. **Local frame.** Every test below runs on the vertices minus their first vertex, so a
   map near 4e9 m (TPCAP cases 13-15) is judged like one at the origin.
2. **Normalisation (documented, counted).** Consecutive duplicate vertices (closer than
   ``vertex_tolerance_m``) and collinear vertices (off the line through their neighbours
   by less than that) are removed; the count is reported, never silently.
3. **Walls.** A polyline, or a polygon with no area (every vertex on one line, within the
   tolerance), becomes a wall of ``wall_thickness_m``: the line thickened by half the
   thickness on each side, square caps and mitred joins (shapely's buffer).
4. **Refusals (one line each).** Non-finite coordinates, fewer than 2 distinct vertices
   (a polygon of 2 has no area: a wall), self-intersections, holes, and more vertices
   than ``max_vertices_per_obstacle``.
5. **Convex parts.** A convex outline is its own single part (bit for bit the vertices
   given, CCW); a non-convex one is triangulated (shapely's constrained Delaunay) and the
   triangles merged greedily across shared edges while the union stays convex
   (Hertel-Mehlhorn): at most four times the minimum number of parts.

The union of the parts is the outline, so the minimum distance to the parts is the exact
distance to the outline: the dense clearance is the distance to the shape as drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from parknss.config import StrictModel
from parknss.errors import PlanningError
from parknss.sim.geometry import vertex_array

SHAPES = ("polygon", "polyline")


class ObstacleInputConfig(StrictModel):
    """Limits and tolerances of scene obstacles as drawn (``obstacles:`` in scenarios.yaml)."""

    wall_thickness_m: float = Field(0.1, gt=0, description="thickness of walls drawn as lines, m")
    vertex_tolerance_m: float = Field(
        1e-6, gt=0, description="duplicate / collinear vertex tolerance, m"
    )
    max_obstacles: int = Field(2000, ge=1, description="obstacles per scene, at most")
    max_vertices_per_obstacle: int = Field(1000, ge=3, description="vertices per obstacle")
    max_vertices_total: int = Field(20000, ge=3, description="vertices per scene, at most")


class SceneImportConfig(StrictModel):
    """How benchmark scenes are imported (``imports:`` in scenarios.yaml)."""

    tpcap_map_margin_m: float = Field(8.0, ge=0, description="map beyond start/goal box, m")
    commonroad_map_margin_m: float = Field(5.0, ge=0, description="map beyond everything, m")
    circle_segments: int = Field(16, ge=6, description="sides of a CommonRoad circle's polygon")
    commonroad_lanelet_walls: bool = Field(False, description="lanelet bounds become walls")
    local_frame_beyond_m: float = Field(1e4, gt=0, description="shift maps farther than this, m")


@dataclass(frozen=True)
class Outline:
    """One obstacle after :func:`drawn_obstacle`.

    Attributes:
        vertices: (M, 2) CCW outline as drawn (a wall: the thickened line), m.
        parts: convex (K_i, 2) CCW polygons whose union is the outline, m.
        removed: duplicate or collinear vertices removed by the normalisation.
        wall: True when the input was a line (or had no area) and became a wall.
    """

    vertices: np.ndarray
    parts: tuple[np.ndarray, ...]
    removed: int = 0
    wall: bool = False


def _signed_area2(v: np.ndarray) -> float:
    return float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - v[:, 1] * np.roll(v[:, 0], -1)))


def clean_vertices(local: np.ndarray, tol: float, closed: bool) -> tuple[np.ndarray, int]:
    """Remove consecutive duplicates and collinear vertices of ``local`` (N, 2) m (already in
    a local frame); (kept (K, 2), number removed). A closed ring wraps around."""
    v = local
    n0 = len(v)
    changed = True
    while changed and len(v) >= 2:
        changed = False
        nxt = np.roll(v, -1, axis=0)
        d = np.hypot(*(nxt - v).T)
        if not closed:
            d[-1] = np.inf
        dup = d < tol
        if np.any(dup):
            v = v[~dup] if not dup.all() else v[:1]
            changed = True
            continue
        if len(v) < 3:
            break
        prev = np.roll(v, 1, axis=0)
        nxt = np.roll(v, -1, axis=0)
        base = nxt - prev
        cross = (v[:, 0] - prev[:, 0]) * base[:, 1] - (v[:, 1] - prev[:, 1]) * base[:, 0]
        off = np.abs(cross) / np.maximum(np.hypot(*base.T), 1e-300)
        # collinear and between its neighbours (a spike that doubles back is not removed
        # here: it makes the ring self-intersect or have no area, both judged later)
        along = np.sum((v - prev) * base, axis=1)
        between = (along > 0) & (along < np.sum(base * base, axis=1))
        col = (off < tol) & between
        if not closed:
            col[0] = col[-1] = False
        if np.any(col):
            i = int(np.flatnonzero(col)[0])  # one at a time: neighbours change
            v = np.delete(v, i, axis=0)
            changed = True
    return v, n0 - len(v)


def _is_convex_ccw(v: np.ndarray) -> bool:
    e = np.roll(v, -1, axis=0) - v
    cross = e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1)
    return bool(np.all(cross > -1e-12 * max(1.0, float(np.abs(cross).max()))))


def _ring(poly) -> np.ndarray:
    """(M, 2) CCW vertices of a shapely polygon without the closing repeat."""
    from shapely.geometry.polygon import orient

    return np.asarray(orient(poly, 1.0).exterior.coords, dtype=float)[:-1]


def convex_parts(local: np.ndarray) -> list[np.ndarray]:
    """Convex CCW parts (local frame) of a simple CCW polygon ``local`` (M, 2): itself when
    convex, else constrained Delaunay triangles merged greedily (Hertel-Mehlhorn)."""
    if _is_convex_ccw(local):
        return [local]
    import shapely
    from shapely.geometry import Polygon

    tris = [_ring(t) for t in shapely.constrained_delaunay_triangles(Polygon(local)).geoms]
    parts = [Polygon(t) for t in tris if abs(_signed_area2(t)) > 0.0]
    merged = True
    while merged:
        merged = False
        for i in range(len(parts)):
            for j in range(i + 1, len(parts)):
                if parts[i].intersection(parts[j]).length <= 0.0:
                    continue  # no shared edge
                union = parts[i].union(parts[j])
                if union.geom_type != "Polygon":
                    continue
                cand = _ring(union.simplify(0.0))
                if _is_convex_ccw(cand):
                    parts[i] = Polygon(cand)
                    del parts[j]
                    merged = True
                    break
            if merged:
                break
    return [_ring(p.simplify(0.0)) for p in parts]


def _wall(local: np.ndarray, thickness: float, name: str) -> np.ndarray:
    """CCW outline (local frame) of the line through ``local`` thickened to ``thickness``."""
    from shapely.geometry import LineString

    if len(local) < 2:
        raise PlanningError(f"{name}: a wall needs 2 distinct vertices")
    shape = LineString(local).buffer(0.5 * thickness, cap_style="square", join_style="mitre")
    if shape.geom_type != "Polygon" or len(shape.interiors):
        raise PlanningError(f"{name}: the wall line crosses itself")
    return _ring(shape.simplify(0.0))


def drawn_obstacle(
    vertices,
    name: str = "obstacle",
    shape: str = "polygon",
    cfg: ObstacleInputConfig | None = None,
) -> Outline:
    """Validate, normalise and split one drawn obstacle (module docstring); PlanningError
    naming ``name`` with one line when it is refused."""
    cfg = cfg or ObstacleInputConfig()
    if shape not in SHAPES:
        raise PlanningError(f"{name}: shape must be one of {', '.join(SHAPES)}, got {shape!r}")
    v = vertex_array(vertices, name, 2)
    if len(v) > cfg.max_vertices_per_obstacle:
        raise PlanningError(
            f"{name}: {len(v)} vertices, more than max_vertices_per_obstacle "
            f"({cfg.max_vertices_per_obstacle})"
        )
    origin = v[0].copy()
    local = v - origin
    tol = cfg.vertex_tolerance_m
    if shape == "polygon" and len(local) > 2 and np.hypot(*(local[-1] - local[0])) < tol:
        local = local[:-1]  # a ring given closed: the repeat is not a vertex
    closed = shape == "polygon"
    kept, removed = clean_vertices(local, tol, closed)
    flat = len(kept) < 3 or _off_line(kept) < cfg.vertex_tolerance_m
    if shape == "polyline" or flat:
        line = kept if shape == "polyline" else _extent(kept)
        outline = _wall(line, cfg.wall_thickness_m, name)
        return Outline(
            outline + origin, tuple(p + origin for p in convex_parts(outline)), removed, True
        )
    from shapely.geometry import Polygon
    from shapely.validation import explain_validity

    poly = Polygon(kept)
    if not poly.is_valid:
        why = explain_validity(poly).split("[")[0].strip().lower()
        raise PlanningError(f"{name}: polygon is not simple ({why}); draw it without crossings")
    if _signed_area2(kept) < 0:
        kept = kept[::-1].copy()
    return Outline(kept + origin, tuple(p + origin for p in convex_parts(kept)), removed, False)


def _off_line(local: np.ndarray) -> float:
    """Largest distance (m) of the vertices from the line through the two farthest apart."""
    a, b = _extent(local)
    d = b - a
    n = np.hypot(*d)
    if n <= 0.0:
        return 0.0
    r = local - a
    return float(np.max(np.abs(r[:, 0] * d[1] - r[:, 1] * d[0])) / n)


def _extent(local: np.ndarray) -> np.ndarray:
    """The two extreme points of collinear vertices (a polygon with no area), local frame."""
    if len(local) < 2:
        return local
    d = local - local[0]
    axis = d[int(np.argmax(np.hypot(*d.T)))]
    t = d @ axis
    return np.array([local[int(np.argmin(t))], local[int(np.argmax(t))]])


def check_counts(n_obstacles: int, n_vertices: int, source: str, cfg: ObstacleInputConfig) -> None:
    """One-line PlanningError when a scene has more obstacles or vertices than the caps."""
    if n_obstacles > cfg.max_obstacles:
        raise PlanningError(
            f"{source}: {n_obstacles} obstacles, more than max_obstacles ({cfg.max_obstacles})"
        )
    if n_vertices > cfg.max_vertices_total:
        raise PlanningError(
            f"{source}: {n_vertices} obstacle vertices, more than max_vertices_total "
            f"({cfg.max_vertices_total})"
        )
