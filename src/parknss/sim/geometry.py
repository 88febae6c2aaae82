"""Exact planar geometry of the car and the scene: footprints, collision, clearance.

The car body is the rectangle of :class:`~parknss.vehicle.VehicleGeometry` (length,
width, rear overhang) around the rear-axle pose (x m, y m, heading rad). Obstacles are
convex polygons (vertices in m, either orientation). Every function here is exact (no
grids, no discs) and vectorised over many poses with NumPy: collision is the separating
axis theorem, clearance the Euclidean distance between the footprint and the polygon
(0 when they touch or overlap), computed as the smallest vertex-to-edge distance of the
two polygons, which is exact for disjoint convex polygons.

Paths are checked densely: :func:`densify` inserts poses so that no two consecutive poses
are more than ``max_step_m`` of travel or ``max_dheading_deg`` of heading apart (2 cm and
0.5° by default), because sampled search and sampled optimisation can both clip a corner
between samples.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from pydantic import Field

from parknss.config import StrictModel
from parknss.errors import PlanningError
from parknss.vehicle import VehicleGeometry


class DenseCheckConfig(StrictModel):
    """Spacing of the dense collision and clearance check along a path."""

    max_step_m: float = Field(0.02, gt=0.0, description="max travel between checks, m")
    max_dheading_deg: float = Field(0.5, gt=0.0, description="max heading change, deg")


# ---------------------------------------------------------------------------------------
# Polygons


def vertex_array(vertices, name: str, min_count: int) -> np.ndarray:
    """``vertices`` as a finite (M, 2) float array of at least ``min_count`` rows;
    PlanningError naming ``name`` in one line otherwise."""
    try:
        v = np.asarray(vertices, dtype=float)
    except (TypeError, ValueError) as exc:
        raise PlanningError(f"{name}: vertices are not numbers") from exc
    if v.ndim != 2 or v.shape[1] != 2 or len(v) < min_count:
        raise PlanningError(
            f"{name}: need at least {min_count} [x, y] vertices, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise PlanningError(f"{name}: vertices must be finite")
    return v


def convex_polygon(vertices, name: str = "polygon") -> np.ndarray:
    """Validate a convex polygon and return it as a (M, 2) counter-clockwise array.

    Raises PlanningError naming ``name`` if it has fewer than 3 vertices, non-finite
    values, no area, or is not convex. Either input orientation is accepted. Area and
    convexity are judged in a local frame (vertices minus the first), so a polygon far
    from the origin (TPCAP cases near 4e9 m) is judged like the same one at the origin.
    Scenes as drawn (non-convex, walls) go through :mod:`parknss.sim.obstacles`.
    """
    v = vertex_array(vertices, name, 3)
    loc = v - v[0]  # a local frame: area and convexity do not depend on where the map lies
    e = np.roll(loc, -1, axis=0) - loc
    cross = e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1)
    area2 = float(np.sum(loc[:, 0] * np.roll(loc[:, 1], -1) - loc[:, 1] * np.roll(loc[:, 0], -1)))
    if abs(area2) < 1e-9:
        raise PlanningError(f"{name}: polygon has no area")
    if area2 < 0:
        v, cross = v[::-1].copy(), -cross[::-1]
    if np.any(cross < -1e-9 * max(1.0, float(np.abs(cross).max()))):
        raise PlanningError(f"{name}: polygon is not convex (split it into convex parts)")
    return v


def rectangle(cx: float, cy: float, length: float, width: float, angle: float = 0.0):
    """(4, 2) CCW corners of a rectangle centred at (cx, cy), long side at ``angle`` rad."""
    c, s = math.cos(angle), math.sin(angle)
    hl, hw = 0.5 * length, 0.5 * width
    local = np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw]])
    return local @ np.array([[c, s], [-s, c]]) + np.array([cx, cy])


def body_corners(geom: VehicleGeometry, margin: float = 0.0) -> np.ndarray:
    """(4, 2) CCW footprint corners in the rear-axle frame (x forward, y left), m."""
    rear = -geom.rear_overhang - margin
    front = geom.length - geom.rear_overhang + margin
    hw = 0.5 * geom.width + margin
    return np.array([[rear, -hw], [front, -hw], [front, hw], [rear, hw]])


def footprints(poses, geom: VehicleGeometry, margin: float = 0.0) -> np.ndarray:
    """(N, 4, 2) CCW footprint corners at rear-axle poses (N, 3+) [x, y, heading]."""
    p = np.atleast_2d(np.asarray(poses, dtype=float))
    local = body_corners(geom, margin)
    c, s = np.cos(p[:, 2])[:, None], np.sin(p[:, 2])[:, None]
    x = p[:, 0:1] + c * local[None, :, 0] - s * local[None, :, 1]
    y = p[:, 1:2] + s * local[None, :, 0] + c * local[None, :, 1]
    return np.stack([x, y], axis=-1)


def footprint(pose, geom: VehicleGeometry, margin: float = 0.0) -> np.ndarray:
    """(4, 2) CCW footprint corners at one rear-axle pose, optionally grown by ``margin``."""
    return footprints(np.asarray(pose, dtype=float)[None, :3], geom, margin)[0]


# ---------------------------------------------------------------------------------------
# Collision and distance (batched polygons A (N, K, 2) against one polygon B (M, 2))


def _normals(poly: np.ndarray) -> np.ndarray:
    """Edge normals (unnormalised) of CCW polygons, (..., K, 2)."""
    e = np.roll(poly, -1, axis=-2) - poly
    return np.stack([e[..., 1], -e[..., 0]], axis=-1)


def intersects(polys: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(N,) True where convex polygon ``polys[i]`` (N, K, 2) overlaps or touches ``poly``.

    Separating axis theorem over the edge normals of both polygons.
    """
    a = np.asarray(polys, dtype=float)
    b = np.asarray(poly, dtype=float)
    sep = np.zeros(a.shape[0], dtype=bool)
    na = _normals(a)  # (N, K, 2)
    pa = np.einsum("nkd,njd->nkj", na, a)  # A on its own axes: (N, K axes, K verts)
    pb = np.einsum("nkd,md->nkm", na, b)
    sep |= np.any((pa.max(-1) < pb.min(-1)) | (pb.max(-1) < pa.min(-1)), axis=1)
    nb = _normals(b)  # (M, 2)
    qa = np.einsum("md,nkd->nmk", nb, a)
    qb = nb @ b.T  # (M axes, M verts)
    sep |= np.any((qa.max(-1) < qb.min(-1)[None]) | (qb.max(-1)[None] < qa.min(-1)), axis=1)
    return ~sep


def _point_segment_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points p to segments a-b (broadcast shapes (..., 2))."""
    ab = b - a
    ap = p - a
    denom = np.maximum(np.sum(ab * ab, axis=-1), 1e-300)
    t = np.clip(np.sum(ap * ab, axis=-1) / denom, 0.0, 1.0)
    d = ap - t[..., None] * ab
    return np.sqrt(np.sum(d * d, axis=-1))


def point_distance(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(N,) distance in m from points (N, 2) to a convex CCW polygon (M, 2); 0 inside."""
    p = np.asarray(points, dtype=float)
    b = np.asarray(poly, dtype=float)
    px, py = p[:, 0], p[:, 1]
    best = np.full(len(p), np.inf)
    inside = np.ones(len(p), dtype=bool)
    for k in range(len(b)):
        ax, ay = b[k]
        ex, ey = b[(k + 1) % len(b)] - b[k]
        rx, ry = px - ax, py - ay
        inside &= ex * ry - ey * rx >= 0.0  # left of every CCW edge
        t = np.clip((rx * ex + ry * ey) / max(ex * ex + ey * ey, 1e-300), 0.0, 1.0)
        dx, dy = rx - t * ex, ry - t * ey
        np.minimum(best, dx * dx + dy * dy, out=best)
    return np.where(inside, 0.0, np.sqrt(best))


def distance(polys: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(N,) exact distance between convex polygons ``polys`` (N, K, 2) and ``poly`` (M, 2).

    Zero where they overlap or touch; otherwise the smallest vertex-to-edge distance.
    """
    a = np.asarray(polys, dtype=float)
    b = np.asarray(poly, dtype=float)
    a_next = np.roll(a, -1, axis=1)
    b_next = np.roll(b, -1, axis=0)
    # vertices of A against edges of B: (N, K, M)
    d1 = _point_segment_dist(a[:, :, None, :], b[None, None, :, :], b_next[None, None, :, :])
    # vertices of B against edges of A: (N, M, K)
    d2 = _point_segment_dist(b[None, :, None, :], a[:, None, :, :], a_next[:, None, :, :])
    d = np.minimum(d1.min(axis=(1, 2)), d2.min(axis=(1, 2)))
    return np.where(intersects(a, b), 0.0, d)


def body_circles(poses, geom: VehicleGeometry) -> tuple[np.ndarray, np.ndarray, float]:
    """(cx (N,), cy (N,), r m): centre of the footprint at each rear-axle pose (N, 3+) and
    the radius of the circle through its corners, the broad phase of clearance and
    collision (the footprint lies inside the circle)."""
    p = np.atleast_2d(np.asarray(poses, dtype=float))
    local = body_corners(geom)
    c = local.mean(axis=0)
    r = float(np.hypot(*(local[0] - c)))
    cx = p[:, 0] + np.cos(p[:, 2]) * c[0] - np.sin(p[:, 2]) * c[1]
    cy = p[:, 1] + np.sin(p[:, 2]) * c[0] + np.cos(p[:, 2]) * c[1]
    return cx, cy, r


def polygon_circle(poly) -> tuple[np.ndarray, float]:
    """(centre (2,), r m): the vertex centroid of a polygon (M, 2) and the radius of the
    circle about it through its farthest vertex (a convex polygon lies inside it)."""
    o = np.asarray(poly, dtype=float)
    oc = o.mean(axis=0)
    return oc, float(np.max(np.hypot(*(o - oc).T)))


def polygon_circles(polygons: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(centres (M, 2), radii (M,)) of :func:`polygon_circle` for M polygons."""
    circles = [polygon_circle(o) for o in polygons]
    return (
        np.array([c for c, _ in circles], dtype=float).reshape(-1, 2),
        np.array([r for _, r in circles], dtype=float),
    )


def clearance(
    poses,
    geom: VehicleGeometry,
    obstacles: Sequence[np.ndarray],
    cutoff: float | None = None,
    chunk: int = 4096,
) -> np.ndarray:
    """(N,) distance in m from the footprint at each pose to the nearest obstacle.

    ``inf`` when there are no obstacles; 0 where the footprint touches or overlaps one.
    With ``cutoff`` (m), obstacle/pose pairs whose bounding circles are farther apart
    than ``cutoff`` are skipped, so values above ``cutoff`` are lower bounds (every
    value below it is exact). This is what makes dense path checks cheap.
    """
    p = np.atleast_2d(np.asarray(poses, dtype=float))
    out = np.full(len(p), np.inf)
    if not len(p):
        return out
    cx, cy, r_car = body_circles(p, geom)
    for obs in obstacles:
        o = np.asarray(obs, dtype=float)
        oc, r_obs = polygon_circle(o)
        gap = np.hypot(cx - oc[0], cy - oc[1]) - r_car - r_obs  # lower bound of distance
        if cutoff is None:
            idx = np.arange(len(p))
        else:
            near = gap <= cutoff
            idx = np.flatnonzero(near)
            out[~near] = np.minimum(out[~near], gap[~near])
        for i in range(0, len(idx), chunk):
            sel = idx[i : i + chunk]
            out[sel] = np.minimum(out[sel], distance(footprints(p[sel], geom), o))
    return out


def collides(
    poses,
    geom: VehicleGeometry,
    obstacles: Sequence[np.ndarray],
    margin: float = 0.0,
    circles: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """(N,) True where the footprint is closer than ``margin`` m to any obstacle.

    With ``margin = 0`` this is pure SAT overlap (touching counts as a collision), tested
    only for obstacles whose bounding circle meets the footprint's (:func:`body_circles`)
    at some pose; ``circles`` are the obstacles' :func:`polygon_circles` when the caller
    checks the same obstacles many times.
    """
    p = np.atleast_2d(np.asarray(poses, dtype=float))
    if margin <= 0.0:
        hit = np.zeros(len(p), dtype=bool)
        if not len(obstacles) or not len(p):
            return hit
        oc, r_obs = circles if circles is not None else polygon_circles(obstacles)
        cx, cy, r_car = body_circles(p, geom)
        # broad phase: obstacles whose bounding circle no pose's circle meets (1 µm of
        # slack) cannot overlap; the others get the exact test on every pose
        gap = np.hypot(cx[:, None] - oc[:, 0], cy[:, None] - oc[:, 1])
        near = np.flatnonzero(np.any(gap <= r_car + r_obs + 1e-6, axis=0))
        if len(near):
            fp = footprints(p, geom)
            for j in near:
                hit |= intersects(fp, obstacles[j])
        return hit
    return clearance(p, geom, obstacles) < margin


def inside_bounds(poses, geom: VehicleGeometry, bounds) -> np.ndarray:
    """(N,) True where the whole footprint lies in bounds (xmin, ymin, xmax, ymax), m."""
    fp = footprints(poses, geom)
    xmin, ymin, xmax, ymax = bounds
    x, y = fp[..., 0], fp[..., 1]
    return np.all((x >= xmin) & (x <= xmax) & (y >= ymin) & (y <= ymax), axis=1)


def inside_planes(poses, geom: VehicleGeometry, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) True where the whole footprint satisfies A @ p <= b (a convex map), m."""
    fp = footprints(poses, geom)
    return np.all(np.einsum("nkj,mj->nkm", fp[..., :2], A) <= b, axis=(1, 2))


def inside_map(poses, geom: VehicleGeometry, scene) -> np.ndarray:
    """(N,) True where the whole footprint lies on the scene's map (its box ``bounds``,
    and its ``map_outline`` when it has one)."""
    ok = inside_bounds(poses, geom, scene.bounds)
    if getattr(scene, "map_outline", None) is not None:
        ok &= inside_planes(poses, geom, *scene.map_planes())
    return ok


# ---------------------------------------------------------------------------------------
# Dense checking along a path


def arc_interpolate(p0: np.ndarray, p1: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Poses at fractions ``tau`` (M,) between pose pairs p0, p1 (M, 3+), (M, 3).

    The car follows the circular arc (or line) from p0 to p1 whose heading changes
    linearly, which is exact when the pair lies on a kinematic-bicycle arc. This is the
    inverse problem of :func:`parknss.vehicle.arc_step` (the arc is given by its two end
    poses, not by a start pose and a curvature), written in the chord form that every
    dense check and path reference has always used; the tests check it against
    ``arc_step`` to 1e-12. (Rewritten as a call of ``arc_step`` it rounds differently in
    the last bits, which moves IPOPT's refined plans and so Table V.)
    """
    d = p1[:, :2] - p0[:, :2]
    chord = np.hypot(d[:, 0], d[:, 1])
    dth = (p1[:, 2] - p0[:, 2] + np.pi) % (2 * np.pi) - np.pi
    half = 0.5 * dth
    sub = chord * tau * np.sinc(tau * half / np.pi) / np.sinc(half / np.pi)
    ang = np.arctan2(d[:, 1], d[:, 0]) + (tau - 1.0) * half
    return np.column_stack(
        [p0[:, 0] + sub * np.cos(ang), p0[:, 1] + sub * np.sin(ang), p0[:, 2] + tau * dth]
    )


def interval_counts(p0: np.ndarray, p1: np.ndarray, max_step: float, max_dheading: float):
    """(M,) number of sub-steps so each is <= max_step m of arc and <= max_dheading rad."""
    d = p1[:, :2] - p0[:, :2]
    chord = np.hypot(d[:, 0], d[:, 1])
    dth = (p1[:, 2] - p0[:, 2] + np.pi) % (2 * np.pi) - np.pi
    arc = chord / np.sinc(0.5 * dth / np.pi)  # arc length >= chord
    n = np.ceil(np.maximum(arc / max_step, np.abs(dth) / max_dheading) - 1e-9)
    return np.maximum(1, n).astype(int)


def densify_pairs(p0: np.ndarray, p1: np.ndarray, max_step: float, max_dheading: float):
    """Dense poses strictly after p0 up to and including p1, for M independent pairs.

    Returns (poses (T, 3), pair (T,) index of the pair, j (T,) sub-step 1..n, n (M,)).
    """
    n = interval_counts(p0, p1, max_step, max_dheading)
    pair = np.repeat(np.arange(len(n)), n)
    j = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n) + 1
    poses = arc_interpolate(p0[pair], p1[pair], j / n[pair])
    return poses, pair, j, n


def densify(poses, max_step: float = 0.02, max_dheading: float = math.radians(0.5)):
    """Insert poses so consecutive ones are <= max_step m and <= max_dheading rad apart.

    ``poses`` is (N, 3+) [x, y, heading, ...]; extra columns are repeated from the left
    pose of each interval. Between two poses the car follows the circular arc (or line)
    through both whose heading changes linearly, exact for kinematic-bicycle paths.
    Returns (M, C) with the original poses included, in order.
    """
    p = np.atleast_2d(np.asarray(poses, dtype=float))
    if len(p) < 2:
        return p.copy()
    n = interval_counts(p[:-1], p[1:], max_step, max_dheading)
    seg = np.repeat(np.arange(len(n)), n)
    tau = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
    out = np.empty((len(seg) + 1, p.shape[1]))
    out[:-1] = p[seg]
    out[:-1, :3] = arc_interpolate(p[:-1][seg], p[1:][seg], tau)
    out[-1] = p[-1]
    return out


def dense_clearance(
    poses,
    geom: VehicleGeometry,
    obstacles: Sequence[np.ndarray],
    cfg: DenseCheckConfig | None = None,
) -> tuple[float, int]:
    """Minimum exact clearance (m) along a densified path and the index of the worst pose.

    The index refers to ``densify(poses, ...)``. Returns (inf, -1) with no obstacles.
    Exact whenever the minimum is below 1 m (farther obstacle pairs are bounded, not
    computed).
    """
    cfg = cfg or DenseCheckConfig()
    dense = densify(poses, cfg.max_step_m, math.radians(cfg.max_dheading_deg))
    if not obstacles:
        return math.inf, -1
    c = clearance(dense, geom, obstacles, cutoff=1.0)
    i = int(np.argmin(c))
    return float(c[i]), i
