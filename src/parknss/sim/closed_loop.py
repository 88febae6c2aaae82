"""One parking cell in closed loop: plan, then tracker + command interface + plant at 100 Hz.

:func:`plan_scene` plans a scene once (Hybrid A*, then the refinement when it is
installed and its result passes the exact dense check; otherwise the coarse path).
:func:`execute` drives a trajectory through a plant until

* **completed**: the last segment ended, the car stands still and park is engaged;
* **collision**: the exact footprint overlaps an obstacle (checked at every 10 ms
  pose, in batches of ``collision_every``; the run ends at the first contact);
* **livelock**: the path progress has not grown by ``livelock_progress_m`` for
  ``livelock_s`` seconds (the car stands or oscillates without getting on);
* **timeout**: ``timeout_s`` of simulated time.

The :class:`Outcome` carries the goal position error (cm, rear axle against the scene's
goal) and heading error (deg), measured at the final pose whatever the reason, the driven
clearance (exact dense minimum over every executed pose, cm), the duration, and the full
time series.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from pydantic import Field

from parknss.config import CONFIG_DIR, StrictModel, load_config
from parknss.errors import ParknssError
from parknss.plant import PlantOutput
from parknss.sim import geometry
from parknss.sim.control.interface import CommandInterface, InterfaceConfig
from parknss.sim.control.mpc import PreviewMpc
from parknss.sim.control.tracker import Tracker, TrackerConfig
from parknss.sim.plants import Actuation, PoseIntegrator, SimPlant
from parknss.sim.trajectory import Trajectory
from parknss.vehicle import VehicleGeometry

REASONS = ("completed", "collision", "livelock", "timeout", "not plannable")
SERIES_COLUMNS = (
    "t",
    "x",
    "y",
    "heading",
    "vx",
    "yaw_rate",
    "ax",
    "ay",
    "gear",
    "torque",
    "brake_pressure",
    "steer",
    "gear_cmd",
    "torque_cmd",
    "decel_cmd",
    "steer_cmd",
    "speed_req",
    "steer_req",
    "progress",
    "lateral_error",
    "heading_error",
    "segment",
)


class ClosedLoopConfig(StrictModel):
    """Termination rules and the tracker (configs/closed_loop.yaml)."""

    timeout_s: float = Field(240.0, gt=0, description="simulated-time limit, s")
    livelock_s: float = Field(20.0, gt=0, description="no progress for this long: livelock, s")
    livelock_progress_m: float = Field(0.02, gt=0, description="progress that counts, m")
    collision_every: int = Field(10, ge=1, description="poses per collision batch")
    clearance_floor_cm: float = Field(20.0, ge=0, description="ultrasonic sensor floor, cm")
    reference_vehicle: str | None = Field(None, description="reference-plant vehicle YAML")
    chain_path: str | None = Field(None, description="chain checkpoint (default: shipped)")
    plant_seed: int | None = Field(None, description="reference-plant noise seed")
    steer_reserve: float = Field(
        0.1, ge=0, lt=0.5, description="fraction of the steering lock the plan leaves free"
    )
    plan_margin_m: float | None = Field(
        0.2, ge=0, description="planner clearance margin for closed-loop runs (None: planning.yaml)"
    )
    tracker: TrackerConfig = TrackerConfig()


def load_closed_loop_config(path: str | Path | None = None) -> ClosedLoopConfig:
    """Read configs/closed_loop.yaml (or ``path``); defaults when the file is absent."""
    p = Path(path) if path is not None else CONFIG_DIR / "closed_loop.yaml"
    return load_config(ClosedLoopConfig, p if (path is not None or p.is_file()) else None)


@dataclass
class Outcome:
    """The result of one closed-loop run (units in the names)."""

    completed: bool
    reason: str
    plant: str
    goal_error_cm: float | None = None
    heading_error_deg: float | None = None
    clearance_cm: float | None = None
    duration_s: float = 0.0
    wall_s: float = 0.0
    steps: int = 0
    planned_length_m: float | None = None
    cusps: int | None = None
    driven_length_m: float = 0.0
    gear_changes: int = 0
    series: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.duration_s / self.wall_s if self.wall_s > 0 else math.inf

    def to_json(self) -> dict:
        """The scalar fields as a JSON-ready dict (no time series)."""
        out = {k: v for k, v in self.__dict__.items() if k != "series"}
        for k, v in out.items():
            if isinstance(v, float) and not math.isfinite(v):
                out[k] = None
        out["realtime_factor"] = (
            round(self.realtime_factor, 2) if math.isfinite(self.realtime_factor) else None
        )
        return out


# ---------------------------------------------------------------------------------------
# Planning


@dataclass
class Plan:
    """A scene's plan: the trajectory driven (None if not plannable) and how it was made."""

    trajectory: Trajectory | None
    reason: str
    coarse: Trajectory | None = None
    refined: bool = False
    plan_s: float = 0.0
    min_clearance_m: float | None = None


def planning_geometry(geom: VehicleGeometry, steer_reserve: float) -> VehicleGeometry:
    """The planner's vehicle: the same body, the steering lock reduced by ``steer_reserve``
    (a fraction) so the tracker keeps steering authority on full-lock arcs."""
    return replace(geom, steer_lock_deg=geom.steer_lock_deg * (1.0 - steer_reserve))


def plan_scene(
    scene,
    planning_config: str | Path | None = None,
    geom: VehicleGeometry | None = None,
    steer_reserve: float = 0.0,
    safety_margin_m: float | None = None,
) -> Plan:
    """Hybrid A* plus refinement (if installed and it passes the dense check).

    The planner and the refinement use :func:`planning_geometry` (``steer_reserve`` of
    the lock held back for feedback); the dense check uses the body of ``geom``.
    ``safety_margin_m`` (m), when given, replaces the planning config's clearance margin.
    """
    from parknss.sim.planning.hybrid_astar import (
        HybridAStar,
        load_planning_config,
        verify_trajectory,
    )

    geom = planning_geometry(geom or VehicleGeometry(), steer_reserve)
    cfg = load_planning_config(planning_config)
    if safety_margin_m is not None:
        cfg = type(cfg).model_validate({**cfg.model_dump(), "safety_margin_m": safety_margin_m})
    t0 = time.perf_counter()
    res = HybridAStar(cfg, geom).plan(scene)
    if not res.found:
        return Plan(None, res.reason, plan_s=time.perf_counter() - t0)
    final, refined = res.trajectory, False
    try:
        from parknss.sim.planning.refine import refine
    except ImportError:
        refine = None
    if refine is not None:
        try:
            rr = refine(scene, res.trajectory, geom, cfg)
        except ParknssError:
            rr = None
        traj = getattr(rr, "trajectory", None)
        if rr is not None and getattr(rr, "ok", False) and traj is not None and traj.segments:
            passed, _ = verify_trajectory(traj, scene, geom, cfg)
            if passed:
                final, refined = traj, True
    _, clr = verify_trajectory(final, scene, geom, cfg)
    return Plan(
        final,
        "ok",
        res.trajectory,
        refined,
        time.perf_counter() - t0,
        clr if math.isfinite(clr) else None,
    )


# ---------------------------------------------------------------------------------------
# Execution


class _Recorder:
    """Preallocated time-series buffers."""

    def __init__(self, n: int) -> None:
        self.data = {c: np.zeros(n) for c in SERIES_COLUMNS}
        self.n = 0

    def add(self, t, pose, y: PlantOutput, cmd, req, tracker: Tracker) -> None:
        k, d = self.n, self.data
        d["t"][k] = t
        d["x"][k], d["y"][k], d["heading"][k] = pose
        d["vx"][k], d["yaw_rate"][k], d["ax"][k], d["ay"][k] = y.vx, y.yaw_rate, y.ax, y.ay
        d["gear"][k], d["torque"][k] = y.gear, y.torque
        d["brake_pressure"][k], d["steer"][k] = y.brake_pressure, y.steer
        d["gear_cmd"][k], d["torque_cmd"][k] = cmd.gear, cmd.torque_cmd
        d["decel_cmd"][k], d["steer_cmd"][k] = cmd.decel_cmd, cmd.steer_cmd
        d["speed_req"][k] = req.direction * req.speed
        d["steer_req"][k], d["progress"][k] = req.steer, tracker.progress
        proj = tracker.last
        d["lateral_error"][k] = proj.e_y if proj is not None else np.nan
        d["heading_error"][k] = proj.e_phi if proj is not None else np.nan
        d["segment"][k] = tracker.index
        self.n += 1

    def arrays(self) -> dict[str, np.ndarray]:
        return {c: v[: self.n].copy() for c, v in self.data.items()}


class _CollisionCheck:
    """Exact footprint/obstacle overlap (SAT) for a batch of poses, with a bounding-circle
    broad phase: only obstacles whose circle comes within reach of the batch are tested."""

    def __init__(self, obstacles: list[np.ndarray], geom: VehicleGeometry) -> None:
        self.obstacles = obstacles
        self.geom = geom
        local = geometry.body_corners(geom)
        self.centre = local.mean(axis=0)
        self.r_car = float(np.max(np.hypot(*(local - self.centre).T)))
        self.oc = np.array([o.mean(axis=0) for o in obstacles]).reshape(-1, 2)
        self.r_obs = np.array([np.max(np.hypot(*(o - o.mean(axis=0)).T)) for o in obstacles])

    def collides(self, poses: np.ndarray) -> np.ndarray:
        """(N,) True where the footprint at pose i overlaps an obstacle."""
        hit = np.zeros(len(poses), dtype=bool)
        if not self.obstacles or not len(poses):
            return hit
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        cx = poses[:, 0] + c * self.centre[0] - s * self.centre[1]
        cy = poses[:, 1] + s * self.centre[0] + c * self.centre[1]
        gap = np.hypot(cx[:, None] - self.oc[:, 0], cy[:, None] - self.oc[:, 1])
        near = np.flatnonzero(np.any(gap <= self.r_car + self.r_obs + 1e-6, axis=0))
        if len(near):
            fp = geometry.footprints(poses, self.geom)
            for j in near:
                hit |= geometry.intersects(fp, self.obstacles[j])
        return hit


def _wrap_deg(a: float) -> float:
    return abs(math.degrees((a + math.pi) % (2.0 * math.pi) - math.pi))


def execute(
    scene,
    trajectory: Trajectory,
    plant: SimPlant,
    cfg: ClosedLoopConfig | None = None,
    interface_cfg: InterfaceConfig | None = None,
    geom: VehicleGeometry | None = None,
    mpc: PreviewMpc | None = None,
) -> Outcome:
    """Drive ``trajectory`` from ``scene.start`` through ``plant`` (see module docstring)."""
    cfg = cfg or ClosedLoopConfig()
    geom = geom or VehicleGeometry()
    wall0 = time.perf_counter()
    dt = plant.dt
    tracker = Tracker(trajectory, cfg.tracker, geom, dt, mpc)
    iface = CommandInterface(interface_cfg, dt)
    integ = PoseIntegrator(scene.start, dt)
    broad = _CollisionCheck(scene.obstacle_arrays(), geom)
    n_max = round(cfg.timeout_s / dt) + 1
    rec = _Recorder(n_max)
    y = plant.reset()
    poses = np.empty((n_max, 3))
    checked = 0
    best, best_t = -math.inf, 0.0
    reason = "timeout"
    for k in range(n_max):
        t = k * dt
        pose = integ.pose
        poses[k] = pose
        req = tracker.step(pose, y, iface.standstill)
        cmd = iface.step(req, y)
        rec.add(t, pose, y, cmd, req, tracker)
        if k + 1 - checked >= cfg.collision_every or tracker.done:
            hit = broad.collides(poses[checked : k + 1])
            if np.any(hit):
                first = checked + int(np.argmax(hit))
                rec.n = first + 1
                reason = "collision"
                break
            checked = k + 1
        if tracker.done:
            reason = "completed"
            break
        if tracker.progress > best + cfg.livelock_progress_m:
            best, best_t = tracker.progress, t
        elif t - best_t >= cfg.livelock_s:
            reason = "livelock"
            break
        y = plant.advance(Actuation(cmd, iface.speed_target))
        integ.step(*plant.motion)
    series = rec.arrays()
    return _outcome(scene, trajectory, plant, cfg, geom, series, reason, iface, wall0)


def _outcome(scene, traj, plant, cfg, geom, series, reason, iface, wall0) -> Outcome:
    """Scalar metrics of a finished run."""
    x, y, th = series["x"], series["y"], series["heading"]
    gx, gy, gth = scene.goal
    obstacles = scene.obstacle_arrays()
    clr, _ = geometry.dense_clearance(np.column_stack([x, y, th]), geom, obstacles)
    driven = float(np.sum(np.hypot(np.diff(x), np.diff(y)))) if len(x) > 1 else 0.0
    return Outcome(
        completed=reason == "completed",
        reason=reason,
        plant=plant.name,
        goal_error_cm=float(math.hypot(x[-1] - gx, y[-1] - gy) * 100.0),
        heading_error_deg=_wrap_deg(th[-1] - gth),
        clearance_cm=clr * 100.0 if math.isfinite(clr) else None,
        duration_s=float(series["t"][-1]),
        wall_s=time.perf_counter() - wall0,
        steps=len(x),
        planned_length_m=traj.length,
        cusps=traj.cusps,
        driven_length_m=driven,
        gear_changes=int(np.count_nonzero(np.diff(series["gear_cmd"]))),
        series=series,
    )


def not_plannable(plant_name: str, plan: Plan) -> Outcome:
    """The outcome recorded for a cell the planner could not solve."""
    return Outcome(False, "not plannable", plant_name, duration_s=0.0, wall_s=plan.plan_s)


# ---------------------------------------------------------------------------------------
# Cells and grids


def run_cell(
    scene,
    plants: list[str],
    cfg: ClosedLoopConfig | None = None,
    interface_cfg: InterfaceConfig | None = None,
    planning_config: str | Path | None = None,
    geom: VehicleGeometry | None = None,
    trajectory: Trajectory | None = None,
) -> tuple[Plan, list[Outcome]]:
    """Plan ``scene`` once (unless ``trajectory`` is given) and execute it under each plant."""
    from parknss.sim.plants import make_plant

    cfg = cfg or ClosedLoopConfig()
    geom = geom or VehicleGeometry()
    if trajectory is None:
        plan = plan_scene(scene, planning_config, geom, cfg.steer_reserve, cfg.plan_margin_m)
    else:
        plan = Plan(trajectory, "given", trajectory)
    outcomes = []
    mpc = PreviewMpc(cfg.tracker.mpc)
    for kind in plants:
        plant = make_plant(
            kind,
            geom=geom,
            vehicle_yaml=cfg.reference_vehicle,
            chain_path=cfg.chain_path,
            seed=cfg.plant_seed,
        )
        if plan.trajectory is None:
            outcomes.append(not_plannable(plant.name, plan))
        else:
            outcomes.append(execute(scene, plan.trajectory, plant, cfg, interface_cfg, geom, mpc))
    return plan, outcomes


def cell_job(
    grid: str,
    index: int,
    plants: list[str],
    closed_loop_config: str | None = None,
    interface_config: str | None = None,
    interface_overrides: dict | None = None,
    planning_config: str | None = None,
    scenarios_config: str | None = None,
) -> list[dict]:
    """Executor job: one cell of grid "36" or "252" under each plant; JSON rows."""
    from parknss.sim import scenarios as sc
    from parknss.sim.control.interface import load_interface_config

    scfg = sc.load_scenarios_config(scenarios_config)
    scene = sc.robust_scene(index, scfg) if grid == "252" else sc.grid_scene(index, scfg)
    cfg = load_closed_loop_config(closed_loop_config)
    icfg = load_interface_config(interface_config)
    if interface_overrides:
        icfg = type(icfg).model_validate({**icfg.model_dump(), **interface_overrides})
    plan, outcomes = run_cell(scene, plants, cfg, icfg, planning_config)
    rows = []
    for o in outcomes:
        row = o.to_json()
        row.update(
            grid=grid,
            index=index,
            cell=scene.meta.cell,
            name=scene.meta.name,
            perturbation=scene.meta.perturbation,
            plannable=plan.trajectory is not None,
            plan_reason=plan.reason,
            refined=plan.refined,
            plan_s=round(plan.plan_s, 4),
            plan_clearance_cm=None
            if plan.min_clearance_m is None
            else plan.min_clearance_m * 100.0,
        )
        rows.append(row)
    return rows


@dataclass
class GridSummary:
    """Table V statistics of one plant over a set of cells (goal errors over every
    executed cell, failed runs at their final pose; cm, s)."""

    plant: str
    cells: int
    plannable: int
    completed: int
    goal_mean_cm: float | None
    goal_median_cm: float | None
    goal_max_cm: float | None
    clearance_mean_cm: float | None
    under_floor: int
    over_20cm_goal: int
    collisions: int
    livelocks: int
    timeouts: int
    duration_mean_s: float | None
    sim_s: float
    wall_s: float

    @property
    def realtime_factor(self) -> float | None:
        return self.sim_s / self.wall_s if self.wall_s > 0 else None

    def to_json(self) -> dict:
        out = dict(self.__dict__)
        out["realtime_factor"] = self.realtime_factor
        return out


def summarize(rows: list[dict], plant: str, floor_cm: float = 20.0) -> GridSummary:
    """Aggregate the rows of one plant (see :class:`GridSummary`)."""
    mine = [r for r in rows if r["plant"] == plant]
    ran = [r for r in mine if r["plannable"]]
    goals = np.array([r["goal_error_cm"] for r in ran], float)
    clr = np.array([r["clearance_cm"] for r in ran if r["clearance_cm"] is not None], float)

    def stat(fn, a):
        return float(fn(a)) if len(a) else None

    return GridSummary(
        plant=plant,
        cells=len(mine),
        plannable=len(ran),
        completed=sum(r["completed"] for r in ran),
        goal_mean_cm=stat(np.mean, goals),
        goal_median_cm=stat(np.median, goals),
        goal_max_cm=stat(np.max, goals),
        clearance_mean_cm=stat(np.mean, clr),
        under_floor=int(np.sum(clr < floor_cm)),
        over_20cm_goal=int(np.sum(goals > 20.0)),
        collisions=sum(r["reason"] == "collision" for r in ran),
        livelocks=sum(r["reason"] == "livelock" for r in ran),
        timeouts=sum(r["reason"] == "timeout" for r in ran),
        duration_mean_s=stat(np.mean, np.array([r["duration_s"] for r in ran], float)),
        sim_s=float(sum(r["duration_s"] for r in ran)),
        wall_s=float(sum(r["wall_s"] for r in mine)),
    )
