"""The nonlinear program of one gear segment (CasADi Opti stack, IPOPT).

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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from parknss.sim.planning.refine_config import RefineConfig
from parknss.sim.planning.refine_obca import ObstacleTerm, body_box
from parknss.vehicle import VehicleGeometry

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
    """
    try:
        opti, X, U, h = _build(ws, terms, bounds, geom, lim, cfg, cpu_time_s, d_min, init, planes)
        sol = opti.solve_limited()
        val = sol.value
        stats = opti.stats()
    except Exception as exc:  # any CasADi/IPOPT error (set_initial, evaluation) fails
        first = (str(exc).splitlines() or [type(exc).__name__])[0][:80]
        return _failed(ws, f"solver error ({type(exc).__name__}: {first})")
    status = str(stats.get("return_status", "unknown"))
    Xv, Uv = np.asarray(val(X)), np.atleast_2d(np.asarray(val(U)))
    return SegmentSolution(
        poses=Xv[0:3].T.copy(),
        speed=np.clip(Xv[3], 0.0, lim.v_max),  # IPOPT meets bounds to ~1e-8 (relaxed)
        delta=np.clip(Xv[4], -lim.delta_max, lim.delta_max),
        accel=Uv[0].copy(),
        rate=Uv[1].copy(),
        h=float(val(h)),
        status=status,
        success=status in SUCCESS,
        iterations=int(stats.get("iter_count", -1)),
    )


def _build(ws, terms, bounds, geom, lim, cfg, cpu_time_s, d_min, init, planes):
    """The Opti problem of :func:`solve_segment`: (opti, X, U, h)."""
    n = len(ws.poses) - 1
    dmin = np.full(n + 1, lim.d_min) if d_min is None else np.asarray(d_min, dtype=float)
    d = float(ws.direction)
    opti = ca.Opti()
    X = opti.variable(5, n + 1)
    U = opti.variable(2, n)
    h = opti.variable()
    x, y, th, v, de = X[0, :], X[1, :], X[2, :], X[3, :], X[4, :]
    a, om = U[0, :], U[1, :]

    # dynamics: exact arcs of constant curvature per interval
    ds = d * h * (v[:-1] + v[1:]) / 2
    dth = d * heading_change(v[:-1], v[1:], de[:-1], de[1:], h, geom.wheelbase, ca.tan)
    mid = th[:-1] + dth / 2
    step = ds * _sinc(dth / 2)
    opti.subject_to(v[1:] == v[:-1] + h * a)
    opti.subject_to(de[1:] == de[:-1] + h * om)
    opti.subject_to(th[1:] == th[:-1] + dth)
    opti.subject_to(x[1:] == x[:-1] + step * ca.cos(mid))
    opti.subject_to(y[1:] == y[:-1] + step * ca.sin(mid))

    # boundary conditions: poses fixed, standstill at both ends
    p0, p1 = ws.poses[0], ws.poses[-1]
    opti.subject_to(X[0:3, 0] == p0)
    if cfg.end_tolerance_m > 0:  # a thin tube instead of a point (see RefineConfig)
        tol = np.array(
            [cfg.end_tolerance_m, cfg.end_tolerance_m, math.radians(cfg.end_tolerance_deg)]
        )
        opti.subject_to(opti.bounded(p1 - tol, X[0:3, n], p1 + tol))
    else:
        opti.subject_to(X[0:3, n] == p1)
    opti.subject_to(v[0] == 0)
    opti.subject_to(v[n] == 0)

    # bounds
    opti.subject_to(opti.bounded(0, v, lim.v_max))
    opti.subject_to(opti.bounded(-lim.delta_max, de, lim.delta_max))
    opti.subject_to(opti.bounded(-lim.a_max, a, lim.a_max))
    opti.subject_to(opti.bounded(-lim.rate_max, om, lim.rate_max))
    opti.subject_to(opti.bounded(lim.h_min, h, lim.h_max))
    if n > 1:
        jerk = a[1:] - a[:-1]
        opti.subject_to(opti.bounded(-lim.jerk_max * h, jerk, lim.jerk_max * h))

    # the footprint's corners inside the map (interior knots)
    if n > 1:
        g = body_box(geom)
        c, s = ca.cos(th[1:-1]), ca.sin(th[1:-1])
        xmin, ymin, xmax, ymax = bounds
        for ex in (g[0], -g[2]):
            for ey in (g[1], -g[3]):
                cx = x[1:-1] + c * ex - s * ey
                cy = y[1:-1] + s * ex + c * ey
                opti.subject_to(opti.bounded(xmin, cx, xmax))
                opti.subject_to(opti.bounded(ymin, cy, ymax))
                for (ax, ay), bk in zip(*planes, strict=True) if planes is not None else ():
                    opti.subject_to(float(ax) * cx + float(ay) * cy <= float(bk))

    # H-OBCA collision avoidance per obstacle over its knots
    duals = []
    for term in terms:
        k = [int(i) for i in term.knots]
        lam = opti.variable(len(term.b), len(k))
        mu = opti.variable(4, len(k))
        xk, yk, thk = x[k], y[k], th[k]
        w = ca.mtimes(term.A.T, lam)  # (2, K) = Aᵀλ
        c, s = ca.cos(thk), ca.sin(thk)
        g = body_box(geom)
        opti.subject_to(ca.vec(lam) >= 0)
        opti.subject_to(ca.vec(mu) >= 0)
        opti.subject_to(mu[0, :] - mu[2, :] + c * w[0, :] + s * w[1, :] == 0)
        opti.subject_to(mu[1, :] - mu[3, :] - s * w[0, :] + c * w[1, :] == 0)
        opti.subject_to(w[0, :] ** 2 + w[1, :] ** 2 <= 1)
        dist = xk * w[0, :] + yk * w[1, :] - ca.mtimes(term.b[None, :], lam)
        dist = dist - ca.mtimes(g[None, :], mu)
        opti.subject_to(dist >= dmin[k][None, :])
        duals.append((lam, mu, term))

    # cost
    ref = ws.poses
    dev = (x - ref[:, 0][None, :]) ** 2 + (y - ref[:, 1][None, :]) ** 2
    dev = dev + (cfg.deviation_heading_m * (th - ref[:, 2][None, :])) ** 2
    cost = cfg.w_time * n * h
    cost = cost + h * (cfg.w_accel * ca.sumsqr(a) + cfg.w_steer_rate * ca.sumsqr(om))
    cost = cost + cfg.w_deviation * ca.sum2(dev) / (n + 1)
    opti.minimize(cost)

    # initial guess: the warm start, or an earlier solution
    if init is None:
        opti.set_initial(X, np.vstack([ref.T, ws.speed[None, :], ws.delta[None, :]]))
        opti.set_initial(h, ws.h)
        acc0 = np.clip(np.diff(ws.speed) / ws.h, -lim.a_max, lim.a_max)
        rate0 = np.clip(np.diff(ws.delta) / ws.h, -lim.rate_max, lim.rate_max)
        opti.set_initial(U, np.vstack([acc0, rate0]))
    else:
        opti.set_initial(X, np.vstack([init.poses.T, init.speed[None, :], init.delta[None, :]]))
        opti.set_initial(h, init.h)
        opti.set_initial(U, np.vstack([init.accel, init.rate]))
    for lam, mu, term in duals:
        opti.set_initial(lam, term.lam0)
        opti.set_initial(mu, term.mu0)

    opti.solver(
        "ipopt",
        {"print_time": False, "error_on_fail": False, "expand": True},
        {
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
    )
    return opti, X, U, h


def _failed(ws: WarmStart, status: str) -> SegmentSolution:
    n = len(ws.poses) - 1
    return SegmentSolution(
        ws.poses, ws.speed, ws.delta, np.zeros(n), np.zeros(n), ws.h, status, False, 0
    )
