"""Obstacle data of the H-OBCA collision constraints: half-spaces, broad phase, dual warm start.

The distance between the car body E(x) = {R(θ) e + t : G e <= g} (the footprint
rectangle in the rear-axle frame, t = rear-axle position) and a convex obstacle
O = {y : A y <= b} is, by LP duality (Zhang et al. 2018),

    dist(E, O) = max  (A t - b)ᵀ λ - gᵀ μ
                 s.t. Gᵀ μ + R(θ)ᵀ Aᵀ λ = 0,  ||Aᵀ λ||₂ <= 1,  λ >= 0,  μ >= 0,

so "exists λ, μ >= 0 with those equalities and (A t - b)ᵀ λ - gᵀ μ >= d_min" is exactly
dist >= d_min. Here A has unit outward edge normals as rows (b_i = a_i · v_i), and
G = [e_x, e_y, -e_x, -e_y], g = [front, W/2, rear overhang, W/2] (m).

The warm start of the duals is the optimum itself at the warm-start pose: w = Aᵀ λ is the
unit direction from the obstacle's closest point to the car's, λ the non-negative
combination of the two obstacle normals whose cone contains w, and μ the positive and
negative parts of -Rᵀ w.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parknss.sim import geometry
from parknss.sim.obstacles import clean_vertices
from parknss.vehicle import VehicleGeometry


@dataclass
class ObstacleTerm:
    """One obstacle's collision constraints in one segment's problem.

    Attributes:
        poly: (M, 2) the CCW obstacle polygon, m.
        A: (M, 2) unit outward edge normals; b: (M,) offsets, A y <= b inside, m.
        knots: (K,) indices of the knots (1..N-1) constrained against this obstacle.
        lam0: (M, K) and mu0: (4, K) warm-start dual multipliers.
    """

    poly: np.ndarray
    A: np.ndarray
    b: np.ndarray
    knots: np.ndarray
    lam0: np.ndarray
    mu0: np.ndarray


def halfspaces(poly: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A (M, 2), b (M,)) of a CCW convex polygon (M, 2): unit outward normals, offsets."""
    v = np.asarray(poly, dtype=float)
    e = np.roll(v, -1, axis=0) - v
    n = np.column_stack([e[:, 1], -e[:, 0]])
    n /= np.hypot(n[:, 0], n[:, 1])[:, None]
    return n, np.einsum("md,md->m", n, v)


def body_box(geom: VehicleGeometry) -> np.ndarray:
    """g (4,) of the body rectangle G e <= g in the rear-axle frame, m."""
    hw = 0.5 * geom.width
    return np.array([geom.length - geom.rear_overhang, hw, geom.rear_overhang, hw])


def _closest_direction(fp: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(N, 2) unit vectors from the obstacle's closest point to the footprint's.

    ``fp`` (N, 4, 2) footprints, ``poly`` (M, 2) CCW. Overlapping pairs get the
    direction from the obstacle's centroid to the footprint's centre.
    """
    a, a_next = fp, np.roll(fp, -1, axis=1)
    b, b_next = poly, np.roll(poly, -1, axis=0)

    def closest(p, s0, s1):  # points p (..., 2) onto segments s0-s1 (..., 2)
        d = s1 - s0
        t = np.clip(np.sum((p - s0) * d, -1) / np.maximum(np.sum(d * d, -1), 1e-300), 0, 1)
        return s0 + t[..., None] * d

    # footprint vertices against obstacle edges: (N, 4, M)
    q1 = closest(a[:, :, None, :], b[None, None], b_next[None, None])
    v1 = a[:, :, None, :] - q1
    # obstacle vertices against footprint edges: (N, M, 4); vector obstacle -> car
    q2 = closest(b[None, :, None, :], a[:, None], a_next[:, None])
    v2 = q2 - b[None, :, None, :]
    n = len(fp)
    v1, v2 = v1.reshape(n, -1, 2), v2.reshape(n, -1, 2)
    d1, d2 = np.hypot(v1[..., 0], v1[..., 1]), np.hypot(v2[..., 0], v2[..., 1])
    i1, i2 = d1.argmin(1), d2.argmin(1)
    rows = np.arange(n)
    use1 = d1[rows, i1] <= d2[rows, i2]
    vec = np.where(use1[:, None], v1[rows, i1], v2[rows, i2])
    dist = np.hypot(vec[:, 0], vec[:, 1])
    centre = fp.mean(axis=1) - poly.mean(axis=0)
    overlap = geometry.intersects(fp, poly) | (dist < 1e-9)
    vec = np.where(overlap[:, None], centre, vec)
    return vec / np.maximum(np.hypot(vec[:, 0], vec[:, 1]), 1e-12)[:, None]


def strict_polygon(poly: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """``poly`` (M, 2) without duplicate or collinear vertices (judged in a local frame), so
    consecutive edge normals are never parallel: the dual warm start divides by their
    cross product."""
    v = np.asarray(poly, dtype=float)
    kept, removed = clean_vertices(v - v[0], tol, closed=True)
    return kept + v[0] if removed and len(kept) >= 3 else v


def dual_warm_start(poses: np.ndarray, poly: np.ndarray, A: np.ndarray, geom: VehicleGeometry):
    """(λ (M, N), μ (4, N)) at rear-axle poses (N, 3): the dual optimum of the distance.

    Consecutive parallel normals (a collinear vertex) span no cone; they are skipped
    rather than divided by zero."""
    fp = geometry.footprints(poses, geom)
    w = _closest_direction(fp, poly)  # (N, 2)
    a0, a1 = A, np.roll(A, -1, axis=0)  # consecutive normals (M, 2)
    det = a0[:, 0] * a1[:, 1] - a0[:, 1] * a1[:, 0]  # > 0 for a strictly convex CCW polygon
    ok = det > 1e-12
    safe = np.where(ok, det, 1.0)
    c0 = (w[:, None, 0] * a1[None, :, 1] - w[:, None, 1] * a1[None, :, 0]) / safe
    c1 = (a0[None, :, 0] * w[:, None, 1] - a0[None, :, 1] * w[:, None, 0]) / safe
    score = np.where(ok[None, :], np.minimum(c0, c1), -np.inf)
    pick = score.argmax(axis=1)  # the cone that contains w
    rows = np.arange(len(poses))
    m = len(A)
    lam = np.zeros((len(poses), m))
    lam[rows, pick] = np.maximum(c0[rows, pick], 0.0)
    lam[rows, (pick + 1) % m] += np.maximum(c1[rows, pick], 0.0)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    m1 = -(c * w[:, 0] + s * w[:, 1])
    m2 = s * w[:, 0] - c * w[:, 1]
    mu = np.stack([np.maximum(m1, 0), np.maximum(m2, 0), np.maximum(-m1, 0), np.maximum(-m2, 0)])
    return lam.T, mu


def obstacle_terms(
    poses: np.ndarray,
    obstacles: list[np.ndarray],
    geom: VehicleGeometry,
    reach_m: float,
    window: int,
) -> list[ObstacleTerm]:
    """Broad phase and warm start for one segment's knots ``poses`` (N+1, 3).

    Obstacle m constrains interior knot k (1..N-1) when the warm-start clearance of a
    knot within ``window`` of k is below ``reach_m``. Obstacles constraining no knot are
    left out of the problem.
    """
    n = len(poses)
    interior = np.arange(1, n - 1)
    terms: list[ObstacleTerm] = []
    if not len(interior):
        return terms
    fp = geometry.footprints(poses, geom)
    cx, cy, r_car = geometry.body_circles(poses, geom)
    for poly in obstacles:
        # bounding circles first: their gap is a lower bound of the distance, so only
        # the knots within reach of the circles need the exact distance
        centre, r_obs = geometry.polygon_circle(poly)
        cand = np.flatnonzero(np.hypot(cx - centre[0], cy - centre[1]) - r_car - r_obs < reach_m)
        if not len(cand):
            continue
        poly = strict_polygon(poly)
        near = np.zeros(n, dtype=bool)
        near[cand] = geometry.distance(fp[cand], poly) < reach_m
        if window:
            idx = np.flatnonzero(near)
            grown = np.zeros(n, dtype=bool)
            for k in idx:
                grown[max(0, k - window) : k + window + 1] = True
            near = grown
        knots = interior[near[interior]]
        if not len(knots):
            continue
        A, b = halfspaces(poly)
        lam0, mu0 = dual_warm_start(poses[knots], poly, A, geom)
        terms.append(ObstacleTerm(np.asarray(poly, dtype=float), A, b, knots, lam0, mu0))
    return terms


def rewarm(terms: list[ObstacleTerm], poses: np.ndarray, geom: VehicleGeometry) -> None:
    """Recompute each term's warm-start duals at new knot poses (N+1, 3), in place."""
    for term in terms:
        term.lam0, term.mu0 = dual_warm_start(poses[term.knots], term.poly, term.A, geom)
