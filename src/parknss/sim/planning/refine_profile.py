"""Speed profiles and path sampling for the refinement: trapezoids, warm starts, output.

* :func:`trapezoid` -- the rest-to-rest trapezoidal (or triangular) speed profile over a
  length, as speed and time at given arc positions, and its inverse :func:`trapezoid_at_time`.
* :func:`warm_start` -- the coarse segment driven stop-to-steer, sampled at N+1 knots.
* :func:`sample_solution` -- a solved segment resampled every ``step`` m of travel, exact on
  the solution's arcs, with speed, steering and time stamps.
"""

from __future__ import annotations

import math

import numpy as np

from parknss.sim import geometry
from parknss.sim.planning.refine_problem import SegmentSolution, WarmStart, heading_change
from parknss.sim.trajectory import Segment
from parknss.vehicle import VehicleGeometry, arc_step


def _peak(length: float, v_max: float, a_max: float) -> tuple[float, float, float, float]:
    """(peak speed m/s, ramp length m, ramp time s, total time s) of a rest-to-rest move."""
    vp = min(v_max, math.sqrt(a_max * max(length, 0.0)))
    if vp <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    s1, t1 = vp * vp / (2 * a_max), vp / a_max
    return vp, s1, t1, 2 * t1 + (length - 2 * s1) / vp


def trapezoid(arc: np.ndarray, v_max: float, a_max: float) -> tuple[np.ndarray, np.ndarray]:
    """(speed m/s, time s) at arc positions ``arc`` (N,) (0..length, increasing) of the
    trapezoidal rest-to-rest profile with cruise ``v_max`` and ramps ``a_max``."""
    s = np.asarray(arc, dtype=float)
    length = float(s[-1]) if len(s) else 0.0
    vp, s1, t1, total = _peak(length, v_max, a_max)
    if vp <= 0.0:
        return np.zeros_like(s), np.zeros_like(s)
    speed = np.minimum.reduce(
        [
            np.full_like(s, vp),
            np.sqrt(2 * a_max * s),
            np.sqrt(2 * a_max * np.maximum(length - s, 0)),
        ]
    )
    t = np.where(
        s <= s1,
        np.sqrt(2 * s / a_max),
        np.where(
            s <= length - s1,
            t1 + (s - s1) / vp,
            total - np.sqrt(2 * np.maximum(length - s, 0) / a_max),
        ),
    )
    speed[-1] = 0.0
    return speed, t


def trapezoid_at_time(t: np.ndarray, length: float, v_max: float, a_max: float):
    """(arc m, speed m/s) at times ``t`` (s) of the same profile; (total time s) as third."""
    vp, s1, t1, total = _peak(length, v_max, a_max)
    tt = np.clip(np.asarray(t, dtype=float), 0.0, total)
    if vp <= 0.0:
        return np.zeros_like(tt), np.zeros_like(tt), 0.0
    back = total - tt
    arc = np.where(
        tt <= t1,
        0.5 * a_max * tt**2,
        np.where(back >= t1, s1 + vp * (tt - t1), length - 0.5 * a_max * back**2),
    )
    speed = np.minimum.reduce([np.full_like(tt, vp), a_max * tt, a_max * back])
    return arc, speed, total


def poses_at(seg: Segment, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(poses (K, 3), index (K,) of the coarse interval) at arc positions ``s`` along ``seg``,
    following the circular arc through each pair of coarse poses."""
    arc = seg.arc_length
    i = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(arc) - 2)
    gap = np.maximum(arc[i + 1] - arc[i], 1e-12)
    tau = np.clip((s - arc[i]) / gap, 0.0, 1.0)
    return geometry.arc_interpolate(seg.poses[i], seg.poses[i + 1], tau), i


def _pieces(seg: Segment) -> tuple[np.ndarray, np.ndarray]:
    """(arc bounds (P+1,) m, steering-wheel angle (P,) deg) of the runs of constant
    steering along a coarse segment (one run if it carries no steering)."""
    arc = seg.arc_length
    if seg.steer is None:
        return np.array([0.0, arc[-1]]), np.zeros(1)
    st = np.asarray(seg.steer, dtype=float)[1:]  # steering of the arc ending at pose j+1
    new = np.flatnonzero(np.abs(np.diff(st)) > 1e-6) + 1
    bounds = np.concatenate([[0.0], arc[new], [arc[-1]]])
    return bounds, st[np.concatenate([[0], new])]


def least_intervals(
    length: float, v_max: float, a_max: float, jerk_max: float, dt_max: float
) -> int:
    """Enough intervals of at most ``dt_max`` (s) for a gear segment ``length`` (m) long
    to be driven rest to rest within the speed (m/s), acceleration (m/s²) and jerk
    (m/s³) limits: length / v + v / a + a / j (s), its least time at these limits when
    it is long enough to cruise (an upper bound of it otherwise), over ``dt_max``.
    TPCAP case 19's 37.2 m reverse needs 46.6 s, so 47 intervals: with ``max_intervals``
    (40) steps of 1 s it was infeasible (IPOPT: ``Infeasible_Problem_Detected``)."""
    t_min = length / v_max + v_max / a_max + a_max / jerk_max
    return math.ceil(t_min / dt_max - 1e-9)


def warm_start(
    seg: Segment,
    geom: VehicleGeometry,
    v_max: float,
    a_max: float,
    rate_dps: float,
    dt: float,
    n_min: int,
    n_max: int,
    n_floor: int = 0,
) -> WarmStart:
    """The coarse segment driven stop-to-steer, sampled at N+1 knots.

    Each run of constant steering is driven rest to rest with a trapezoid (``v_max``,
    ``a_max``), and between runs the wheel turns at standstill at ``rate_dps`` (deg/s).
    This is a feasible motion of the coarse path (up to the jerk bound), so the solver
    starts from a point that satisfies the dynamics, the bounds and the clearance, and a
    segment that must be driven at full lock on both sides of a steering change (a path
    on the boundary of the reachable set) still has its only solution available. N comes
    from the duration and ``dt`` (s), clamped to [n_min, n_max], but never fewer than
    ``n_floor`` (:func:`least_intervals`: a segment too long to be driven in ``n_max``
    steps of the solver's largest step; its warm-start step may then exceed that bound,
    and IPOPT moves the start inside it).
    """
    bounds, steer = _pieces(seg)
    lengths = np.diff(bounds)
    runs = [trapezoid_at_time(np.zeros(1), ln, v_max, a_max)[2] for ln in lengths]
    dwells = np.abs(np.diff(steer)) / rate_dps
    # timeline: run 0, dwell 0, run 1, dwell 1, ..., run P-1
    spans = np.empty(2 * len(runs) - 1)
    spans[0::2], spans[1::2] = runs, dwells
    edges = np.concatenate([[0.0], np.cumsum(spans)])
    total = float(edges[-1])
    n = int(min(max(math.ceil(total / dt), n_min), n_max))
    n = max(n, n_floor)
    t = np.linspace(0.0, total, n + 1)
    j = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(spans) - 1)
    s, speed, sw = np.empty(n + 1), np.zeros(n + 1), np.empty(n + 1)
    for k in range(n + 1):
        piece, tau = j[k] // 2, t[k] - edges[j[k]]
        if j[k] % 2 == 0:  # driving run `piece`
            arc, v, _ = trapezoid_at_time(np.array([tau]), lengths[piece], v_max, a_max)
            s[k], speed[k], sw[k] = bounds[piece] + arc[0], v[0], steer[piece]
        else:  # steering at standstill after run `piece`
            frac = tau / max(spans[j[k]], 1e-12)
            s[k] = bounds[piece + 1]
            sw[k] = steer[piece] + frac * (steer[piece + 1] - steer[piece])
    s[-1], speed[0], speed[-1] = seg.length, 0.0, 0.0
    poses, _ = poses_at(seg, s)
    poses[0], poses[-1] = seg.poses[0], seg.poses[-1]
    lock = math.radians(geom.steer_lock_deg / geom.steer_ratio)
    delta = np.clip(np.radians(sw) / geom.steer_ratio, -lock, lock)
    return WarmStart(poses, speed, delta, total / n, int(seg.direction))


def sample_solution(
    sol: SegmentSolution,
    direction: int,
    ends: tuple[np.ndarray, np.ndarray],
    geom: VehicleGeometry,
    step: float,
    blend: float = 1.0,
) -> Segment:
    """The solved segment as a dense :class:`Segment`: poses every <= ``step`` m along each
        interval's arc (knots included), speed (>= 0, 0 at the end), steering-wheel angle (deg)
        and time (s). Intervals without travel add no pose; their time carries over. The first
    and last poses are ``ends``; the solver met the end pose within its tolerance box, and
    that offset is blended in (:func:`blend_weights`: over the last ``blend`` m where the
    path has curvature to spare below the lock, else over the whole segment)."""
    p, v, de, h = sol.poses, np.maximum(sol.speed, 0.0), sol.delta, sol.h
    start_pose, end_pose = (np.asarray(e, dtype=float) for e in ends)
    n = len(p) - 1
    dist = h * (v[:-1] + v[1:]) / 2  # travel per interval, m
    turn = heading_change(v[:-1], v[1:], de[:-1], de[1:], h, geom.wheelbase)
    kap = turn / np.maximum(dist, 1e-12)  # curvature of each interval's arc, 1/m
    acc = (v[1:] - v[:-1]) / h
    out_p, out_v, out_d, out_t = [start_pose], [v[0]], [de[0]], [0.0]
    for k in range(n):
        if dist[k] <= 1e-6:
            continue
        m = max(1, math.ceil(dist[k] / step - 1e-9))
        sub = dist[k] * np.arange(1, m + 1) / m  # travelled within the interval, m
        sig = direction * sub
        out_p.extend(np.column_stack(arc_step(p[k, 0], p[k, 1], p[k, 2], sig, sig * kap[k])))
        root = np.sqrt(np.maximum(v[k] ** 2 + 2 * acc[k] * sub, 0.0))
        tau = np.clip(2 * sub / np.maximum(v[k] + root, 1e-12), 0.0, h)
        out_v.extend(np.maximum(v[k] + acc[k] * tau, 0.0))
        out_d.extend(de[k] + (de[k + 1] - de[k]) * tau / h)
        out_t.extend(k * h + tau)
    poses = np.asarray(out_p)
    speed, delta, t = np.asarray(out_v), np.asarray(out_d), np.asarray(out_t)
    if len(poses) < 2:  # no travel at all: keep the two end poses
        poses = np.vstack([start_pose, end_pose])
        speed, delta, t = np.zeros(2), de[[0, -1]], np.array([0.0, n * h])
    # the solver met the end pose to its tolerance box: blend the offset in so the path
    # ends exactly on it without a kink and without exceeding the lock (blend_weights)
    err = end_pose - poses[-1]
    err[2] = (err[2] + math.pi) % (2 * math.pi) - math.pi
    kappa_max = math.tan(math.radians(geom.steer_lock_deg / geom.steer_ratio)) / geom.wheelbase
    w = blend_weights(poses, kappa_max, blend, abs(float(err[2])))
    poses = poses + w[:, None] * err[None, :]
    poses[0], poses[-1] = start_pose, end_pose
    speed[0] = speed[-1] = 0.0  # standstill by constraint, to solver tolerance
    t[-1] = n * h
    steer = np.degrees(delta) * geom.steer_ratio
    return Segment(poses, direction, speed=speed, steer=steer, t=t)


def step_curvature(poses: np.ndarray) -> np.ndarray:
    """(P-1,) curvature (1/m) between consecutive poses (P, 3+): the wrapped heading change
    over the length of the arc through both (chord / sinc(Δθ/2)); 0 where poses coincide."""
    p = np.asarray(poses, dtype=float)
    dth = (np.diff(p[:, 2]) + math.pi) % (2 * math.pi) - math.pi
    ds = np.hypot(*np.diff(p[:, :2], axis=0).T) / np.sinc(0.5 * dth / math.pi)
    return np.where(ds > 1e-12, dth / np.maximum(ds, 1e-12), 0.0)


def blend_weights(poses: np.ndarray, kappa_max: float, blend: float, dheading: float):
    """(P,) weights 0 -> 1 along poses (P, 3) with which an end-pose offset is blended in.

    The weight of each step is the heading change it has to spare below the lock
    (kappa_max · ds - |Δθ|, rad), so a heading offset ``dheading`` (rad) is added only
    where the curvature stays under ``kappa_max`` (1/m): on a full-lock arc the offset is
    carried unchanged, and the path keeps within the lock whenever the spare heading
    change is at least twice the offset. The last ``blend`` m are used when they have
    enough to spare, else the whole segment; a path with none to spare anywhere falls
    back to a linear blend over the last ``blend`` m (the caller checks the curvature).
    """
    p = np.asarray(poses, dtype=float)
    ds = np.hypot(*np.diff(p[:, :2], axis=0).T)
    dth = np.abs((np.diff(p[:, 2]) + math.pi) % (2 * math.pi) - math.pi)
    spare = np.maximum(kappa_max * ds - dth, 0.0)
    arc = np.concatenate([[0.0], np.cumsum(ds)])
    tail = arc[1:] > arc[-1] - blend
    for use in (spare * tail, spare):
        total = float(use.sum())
        if total > 0.0 and total >= 2.0 * dheading:
            return np.concatenate([[0.0], np.cumsum(use)]) / total
    return np.clip((arc - (arc[-1] - blend)) / max(blend, 1e-9), 0.0, 1.0)


def profile_segment(seg: Segment, v_max: float, a_max: float) -> Segment:
    """The coarse segment with a trapezoidal speed and time profile (its poses unchanged)."""
    speed, t = trapezoid(seg.arc_length, v_max, a_max)
    steer = None if seg.steer is None else np.asarray(seg.steer, dtype=float).copy()
    return Segment(seg.poses.copy(), seg.direction, speed=speed, steer=steer, t=t)
