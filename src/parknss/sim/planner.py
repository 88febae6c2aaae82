"""The plan of a scene: the one that ``parknss plan`` shows and every run drives.

:func:`plan_scene` plans a scene once: Hybrid A* (:mod:`parknss.sim.planning.hybrid_astar`)
on the planner's vehicle, then the refinement (:mod:`parknss.sim.planning.refine`), whose
result replaces the coarse path when it is solved and passes the exact dense check.
``parknss plan``, ``parknss simulate``, ``parknss grid``, ``parknss tune`` and the web
simulator all plan through it with the same two settings of the closed-loop config
(configs/closed_loop.yaml), the single truth of what is driven:

* ``steer_reserve`` (0.1): the planner's vehicle keeps that fraction of the steering
  lock free (:func:`planning_geometry`), so the tracker can still correct on a
  full-lock arc;
* ``plan_margin_m`` (0.2 m): the clearance margin of the search, the refinement and the
  dense check (None: planning.yaml's ``safety_margin_m``).

Planning "as the planner alone" (full lock, planning.yaml's margin) is the closed-loop
config with ``steer_reserve: 0`` and ``plan_margin_m: null`` (``parknss plan
--no-reserve``); such a plan is not the one ``simulate`` drives.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

from parknss.config import override
from parknss.errors import ParknssError
from parknss.sim import geometry
from parknss.sim import scenarios as sc
from parknss.sim.closed_loop import ClosedLoopConfig, SimConfigFiles, load_closed_loop_config
from parknss.sim.planning import escape as esc
from parknss.sim.planning.frame import CanonicalFrame, snap_scene, snap_trajectory
from parknss.sim.planning.hybrid_astar import (
    HybridAStar,
    PlanningConfig,
    load_planning_config,
    verify_trajectory,
)
from parknss.sim.planning.refine import refine as refine_path
from parknss.sim.scene_formats import load_scene
from parknss.sim.trajectory import Segment, Trajectory
from parknss.vehicle import VehicleGeometry

NO_RESERVE = {"steer_reserve": 0.0, "plan_margin_m": None}
"""Closed-loop overrides that plan as the planner alone (full lock, planning.yaml margin)."""


@dataclass
class Plan:
    """A scene's plan: the trajectory driven (None if not plannable) and how it was made.

    Times in s (wall clock), clearances in m (exact dense minimum; None when there is no
    obstacle or no path).
    """

    trajectory: Trajectory | None
    reason: str
    coarse: Trajectory | None = None
    refined: bool = False
    plan_s: float = 0.0
    min_clearance_m: float | None = None
    search_s: float = 0.0
    refine_s: float = 0.0
    refine_reason: str = ""
    refinement: Trajectory | None = None
    coarse_min_clearance_m: float | None = None
    expansions: int = 0
    steer_reserve: float = 0.0
    margin_m: float | None = None
    vehicle: dict | None = None  # the car planned for (VehicleGeometry.to_dict, full lock)
    escape_strokes: int = 0  # strokes of the goal's slot escape at the plan's end (escape.py)
    escape_reason: str = ""  # why the escape ran and how it ended ("" when it did not run)

    def to_json(self, scene: sc.Scene) -> dict:
        """The plan summary ``parknss plan --json`` prints (and ``simulate`` reports as
        ``plan``): lengths m, clearances m, times s, ``trajectory`` the driven path's
        :meth:`~parknss.sim.trajectory.Trajectory.digest`."""
        traj = self.trajectory
        meta = scene.meta
        return {
            "cell": meta.cell if meta.robust_index is None else meta.robust_index,
            "name": meta.name,
            "plannable": traj is not None,
            "reason": self.reason,
            "search_time_s": round(self.search_s, 4),
            "refine_time_s": round(self.refine_s, 4),
            "plan_time_s": round(self.plan_s, 4),
            "length_m": round(traj.length, 3) if traj is not None else None,
            "cusps": traj.cusps if traj is not None else None,
            "min_clearance_m": _r4(self.min_clearance_m),
            "coarse_min_clearance_m": _r4(self.coarse_min_clearance_m),
            "refined": self.refined,
            "refine_reason": self.refine_reason,
            "expansions": self.expansions,
            "escape_strokes": self.escape_strokes,
            "escape_reason": self.escape_reason,
            "steer_reserve": self.steer_reserve,
            "margin_m": self.margin_m,
            "vehicle": self.vehicle,
            "trajectory": traj.digest() if traj is not None else None,
        }


TIMING_KEYS = ("search_time_s", "refine_time_s", "plan_time_s")
"""The wall-clock fields of :meth:`Plan.to_json` (they differ from run to run)."""


def _r4(v: float | None) -> float | None:
    return round(v, 4) if v is not None and math.isfinite(v) else None


def planning_geometry(geom: VehicleGeometry, steer_reserve: float) -> VehicleGeometry:
    """The planner's vehicle: the same body, the steering lock reduced by ``steer_reserve``
    (a fraction) so the tracker keeps steering authority on full-lock arcs."""
    return replace(geom, steer_lock_deg=geom.steer_lock_deg * (1.0 - steer_reserve))


def plan_scene(
    scene: sc.Scene,
    loop: ClosedLoopConfig | None = None,
    planning: PlanningConfig | str | Path | None = None,
    geom: VehicleGeometry | None = None,
    *,
    refine: bool = True,
) -> Plan:
    """Plan ``scene`` (module docstring): Hybrid A*, then the refinement when ``refine``.

    Args:
        loop: the closed-loop config whose ``steer_reserve`` and ``plan_margin_m`` shape
            the plan (default: the shipped closed_loop.yaml).
        planning: the planning config or its YAML (default: the shipped planning.yaml).
        geom: the vehicle; the planner and the refinement use :func:`planning_geometry`
            of it, the dense check its body.
        refine: False keeps the coarse Hybrid A* path.
    """
    loop = loop if loop is not None else load_closed_loop_config()
    car = geom or VehicleGeometry()
    geom = planning_geometry(car, loop.steer_reserve)
    cfg = planning if isinstance(planning, PlanningConfig) else load_planning_config(planning)
    if loop.plan_margin_m is not None:
        cfg = override(cfg, {"safety_margin_m": loop.plan_margin_m}, source="plan_margin_m")
    t0 = time.perf_counter()
    # search and refinement in the scene's canonical frame (planning/frame.py): a moved
    # scene gives the same plan moved with it; the trajectories come back in the world's
    frame = CanonicalFrame.of(scene.start, scene.goal) if cfg.canonical_frame else None
    scene = frame.to_canon_scene(scene) if frame is not None else scene
    snap = cfg.canonical_snap if frame is not None else 0.0
    plan = _plan_in(scene, cfg, geom, refine, t0, snap)
    plan.vehicle = car.to_dict()
    plan.steer_reserve = loop.steer_reserve
    if frame is not None:
        moved: dict[int, Trajectory] = {}  # one world copy each (plan.trajectory is coarse)
        for name in ("trajectory", "coarse", "refinement"):
            traj = getattr(plan, name)
            if traj is not None:
                if id(traj) not in moved:
                    moved[id(traj)] = frame.to_world_trajectory(traj)
                setattr(plan, name, moved[id(traj)])
    return plan


def _unsnap_kept(rr, coarse: Trajectory, cfg: PlanningConfig):
    """``rr`` with each segment the refinement kept at the lock (its coarse poses with a
    trapezoidal profile) taken from the search's own, unrounded, coarse segment: the
    rounded copy would bend up to ~5e-5 beyond the lock by the rounding alone."""
    from parknss.sim.planning.refine_profile import profile_segment

    traj = rr.trajectory
    if traj is None or len(traj.segments) != len(coarse.segments) or len(rr.segments) != len(
        coarse.segments
    ):
        return rr
    if not any(d.get("status") == "kept (at the lock)" for d in rr.segments):
        return rr
    rc = cfg.refine
    segs = [
        profile_segment(c, rc.speed_max_ms, rc.accel_max_ms2)
        if d.get("status") == "kept (at the lock)" else s
        for s, c, d in zip(traj.segments, coarse.segments, rr.segments, strict=True)
    ]
    return replace(rr, trajectory=replace(traj, segments=segs))


def _plan_in(
    scene, cfg: PlanningConfig, geom: VehicleGeometry, refine: bool, t0: float, snap: float
):
    """Search and refine ``scene`` as given (no frame change); :func:`plan_scene`. The
    refinement's input is rounded to ``snap`` (> 0): the solver answers a moved scene the
    same (its optimum is flat along the path, so last-bit differences of the input moved
    lengths by up to 1e-3 m). The search takes the scene unrounded: it is invariant
    without, and a 1e-12 m rounding loses TPCAP case 9, found at 809 of 1200 expansions
    on a knife edge."""
    res, tail, why = _search(scene, cfg, geom)
    strokes = sum(a.direction != b.direction for a, b in itertools.pairwise(tail)) + bool(tail)
    settings = {"margin_m": cfg.safety_margin_m, "escape_reason": why,
                "escape_strokes": strokes}
    if tail:  # the search ended at the escape's outer end: refine that part only
        scene = replace(scene, goal=tuple(float(v) for v in tail[0].poses[0]))
    if not res.found:
        return Plan(
            None,
            res.reason,
            plan_s=time.perf_counter() - t0,
            search_s=res.stats.time_s,
            expansions=res.stats.expansions,
            **settings,
        )
    final, clr, refined = res.trajectory, res.min_clearance_m, False
    refine_reason, refinement, refine_s = "", None, 0.0
    if refine:
        t1 = time.perf_counter()
        try:
            rr = refine_path(
                snap_scene(scene, snap) if snap > 0 else scene,
                snap_trajectory(res.trajectory, snap) if snap > 0 else res.trajectory,
                geom,
                cfg,
            )
        except ParknssError as exc:
            rr, refine_reason = None, f"refinement error: {exc}"
        except Exception as exc:  # any other failure of the refinement: the coarse path
            first = (str(exc).splitlines() or [""])[0][:80]
            rr, refine_reason = None, f"refinement error ({type(exc).__name__}: {first})"
        refine_s = time.perf_counter() - t1
        if rr is not None and snap > 0:
            rr = _unsnap_kept(rr, res.trajectory, cfg)
        if rr is not None:
            refinement, refine_reason = rr.trajectory, str(rr.reason)
            if rr.ok and rr.trajectory.segments:
                # the refinement ran the exact dense check (on the map, clearance rr.min_
                # clearance_m) against its own margin; the plan needs the planning margin
                if rr.min_clearance_m >= cfg.safety_margin_m - 1e-9:
                    final, clr, refined = rr.trajectory, rr.min_clearance_m, True
                else:
                    refine_reason = (
                        f"refined path failed the dense check ({rr.min_clearance_m:.3f} m)"
                    )
    coarse = res.trajectory
    if tail:
        ok, worst = verify_trajectory(Trajectory(tail), scene, geom, cfg)
        clr = min(clr, worst) if ok or worst >= 0.0 else -1.0  # -1: it leaves the map
        final = _with_tail(final, tail, refined, cfg)
        coarse = _with_tail(coarse, tail, False, cfg)
    return Plan(
        final,
        "ok",
        coarse,
        refined,
        time.perf_counter() - t0,
        clr if math.isfinite(clr) else None,
        search_s=res.stats.time_s,
        refine_s=refine_s,
        refine_reason=refine_reason,
        refinement=refinement,
        coarse_min_clearance_m=res.min_clearance_m,
        expansions=res.stats.expansions,
        **settings,
    )


ESCAPE_AFTER = ("expansion budget exhausted", "search space exhausted", "time budget exhausted")
"""Search outcomes after which the goal's slot escape is tried (``after_failed_search``)."""


def _search(scene, cfg: PlanningConfig, geom: VehicleGeometry):
    """Hybrid A* from the start to the goal; when the goal is boxed in
    (:func:`~parknss.sim.planning.escape.is_boxed`: before searching) or, with
    ``escape.after_failed_search``, the search ends in one of :data:`ESCAPE_AFTER`, the
    goal's slot escape
    (:mod:`parknss.sim.planning.escape`) and a search to its outer end instead. Returns
    (search result, the escape's segments driven into the slot (empty if none), why the
    escape ran and how it ended)."""
    ec = cfg.escape
    obstacles = scene.obstacle_arrays()
    boxed = ec.enabled and esc.is_boxed(scene.goal, obstacles, geom, cfg.safety_margin_m, ec)
    res, deadline = None, time.perf_counter() + cfg.time_budget_s
    if not boxed:
        res = HybridAStar(cfg, geom).plan(scene)
        late = ec.enabled and ec.after_failed_search and res.reason in ESCAPE_AFTER
        if res.found or not late or not obstacles:
            return res, [], ""
    t0 = time.perf_counter()
    out = esc.escape(
        scene.goal,
        obstacles,
        geom,
        cfg.safety_margin_m,
        ec,
        lambda p: geometry.inside_map(p, geom, scene),
        deadline,
    )
    why = ("goal boxed in" if boxed else f"search: {res.reason}") + (
        f"; escape: {out.reason}, {len(out.strokes)} strokes, {time.perf_counter() - t0:.2f} s"
    )
    if not out.found:
        return (res or HybridAStar(cfg, geom).plan(scene)), [], why
    end = tuple(float(v) for v in out.end)
    res2 = HybridAStar(cfg, geom).plan(replace(scene, goal=end))
    if res is not None:
        res2.stats.expansions += res.stats.expansions
        res2.stats.time_s += res.stats.time_s
    if not res2.found:
        return res2, [], why + f"; no path to its end ({res2.reason})"
    tail = esc.stroke_segments(esc.reversed_strokes(out.strokes), geom, ec.stop_to_steer)
    return res2, tail, why


def _with_tail(traj: Trajectory, tail: list[Segment], profiled: bool,
               cfg: PlanningConfig) -> Trajectory:
    """``traj`` (ending at the escape's outer end) followed by the escape's segments
    (``profiled``: each with the refinement's trapezoidal speed profile, as a refined plan
    has; the car stops at the junction even when the gear stays)."""
    from parknss.sim.planning.refine_profile import profile_segment

    rc = cfg.refine
    tail = [profile_segment(s, rc.speed_max_ms, rc.accel_max_ms2) if profiled else s
            for s in tail]
    info = dict(traj.info, escape_segments=len(tail))
    return Trajectory(list(traj.segments) + tail, source=traj.source, info=info)


def plan_named_scene(
    spec: str,
    files: SimConfigFiles | None = None,
    *,
    refine: bool = True,
    closed_loop_overrides: dict | None = None,
) -> tuple[sc.Scene, Plan]:
    """(scene, plan) of a scene JSON file, grid cell 0-35 or ``robust:N``, planned with
    the configs of ``files`` (``closed_loop_overrides``: e.g. :data:`NO_RESERVE`)."""
    files = files or SimConfigFiles()
    geom = files.vehicle_geometry()
    scene = load_scene(spec, files.scenarios_config(), geom)
    loop = override(files.closed_loop_config(), closed_loop_overrides, source="plan settings")
    return scene, plan_scene(scene, loop, files.planning_config(), geom, refine=refine)


def plan_cell_job(
    grid: str,
    index: int,
    closed_loop_config: str | None = None,
    planning_config: str | None = None,
    scenarios_config: str | None = None,
    refine: bool = True,
    closed_loop_overrides: dict | None = None,
    vehicle: str | None = None,
) -> dict:
    """Executor job: plan cell ``index`` of grid "36" or "252"; its :meth:`Plan.to_json`."""
    files = SimConfigFiles(closed_loop_config, None, planning_config, scenarios_config, vehicle)
    geom = files.vehicle_geometry()
    scene = sc.cell_scene(grid, index, files.scenarios_config(), geom)
    loop = override(files.closed_loop_config(), closed_loop_overrides, source="plan settings")
    return plan_scene(scene, loop, files.planning_config(), geom, refine=refine).to_json(scene)


def plan_grid(
    grid: str,
    cells: list[int] | None = None,
    *,
    files: SimConfigFiles | None = None,
    refine: bool = True,
    closed_loop_overrides: dict | None = None,
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    cache_dir: str | Path | None = None,
    progress: bool = True,
) -> list[dict]:
    """Plan every cell of grid "36", "12" or "252" (or ``cells`` of it) through the
    executor (:func:`parknss.executor.run_jobs`); one :meth:`Plan.to_json` per cell."""
    files = files or SimConfigFiles()
    if cells is None:
        cells = sc.grid_cells(grid, files.scenarios_config())
    kwargs = {
        "closed_loop_config": files.closed_loop,
        "planning_config": files.planning,
        "scenarios_config": files.scenarios,
        "refine": refine,
        "closed_loop_overrides": closed_loop_overrides,
        "vehicle": files.vehicle,
    }
    return sc.run_cells(
        "parknss.sim.planner:plan_cell_job",
        grid,
        cells,
        kwargs,
        executor=executor,
        workers=workers,
        address=address,
        cache_dir=cache_dir,
        progress=progress,
        desc=f"plan grid {grid}",
    )


def _fmt(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def plan_grid_table(rows: list[dict]) -> str:
    """A fixed-width table of :func:`plan_grid` rows and a summary line."""
    head = (
        f"{'cell':>4} {'name':<34} {'plan':>4} {'search s':>9} {'refine s':>9} "
        f"{'length m':>9} {'cusps':>5} {'min clr m':>9}  reason"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        note = r["reason"] if not r["plannable"] else r["refine_reason"]
        lines.append(
            f"{r['cell']:>4} {r['name']:<34} {'yes' if r['plannable'] else 'no':>4} "
            f"{r['search_time_s']:>9.3f} {r['refine_time_s']:>9.3f} "
            f"{_fmt(r['length_m'], '9.2f'):>9} {_fmt(r['cusps'], '5d'):>5} "
            f"{_fmt(r['min_clearance_m'], '9.3f'):>9}  {note}"
        )
    ok = [r for r in rows if r["plannable"]]
    lines.append("-" * len(head))
    lines.append(f"plannable {len(ok)}/{len(rows)}")
    if ok:
        times = sorted(r["search_time_s"] for r in ok)
        clr = [r["min_clearance_m"] for r in ok if r["min_clearance_m"] is not None]
        lines.append(
            f"search time median {times[len(times) // 2]:.3f} s, max {times[-1]:.3f} s"
            + (f"; min clearance {min(clr):.3f} m" if clr else "")
        )
    return "\n".join(lines)
