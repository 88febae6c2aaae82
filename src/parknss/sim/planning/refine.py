"""Optimisation-based refinement of a Hybrid A* path, in the spirit of H-OBCA (paper §IV-C).

``refine(scene, coarse, geom, config)`` turns the coarse path (gear segments of arcs at
full lock or straight, no timing) into a smooth, time-parameterised trajectory: each gear
segment is solved separately as a nonlinear program (:mod:`.refine_problem`; CasADi SX,
IPOPT with MUMPS, each program built once per structure and reused) with the kinematic
bicycle integrated exactly over N intervals of a free time step, bounds on speed
(parking limit), acceleration, jerk, steering angle (the lock of ``geom``, which
already holds back the tracker's reserve) and steering rate, standstill at every cusp
and at the goal, the cusp, start and goal poses fixed, and collision avoidance with a
safety margin by the H-OBCA dual distance constraint (:mod:`.refine_obca`) for the
obstacles a broad phase finds near each knot. The warm start is the coarse segment
timed by a trapezoidal profile; the cost is time plus acceleration and steering-rate
smoothness plus deviation from the warm start (``refine:`` in configs/planning.yaml,
:class:`RefineConfig`).

The result is sampled every ``output_step_m`` of travel (exact on the solution's arcs),
with speed (>= 0, 0 at each segment end), steering-wheel angle (deg) and time (s), and
re-checked with the exact dense check (:func:`verify_trajectory`). Every refined path
stays within the steering lock of ``geom`` (curvature <= tan(δ_max)/L, relative
tolerance :data:`KAPPA_RTOL`): the solver's end offset is blended in only where the path
has curvature to spare (:func:`~.refine_profile.blend_weights`), and a segment with too
little to spare (driven at the lock almost throughout) keeps its coarse poses, which lie
on the lock exactly, with a trapezoidal profile (``status: kept (at the lock)``). If IPOPT fails or
hits its iteration or CPU-time limit, or the dense check fails, the result has
``ok=False``, the reason, and the coarse path with a trapezoidal speed profile as
``source="coarse_fallback"``. Malformed input raises :class:`PlanningError`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from parknss.config import override
from parknss.errors import PlanningError
from parknss.sim import geometry
from parknss.sim.planning.hybrid_astar import (
    PlanningConfig,
    load_planning_config,
    verify_trajectory,
)
from parknss.sim.planning.refine_config import RefineConfig
from parknss.sim.planning.refine_obca import obstacle_terms, rewarm
from parknss.sim.planning.refine_problem import limits, solve_segment
from parknss.sim.planning.refine_profile import (
    least_intervals,
    profile_segment,
    sample_solution,
    step_curvature,
    warm_start,
)
from parknss.sim.trajectory import Segment, Trajectory
from parknss.vehicle import VehicleGeometry

KAPPA_RTOL = 1e-6
"""Relative tolerance of the lock check on a refined segment's curvature (IPOPT meets its
bounds to ~1e-8; the end-pose blend never uses more than half the spare curvature)."""

__all__ = ["KAPPA_RTOL", "RefineConfig", "RefineResult", "coarse_fallback", "refine"]


@dataclass
class RefineResult:
    """The refinement's outcome.

    Attributes:
        trajectory: the refined trajectory (``source="refined"``) when ``ok``, else the
            coarse path with a trapezoidal profile (``source="coarse_fallback"``).
        ok: True when every segment solved and the dense check passed.
        reason: "solved", or what failed (segment, IPOPT status, dense clearance).
        solve_time_s: wall time of the whole refinement, s.
        cpu_s: CPU time of this process during the refinement, s (the budget's clock).
        min_clearance_m: dense exact clearance of the refined path (nan if not checked).
        segments: per-segment details (intervals, obstacles, iterations, status, T s).
    """

    trajectory: Trajectory | None
    ok: bool
    reason: str
    solve_time_s: float = 0.0
    cpu_s: float = 0.0
    min_clearance_m: float = math.nan
    segments: list[dict] = field(default_factory=list)


def coarse_fallback(coarse: Trajectory, cfg: RefineConfig, reason: str) -> Trajectory:
    """The coarse path with trapezoidal speed/time profiles, flagged ``coarse_fallback``."""
    segs = [
        profile_segment(s, cfg.fallback_speed_ms, cfg.fallback_accel_ms2) for s in coarse.segments
    ]
    info = {**coarse.info, "refine_reason": reason}
    return Trajectory(segs, source="coarse_fallback", info=info)


def _validate(coarse) -> None:
    if not isinstance(coarse, Trajectory):
        raise PlanningError(f"refine: expected a Trajectory, got {type(coarse).__name__}")
    if not coarse.segments:
        raise PlanningError("refine: the coarse trajectory has no segments")
    for i, s in enumerate(coarse.segments):
        if not np.all(np.isfinite(s.poses)):
            raise PlanningError(f"refine: segment {i} has non-finite poses")
        if s.steer is not None and not np.all(np.isfinite(s.steer)):
            raise PlanningError(f"refine: segment {i} has non-finite steering")


def refine(
    scene,
    coarse: Trajectory,
    geom: VehicleGeometry | None = None,
    config: PlanningConfig | None = None,
) -> RefineResult:
    """Refine ``coarse`` in ``scene`` (see the module docstring); deterministic.

    ``geom`` is the planner's vehicle (its steering lock bounds the plan); ``config`` the
    planning config (default configs/planning.yaml), whose ``refine`` section sets the
    problem and whose ``safety_margin_m`` is the margin unless ``refine`` overrides it.
    """
    t0 = time.perf_counter()
    _validate(coarse)
    geom = geom or VehicleGeometry()
    pcfg = config or load_planning_config()
    cfg = pcfg.refine
    margin = pcfg.safety_margin_m if cfg.safety_margin_m is None else cfg.safety_margin_m
    lim = limits(cfg, geom, margin + cfg.margin_buffer_m)
    cpu0 = time.process_time()
    segments: list[Segment] = []
    details: list[dict] = []

    def fail(reason: str) -> RefineResult:
        traj = coarse_fallback(coarse, cfg, reason)
        wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
        return RefineResult(traj, False, reason, wall, cpu, math.nan, details)

    n_seg = len(coarse.segments)
    for i, seg in enumerate(coarse.segments):
        if seg.length < max(cfg.min_segment_m, 1e-6):
            segments.append(profile_segment(seg, cfg.speed_max_ms, cfg.accel_max_ms2))
            details.append({"intervals": 0, "status": "kept (short)"})
            continue
        left = cfg.cpu_time_s - (time.process_time() - cpu0)
        if left <= 0:
            return fail(f"segment {i + 1}/{n_seg}: CPU budget of {cfg.cpu_time_s:g} s used up")
        out, detail = _refine_segment(seg, scene, geom, pcfg, lim, margin, cpu0)
        details.append(detail)
        if out is None:
            return fail(f"segment {i + 1}/{n_seg}: {detail['failure']}")
        segments.append(out)

    info = {**coarse.info, "refined_from": coarse.source, "margin_m": margin}
    traj = Trajectory(segments, source="refined", info=info)
    check_cfg = override(pcfg, {"safety_margin_m": margin}, source="refine margin")
    passed, clr = verify_trajectory(traj, scene, geom, check_cfg)
    if not passed:
        what = "left the map" if clr < 0 else f"clearance {clr:.3f} m < {margin:.3f} m"
        return fail(f"refined path failed the dense check ({what})")
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    return RefineResult(traj, True, "solved", wall, cpu, clr, details)


def _refine_segment(seg: Segment, scene, geom, pcfg: PlanningConfig, lim, margin: float, cpu0):
    """Solve one gear segment, re-solving with a raised knot margin where the dense check
    of the sampled result falls below ``margin`` (between knots). Returns (segment or None,
    details with ``failure`` when None)."""
    cfg = pcfg.refine
    ws = warm_start(
        seg,
        geom,
        cfg.speed_max_ms,
        cfg.accel_max_ms2,
        cfg.steer_rate_max_dps,
        cfg.dt_target_s,
        cfg.min_intervals,
        cfg.max_intervals,
        least_intervals(
            seg.length, cfg.speed_max_ms, cfg.accel_max_ms2, cfg.jerk_max_ms3, cfg.dt_max_s
        ),
    )
    obstacles = scene.obstacle_arrays()
    terms = obstacle_terms(
        ws.poses, obstacles, geom, lim.d_min + cfg.broadphase_m, cfg.broadphase_knots
    )
    n = len(ws.poses) - 1
    kappa_max = math.tan(lim.delta_max) / geom.wheelbase
    # the knot bound: the margin plus its buffer, but never above the warm start's own
    # clearance (at least the margin): a coarse path squeezed between margin and buffer
    # (fine cells near obstacles) keeps a feasible start; the dense check and the repair
    # rounds below still hold the margin between knots
    d_min = np.full(n + 1, lim.d_min)
    if obstacles:
        clr = geometry.clearance(ws.poses, geom, obstacles, cutoff=lim.d_min)  # exact below
        d_min = np.minimum(d_min, np.maximum(margin, clr))
    detail: dict = {"intervals": n, "obstacles": len(terms), "iterations": 0, "repairs": 0}
    sol = None
    ends = (seg.poses[0], seg.poses[-1])
    for _ in range(cfg.repair_rounds + 1):
        left = cfg.cpu_time_s - (time.process_time() - cpu0)
        if left <= 0:
            detail["failure"] = f"CPU budget of {cfg.cpu_time_s:g} s used up"
            return None, detail
        if sol is not None:
            rewarm(terms, sol.poses, geom)
        planes = scene.map_planes() if getattr(scene, "map_outline", None) else None
        sol = solve_segment(
            ws, terms, scene.bounds, geom, lim, cfg, cfg.cpu_time_s, d_min, sol, planes
        )
        detail.update(iterations=detail["iterations"] + sol.iterations, status=sol.status)
        detail["duration_s"] = round(n * sol.h, 3)
        if not sol.success:
            detail["failure"] = f"IPOPT {sol.status}"
            return None, detail
        out = sample_solution(sol, seg.direction, ends, geom, cfg.output_step_m, cfg.end_blend_m)
        if np.abs(step_curvature(out.poses)).max(initial=0.0) > kappa_max * (1 + KAPPA_RTOL):
            # a segment driven at the lock almost throughout has too little curvature to
            # spare for the end offset: keep its coarse poses (exact ends, at the lock)
            detail["status"] = "kept (at the lock)"
            return profile_segment(seg, cfg.speed_max_ms, cfg.accel_max_ms2), detail
        short = _short_intervals(out, sol.h, n, obstacles, geom, pcfg, margin)
        if not short:
            return out, detail
        if detail["repairs"] == cfg.repair_rounds:
            break
        detail["repairs"] += 1
        for k, deficit in short.items():
            for j in (k, k + 1):
                if 0 < j < n:
                    d_min[j] += deficit + cfg.margin_buffer_m
    detail["failure"] = (
        f"clearance below the margin between knots after {cfg.repair_rounds} repairs"
    )
    return None, detail


def _short_intervals(out: Segment, h: float, n: int, obstacles, geom, pcfg, margin: float):
    """{interval k: clearance deficit m} where the densified sampled segment comes closer
    than ``margin`` to an obstacle."""
    if not obstacles:
        return {}
    step, dh = pcfg.dense.max_step_m, math.radians(pcfg.dense.max_dheading_deg)
    dense = geometry.densify(np.column_stack([out.poses, out.t]), step, dh)
    clr = geometry.clearance(dense[:, :3], geom, obstacles, cutoff=margin)  # exact below
    bad = np.flatnonzero(clr < margin)
    k = np.clip(np.floor(dense[bad, 3] / h + 1e-9).astype(int), 0, n - 1)
    short: dict[int, float] = {}
    for kk, c in zip(k, clr[bad], strict=True):
        short[int(kk)] = max(short.get(int(kk), 0.0), margin - float(c))
    return short
