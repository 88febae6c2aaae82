"""The nonlinear program of one gear segment (CasADi SX, IPOPT), built once per structure.

Knots k = 0..N carry the state [x, y, θ, v, δ]: rear-axle position (m), heading (rad),
speed magnitude v >= 0 (m/s; the car moves in the segment's direction d = ±1) and
road-wheel angle δ (rad). Intervals k = 0..N-1 carry the controls [a, ω]: acceleration
(m/s²) and steering rate (rad/s of road wheel), constant over an interval of the free
time step h (s, shared by the segment). Over an interval the car drives the signed
distance Δs = d h (v_k + v_k+1)/2 (exact for constant acceleration) while the heading
turns by Δθ = d ∫ v tan(δ) / L dt (Simpson's rule, speed and steering linear in time),
and the rear axle follows the circular arc with those two increments:

    θ+ = θ + Δθ,   [x+, y+] = [x, y] + Δs sinc(Δθ/2) [cos, sin](θ + Δθ/2).

So the knots lie on a chain of circular arcs, the path the dense check and the tracker
interpolate, and satisfy the kinematic bicycle to the accuracy of that arc.

Constraints: fixed start and end poses, v = 0 at both ends, bounds on v, δ, a, ω, jerk
(a_k+1 - a_k)/h and h, the footprint inside the map, and, for the knots the broad phase
selected, the H-OBCA dual distance constraint against each near obstacle
(:mod:`parknss.sim.planning.refine_obca`). Cost: w_time T + ∫(w_accel a² + w_steer_rate
ω²) dt + w_deviation · mean over knots of (|p - p_ws|² + ρ² (θ - θ_ws)²).

Building a program (the symbolic graph, then IPOPT's derivatives in ``nlpsol``) costs
about as much as solving it, so the program is stated with the numbers that change
between segments (poses, obstacles, bounds, map) as parameters and bounds, and kept by
its structure (N, direction, each obstacle's polygon size and knots, outline planes,
vehicle, weights, solver options; :func:`structure_key`) in a small least-recently-used
cache (``program_cache_size``): a repair round, a second plan of the same scene and any
segment of an already seen structure reuse it. A reused program solves exactly as a
freshly built one (the same expression graph; tests/sim/planning/test_refine_problem.py).
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from parknss.sim.planning.refine_config import RefineConfig
from parknss.sim.planning.refine_obca import ObstacleTerm, body_box
from parknss.vehicle import VehicleGeometry

if TYPE_CHECKING:
    import casadi as ca  # imported by build_program: `plan --no-refine` runs without it

SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


@dataclass
class WarmStart:
    """Initial guess of one segment: poses (N+1, 3), speed (N+1,) m/s, delta (N+1,) rad,
    time step h (s), direction ±1."""

    poses: np.ndarray
    speed: np.ndarray
    delta: np.ndarray
    h: float
    direction: int


@dataclass
class Limits:
    """Bounds in SI units: speed m/s, road-wheel angle rad, accel m/s², rate rad/s, jerk m/s³,
    time step s, distance d_min m."""

    v_max: float
    delta_max: float
    a_max: float
    rate_max: float
    jerk_max: float
    h_min: float
    h_max: float
    d_min: float


@dataclass
class SegmentSolution:
    """Solver output: knots (poses (N+1, 3), speed, delta), controls (accel, rate (N,)),
    time step h (s), IPOPT status and iteration count."""

    poses: np.ndarray
    speed: np.ndarray
    delta: np.ndarray
    accel: np.ndarray
    rate: np.ndarray
    h: float
    status: str
    success: bool
    iterations: int


def heading_change(v0, v1, d0, d1, h, wheelbase: float, tan=np.tan):
    """|Δθ| (rad) over an interval with speed and road-wheel angle linear in time: Simpson's
    rule on ∫ v tan(δ) / L dt (exact for the speed, fourth order in the steering)."""
    vm, dm = (v0 + v1) / 2, (d0 + d1) / 2
    return h / (6 * wheelbase) * (v0 * tan(d0) + 4 * vm * tan(dm) + v1 * tan(d1))


def _sinc(z):
    """sin(z)/z by its series (|z| is a few hundredths of a rad here; exact to 1e-13)."""
    z2 = z * z
    return 1 - z2 / 6 * (1 - z2 / 20 * (1 - z2 / 42))


def limits(cfg: RefineConfig, geom: VehicleGeometry, d_min: float) -> Limits:
    """The bounds of :class:`RefineConfig` converted to road-wheel radians and SI units."""
    ratio = geom.steer_ratio
    return Limits(
        v_max=cfg.speed_max_ms,
        delta_max=math.radians(geom.steer_lock_deg / ratio),
        a_max=cfg.accel_max_ms2,
        rate_max=math.radians(cfg.steer_rate_max_dps / ratio),
        jerk_max=cfg.jerk_max_ms3,
        h_min=cfg.dt_min_s,
        h_max=cfg.dt_max_s,
        d_min=d_min,
    )


def solve_segment(
    ws: WarmStart,
    terms: list[ObstacleTerm],
    bounds: tuple[float, float, float, float],
    geom: VehicleGeometry,
    lim: Limits,
    cfg: RefineConfig,
    cpu_time_s: float,
    d_min: np.ndarray | None = None,
    init: SegmentSolution | None = None,
    planes: tuple[np.ndarray, np.ndarray] | None = None,
) -> SegmentSolution:
    """Solve one segment's NLP; never raises for a solver failure.

    ``ws`` is the warm start and the deviation reference; ``d_min`` (N+1,) per-knot
    distance bounds, m (default ``lim.d_min``); ``init`` an earlier solution to start
    from instead of ``ws`` (the terms' duals should then be re-warmed at its poses);
    ``planes`` (A (M, 2), b (M,)): a map outline the corners keep A @ p <= b inside too.
    ``cpu_time_s`` (s) is IPOPT's CPU-time limit of this solve. The program is taken
    from :func:`segment_program` (built once per structure, then only its numbers change).
    """
    n = len(ws.poses) - 1
    try:
        args = program_inputs(ws, terms, bounds, lim, cfg, d_min, init, planes)
        with _LOCK:  # one solve at a time in the process (see _LOCK)
            prog = segment_program(n, ws.direction, terms, planes, geom, lim, cfg, cpu_time_s)
            res = prog.solver(**args)
            stats = prog.solver.stats()
    except Exception as exc:  # any CasADi/IPOPT error (evaluation, input) fails the solve
        first = (str(exc).splitlines() or [type(exc).__name__])[0][:80]
        return _failed(ws, f"solver error ({type(exc).__name__}: {first})")
    status = str(stats.get("return_status", "unknown"))
    z = np.asarray(res["x"], dtype=float).ravel()
    Xv = z[: 5 * (n + 1)].reshape(n + 1, 5).T
    Uv = z[5 * (n + 1) : 7 * n + 5].reshape(n, 2).T
    return SegmentSolution(
        poses=Xv[0:3].T.copy(),
        speed=np.clip(Xv[3], 0.0, lim.v_max),  # IPOPT meets bounds to ~1e-8 (relaxed)
        delta=np.clip(Xv[4], -lim.delta_max, lim.delta_max),
        accel=Uv[0].copy(),
        rate=Uv[1].copy(),
        h=float(z[7 * n + 5]),
        status=status,
        success=status in SUCCESS,
        iterations=int(stats.get("iter_count", -1)),
    )


@dataclass
class SegmentProgram:
    """One segment structure's NLP as an IPOPT solver (CasADi ``nlpsol`` over SX).

    Decision vector: vec(X) (5 (N+1), knot-major [x, y, θ, v, δ]), vec(U) (2 N, [a, ω]),
    h, then per obstacle term vec(λ) (M K) and vec(μ) (4 K). Parameters p: the warm-start
    poses (3 (N+1), the deviation reference), the outline's plane normals (2 P), and per
    term its A (M x 2, column-major) and b (M,). Every bound and fixed pose (lbx/ubx), map
    box, outline offset and per-knot distance bound (lbg/ubg) is a number of the solve, so
    one program serves every segment of the same structure (:func:`structure_key`). Simple
    bounds on the decision variables rather than rows of g: IPOPT handles them natively
    (measured on TPCAP: about 40 % less solve time than the same bounds as constraints).
    """

    solver: ca.Function
    n: int
    n_g: int


_PROGRAMS: OrderedDict[tuple, SegmentProgram] = OrderedDict()
"""The built programs by :func:`structure_key`, least recently used first."""
_LOCK = threading.RLock()
"""Held while a program is built or solved: plans may run on threads (the web page's
workers), and one CasADi/IPOPT solver called from two threads at once crashes the
process (measured: tests/sim/planning/test_refine_problem.py), so solves take turns."""


def structure_key(n, direction, terms, planes, geom, lim, cfg, cpu_time_s) -> tuple:
    """What the symbolic program depends on: N, the direction, each term's polygon size
    and knots, the outline's plane count, the vehicle's wheelbase and body, the jerk bound,
    the cost weights and the solver options (IPOPT's CPU limit among them)."""
    return (
        n,
        int(direction),
        tuple((len(t.b), tuple(int(k) for k in t.knots)) for t in terms),
        0 if planes is None else len(planes[1]),
        float(geom.wheelbase),
        tuple(float(v) for v in body_box(geom)),
        float(lim.jerk_max),
        float(cpu_time_s),
        cfg.model_dump_json(exclude={"program_cache_size"}),
    )


def segment_program(n, direction, terms, planes, geom, lim, cfg, cpu_time_s) -> SegmentProgram:
    """The cached :class:`SegmentProgram` of this structure, built on a miss (the cache
    keeps ``cfg.program_cache_size`` programs; 0: always built afresh)."""
    key = structure_key(n, direction, terms, planes, geom, lim, cfg, cpu_time_s)
    with _LOCK:
        prog = _PROGRAMS.pop(key, None)
        if prog is None:
            prog = build_program(n, direction, terms, planes, geom, lim, cfg, cpu_time_s)
        if cfg.program_cache_size > 0:
            _PROGRAMS[key] = prog  # the most recently used last
        while len(_PROGRAMS) > cfg.program_cache_size:
            _PROGRAMS.popitem(last=False)
    return prog


def clear_programs() -> None:
    """Forget every cached program (the next solve of each structure builds it again)."""
    with _LOCK:
        _PROGRAMS.clear()


def build_program(n, direction, terms, planes, geom, lim, cfg, cpu_time_s) -> SegmentProgram:
    """Build the NLP of the module docstring for this structure (see :class:`SegmentProgram`;
    the rows of g in the order of :func:`program_inputs`' bounds)."""
    import casadi as ca

    d = float(direction)
    X = ca.SX.sym("X", 5, n + 1)
    U = ca.SX.sym("U", 2, n)
    h = ca.SX.sym("h")
    ref = ca.SX.sym("ref", 3, n + 1)
    x, y, th, v, de = X[0, :], X[1, :], X[2, :], X[3, :], X[4, :]
    a, om = U[0, :], U[1, :]
    decision, params, g = [ca.vec(X), ca.vec(U), h], [ca.vec(ref)], []

    # dynamics: exact arcs of constant curvature per interval
    ds = d * h * (v[:-1] + v[1:]) / 2
    dth = d * heading_change(v[:-1], v[1:], de[:-1], de[1:], h, geom.wheelbase, ca.tan)
    mid = th[:-1] + dth / 2
    step = ds * _sinc(dth / 2)
    g += [v[1:] - (v[:-1] + h * a), de[1:] - (de[:-1] + h * om), th[1:] - (th[:-1] + dth)]
    g += [x[1:] - (x[:-1] + step * ca.cos(mid)), y[1:] - (y[:-1] + step * ca.sin(mid))]
    # the fixed poses, standstill at the ends and the bounds on v, δ, a, ω, h, λ, μ are
    # bounds of the decision variables (lbx/ubx, program_inputs)
    if n > 1:
        jerk = a[1:] - a[:-1]
        g += [jerk - lim.jerk_max * h, jerk + lim.jerk_max * h]
        # the footprint's corners inside the map box and the outline (interior knots)
        box = body_box(geom)
        c, s = ca.cos(th[1:-1]), ca.sin(th[1:-1])
        n_planes = 0 if planes is None else len(planes[1])
        normals = ca.SX.sym("planes", 2, n_planes)
        params.append(ca.vec(normals))
        for ex in (box[0], -box[2]):
            for ey in (box[1], -box[3]):
                cx = x[1:-1] + c * ex - s * ey
                cy = y[1:-1] + s * ex + c * ey
                g += [cx, cy]
                g += [normals[0, j] * cx + normals[1, j] * cy for j in range(n_planes)]
    # H-OBCA collision avoidance per obstacle over its knots
    box = body_box(geom)
    for term in terms:
        k = [int(i) for i in term.knots]
        m = len(term.b)
        lam = ca.SX.sym("lam", m, len(k))
        mu = ca.SX.sym("mu", 4, len(k))
        A = ca.SX.sym("A", m, 2)
        b = ca.SX.sym("b", 1, m)
        decision += [ca.vec(lam), ca.vec(mu)]
        params += [ca.vec(A), ca.vec(b)]
        w = ca.mtimes(A.T, lam)  # (2, K) = Aᵀλ
        c, s = ca.cos(th[k]), ca.sin(th[k])
        dist = x[k] * w[0, :] + y[k] * w[1, :] - ca.mtimes(b, lam) - ca.mtimes(box[None, :], mu)
        g += [mu[0, :] - mu[2, :] + c * w[0, :] + s * w[1, :]]
        g += [mu[1, :] - mu[3, :] - s * w[0, :] + c * w[1, :], w[0, :] ** 2 + w[1, :] ** 2, dist]

    # cost
    dev = (x - ref[0, :]) ** 2 + (y - ref[1, :]) ** 2
    dev = dev + (cfg.deviation_heading_m * (th - ref[2, :])) ** 2
    cost = cfg.w_time * n * h
    cost = cost + h * (cfg.w_accel * ca.sumsqr(a) + cfg.w_steer_rate * ca.sumsqr(om))
    cost = cost + cfg.w_deviation * ca.sum2(dev) / (n + 1)

    gv = ca.vertcat(*[ca.vec(e) for e in g])
    nlp = {"x": ca.vertcat(*decision), "p": ca.vertcat(*params), "f": cost, "g": gv}
    solver = ca.nlpsol(
        "refine_segment",
        "ipopt",
        nlp,
        {
            "print_time": False,
            "error_on_fail": False,
            "ipopt": {
                "print_level": 0,
                "sb": "yes",
                "max_iter": int(cfg.max_iter),
                "max_cpu_time": float(max(cpu_time_s, 1e-3)),
                "tol": float(cfg.tol),
                "acceptable_tol": float(cfg.tol) * 100,
                "mu_strategy": cfg.mu_strategy,
                "linear_solver": cfg.linear_solver,
                "hessian_approximation": cfg.hessian_approximation,
                "warm_start_init_point": "yes" if cfg.warm_start_init_point else "no",
                "mu_init": float(cfg.mu_init),
            },
        },
    )
    return SegmentProgram(solver, n, int(gv.numel()))


def program_inputs(ws, terms, bounds, lim, cfg, d_min, init, planes) -> dict:
    """The numbers of one solve of :func:`build_program`'s solver: x0 (the warm start, or
    ``init``, with the terms' duals), the bounds lbx/ubx, p and lbg/ubg, row for row."""
    n = len(ws.poses) - 1
    dmin = np.full(n + 1, lim.d_min) if d_min is None else np.asarray(d_min, dtype=float)
    inf = np.inf
    lo: list = []
    hi: list = []

    def rows(count: int, low, high) -> None:
        lo.append(np.broadcast_to(np.asarray(low, dtype=float), (count,)))
        hi.append(np.broadcast_to(np.asarray(high, dtype=float), (count,)))

    rows(5 * n, 0.0, 0.0)  # dynamics
    # decision bounds: start pose fixed, end pose in a thin box (see RefineConfig),
    # standstill at both ends, v, δ, a, ω and h within their limits, λ, μ >= 0
    p0, p1 = ws.poses[0], ws.poses[-1]
    tol = np.array([cfg.end_tolerance_m, cfg.end_tolerance_m, math.radians(cfg.end_tolerance_deg)])
    xl, xu = np.full((5, n + 1), -inf), np.full((5, n + 1), inf)
    xl[3], xu[3] = 0.0, lim.v_max
    xl[4], xu[4] = -lim.delta_max, lim.delta_max
    xl[0:3, 0], xu[0:3, 0] = p0, p0
    xl[0:3, n], xu[0:3, n] = p1 - tol, p1 + tol
    xl[3, [0, n]] = xu[3, [0, n]] = 0.0
    ul = np.vstack([np.full(n, -lim.a_max), np.full(n, -lim.rate_max)]).ravel(order="F")
    lbx = [xl.ravel(order="F"), ul, [lim.h_min]]
    ubx = [xu.ravel(order="F"), -ul, [lim.h_max]]
    normals = np.zeros((2, 0))
    if n > 1:
        rows(n - 1, -inf, 0.0)
        rows(n - 1, 0.0, inf)
        xmin, ymin, xmax, ymax = bounds
        offsets = np.zeros(0) if planes is None else np.asarray(planes[1], dtype=float)
        normals = normals if planes is None else np.asarray(planes[0], dtype=float).T
        for _ in range(4):
            rows(n - 1, xmin, xmax)
            rows(n - 1, ymin, ymax)
            for bk in offsets:
                rows(n - 1, -inf, bk)
    params = [ws.poses.T.ravel(order="F"), normals.ravel(order="F")] if n > 1 else [
        ws.poses.T.ravel(order="F")
    ]
    duals = []
    for term in terms:
        kk, m = len(term.knots), len(term.b)
        lbx.append(np.zeros(m * kk + 4 * kk))
        ubx.append(np.full(m * kk + 4 * kk, inf))
        rows(2 * kk, 0.0, 0.0)
        rows(kk, -inf, 1.0)
        rows(kk, dmin[np.asarray(term.knots, dtype=int)], inf)
        params += [np.asarray(term.A, dtype=float).ravel(order="F"), np.asarray(term.b, float)]
        duals += [np.asarray(term.lam0, float).ravel(order="F"), np.asarray(term.mu0).ravel("F")]
    if init is None:
        knots = np.vstack([ws.poses.T, ws.speed[None, :], ws.delta[None, :]])
        acc0 = np.clip(np.diff(ws.speed) / ws.h, -lim.a_max, lim.a_max)
        rate0 = np.clip(np.diff(ws.delta) / ws.h, -lim.rate_max, lim.rate_max)
        ctrl, h0 = np.vstack([acc0, rate0]), ws.h
    else:
        knots = np.vstack([init.poses.T, init.speed[None, :], init.delta[None, :]])
        ctrl, h0 = np.vstack([init.accel, init.rate]), init.h
    x0 = np.concatenate([knots.ravel(order="F"), ctrl.ravel(order="F"), [h0], *duals])
    return {
        "x0": x0,
        "lbx": np.concatenate(lbx),
        "ubx": np.concatenate(ubx),
        "p": np.concatenate(params),
        "lbg": np.concatenate(lo),
        "ubg": np.concatenate(hi),
    }


def _failed(ws: WarmStart, status: str) -> SegmentSolution:
    n = len(ws.poses) - 1
    return SegmentSolution(
        ws.poses, ws.speed, ws.delta, np.zeros(n), np.zeros(n), ws.h, status, False, 0
    )
