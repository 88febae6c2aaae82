"""What the simulator API does, independent of HTTP: resolve a scene, plan it (cached per
scene, so every plant drives the same plan), execute it through a plant, and shape the
results into the response models.

Planning and execution are the ones ``parknss plan`` and ``parknss simulate`` use
(:func:`parknss.sim.planner.plan_scene` with the closed-loop steering reserve and
margin, :func:`parknss.sim.session.run_cell` on that plan), read from the same
configs, so every entry point gives the same plan and outcome for the same scene.
"""

from __future__ import annotations

import hashlib
import json
import math
import tempfile
import threading
from collections import OrderedDict
from dataclasses import replace
from pathlib import Path

import numpy as np

import parknss
from parknss.config import override
from parknss.errors import ParknssError
from parknss.sim import geometry
from parknss.sim import scenarios as sc
from parknss.sim.closed_loop import ClosedLoopConfig, load_closed_loop_config
from parknss.sim.control.interface import load_interface_config
from parknss.sim.planner import Plan, plan_scene
from parknss.sim.plants import PLANT_KINDS
from parknss.sim.scene_formats import read_scene_file
from parknss.sim.session import build_plant, not_plannable, run_cell
from parknss.sim.vehicles import resolve_vehicle
from parknss.vehicle import VehicleGeometry
from parknss.web import payload, scene_checks
from parknss.web.config import WebConfig
from parknss.web.errors import BadSceneError, PlantUnavailableError
from parknss.web.schemas import (
    CellInfo,
    CellList,
    FidelityRequest,
    FidelityResponse,
    Health,
    ImportRequest,
    ImportResponse,
    PlanResponse,
    PlantInfo,
    Run,
    RunOutcome,
    SceneRequest,
    SceneResponse,
    SimulateRequest,
    SimulateResponse,
    TargetCheck,
    VehicleInfo,
)

GRID_SIZES = {"36": sc.N_CELLS, "252": sc.N_ROBUST}
FIDELITY_PLANTS = ("chain", "reference")
"""The candidate and the truth of the fidelity view, in that order."""


def scene_key(scene: sc.Scene) -> str:
    """A digest of the scene's JSON (obstacles, start, goal, bounds, meta)."""
    blob = json.dumps(scene.to_json(), sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def _r(v: float | None, digits: int = 3) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), digits)


class PlanCache:
    """The last ``size`` plans, keyed by :func:`scene_key` (thread-safe LRU)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._plans: OrderedDict[str, Plan] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: str) -> Plan | None:
        with self._lock:
            plan = self._plans.get(key)
            if plan is not None:
                self._plans.move_to_end(key)
            return plan

    def put(self, key: str, plan: Plan) -> None:
        with self._lock:
            self._plans[key] = plan
            self._plans.move_to_end(key)
            while len(self._plans) > self.size:
                self._plans.popitem(last=False)


class SimulatorService:
    """The simulator behind the API, configured once per app."""

    def __init__(self, cfg: WebConfig) -> None:
        self.cfg = cfg
        self.scenarios = sc.load_scenarios_config(cfg.scenarios_config)
        self.closed_loop: ClosedLoopConfig = load_closed_loop_config(cfg.closed_loop_config)
        self.geom: VehicleGeometry = resolve_vehicle(cfg.vehicle, self.closed_loop.chain_path)
        self.interface = load_interface_config(cfg.interface_config)
        self.cache = PlanCache(cfg.plan_cache_size)
        self._plan_lock = threading.Lock()
        self._plants: tuple[tuple, list[PlantInfo]] | None = None  # (files' stats, answer)

    # -- catalogue ----------------------------------------------------------------------

    def vehicle(self) -> VehicleInfo:
        g = self.geom
        return VehicleInfo(
            length_m=g.length,
            width_m=g.width,
            rear_overhang_m=g.rear_overhang,
            wheelbase_m=g.wheelbase,
            track_m=g.track,
            steer_ratio=g.steer_ratio,
        )

    def _chain_stamp(self) -> tuple:
        """(name, size, mtime) of every file of the chain artefact: what decides whether the
        chain plant can be built, cheap to read (no hashing, no loading)."""
        from parknss.config import SHIPPED_PLANT

        root = Path(self.closed_loop.chain_path or SHIPPED_PLANT)
        try:
            files = sorted(p for p in root.rglob("*") if p.is_file())
            return tuple((str(p), p.stat().st_size, p.stat().st_mtime_ns) for p in files)
        except OSError:
            return ("unreadable",)

    def plant_info(self) -> list[PlantInfo]:
        """Every plant kind and whether it can be built here (the chain may be missing).
        Building the chain verifies and loads its artefact (~0.1 s and more while a large
        request holds the interpreter), so the answer is kept until a file of the
        artefact changes (:meth:`_chain_stamp`): /api/health stays instant."""
        stamp = self._chain_stamp()
        if self._plants is not None and self._plants[0] == stamp:
            return list(self._plants[1])
        out = []
        for kind in PLANT_KINDS:
            colour = self.cfg.plant_colours.get(kind, "#34495e")
            try:
                self._make_plant(kind, None)
                out.append(PlantInfo(kind=kind, available=True, colour=colour))
            except PlantUnavailableError as exc:
                out.append(PlantInfo(kind=kind, available=False, reason=str(exc), colour=colour))
        self._plants = (stamp, out)
        return list(out)

    def health(self) -> Health:
        return Health(
            version=parknss.__version__,
            plants=self.plant_info(),
            vehicle=self.vehicle(),
            grids=dict(GRID_SIZES),
            planned_colour=self.cfg.planned_colour,
            accel_smoothing_s=self.cfg.accel_smoothing_s,
            plan_budget_s=self.cfg.plan_budget_s,
            simulate_budget_s=self.cfg.simulate_budget_s,
            view_zoom_above_m=sc.VIEW_ZOOM_ABOVE_M,
            view_zoom_pad_m=sc.VIEW_ZOOM_PAD_M,
        )

    def grid_scene(self, grid: str, index: int) -> sc.Scene:
        """Scene ``index`` of grid "36" or "252"; BadSceneError when out of range."""
        if grid not in GRID_SIZES:
            raise BadSceneError(f"grid must be 36 or 252, got {grid!r}")
        n = GRID_SIZES[grid]
        if isinstance(index, bool) or not 0 <= index < n:
            raise BadSceneError(f"cell index must be 0..{n - 1} on grid {grid}, got {index}")
        if grid == "252":
            return sc.robust_scene(index, self.scenarios, self.geom)
        return sc.grid_scene(index, self.scenarios, self.geom)

    def cells(self, grid: str) -> CellList:
        """Every cell of a grid with its bay, approach, tier, barrier and perturbation."""
        if grid not in GRID_SIZES:
            raise BadSceneError(f"grid must be 36 or 252, got {grid!r}")
        cells = []
        for i in range(GRID_SIZES[grid]):
            m = self.grid_scene(grid, i).meta
            cells.append(
                CellInfo(
                    grid=grid,
                    index=i,
                    cell=int(m.cell),
                    name=m.name,
                    bay=m.bay,
                    approach=str(m.approach),
                    tier=int(m.tier),
                    barrier=bool(m.barrier),
                    perturbation=m.perturbation,
                    slot_size_m=m.slot_size_m,
                )
            )
        return CellList(grid=grid, cells=cells)

    def scene_response(self, grid: str, index: int) -> SceneResponse:
        return SceneResponse(grid=grid, index=index, scene=self.grid_scene(grid, index).to_json())

    # -- scenes -------------------------------------------------------------------------

    def resolve(self, req: SceneRequest) -> sc.Scene:
        """The scene of a request, with its start replaced if given; BadSceneError when the
        scene is malformed or the start pose is off the map or touches an obstacle."""
        limits = self.cfg.max_coordinate_m, self.cfg.max_heading_rad
        if req.start is not None:
            scene_checks.check_pose(req.start, "start", *limits)
        if req.index is not None:
            scene = self.grid_scene(req.grid, req.index)
        else:
            scene_checks.check_scene_json(req.scene, *limits)
            try:
                scene = sc.Scene.from_json(req.scene, "scene", self.scenarios.obstacles)
            except ParknssError as exc:
                raise BadSceneError(str(exc)) from exc
        if req.start is not None:
            scene = replace(scene, start=tuple(float(v) for v in req.start))
        self.check_start(scene)
        return scene

    def import_scene(self, req: ImportRequest) -> ImportResponse:
        """A TPCAP .csv or CommonRoad .xml file's text as scene JSON (for the service's car);
        BadSceneError when the file is malformed or of another kind."""
        suffix = Path(req.filename).suffix.lower()
        if suffix not in (".csv", ".xml"):
            raise BadSceneError(f"{req.filename}: import takes a TPCAP .csv or CommonRoad .xml")
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / Path(req.filename).name
            path.write_text(req.text)
            try:
                scene = read_scene_file(path, self.scenarios.obstacles, self.scenarios.imports,
                                        self.geom)
            except ParknssError as exc:
                raise BadSceneError(str(exc).replace(str(path), req.filename)) from exc
        meta = replace(scene.meta, source=req.filename)
        notes = [n.replace(str(path), req.filename) for n in scene.notes]
        doc = replace(scene, meta=meta).to_json()
        scene_checks.check_scene_json(doc, self.cfg.max_coordinate_m, self.cfg.max_heading_rad)
        return ImportResponse(scene=doc, notes=notes)

    def check_start(self, scene: sc.Scene) -> None:
        """BadSceneError when the car at the start pose is off the map or hits an obstacle."""
        pose = np.asarray([scene.start], dtype=float)
        x, y, th = scene.start
        where = f"start pose ({x:.2f} m, {y:.2f} m, {math.degrees(th):.1f}°)"
        if not geometry.inside_map(pose, self.geom, scene)[0]:
            raise BadSceneError(f"{where}: the car leaves the map {list(scene.bounds)}")
        for i, ob in enumerate(scene.obstacles):
            if np.any(geometry.collides(pose, self.geom, list(ob.convex_parts()))):
                raise BadSceneError(f"{where}: the car overlaps obstacle {i} ({ob.kind})")

    # -- planning -----------------------------------------------------------------------

    def plan(self, scene: sc.Scene) -> tuple[Plan, bool]:
        """(plan, from cache) with the closed-loop planning settings of parknss simulate."""
        key = scene_key(scene)
        with self._plan_lock:  # one search per scene, even for concurrent requests
            hit = self.cache.get(key)
            if hit is not None:
                return hit, True
            plan = plan_scene(scene, self.closed_loop, self.cfg.planning_config, self.geom)
            self.cache.put(key, plan)
            return plan, False

    def plan_response(self, scene: sc.Scene, plan: Plan, cached: bool) -> PlanResponse:
        traj, c = plan.trajectory, self.cfg
        return PlanResponse(
            scene_key=scene_key(scene),
            name=scene.meta.name,
            plannable=traj is not None,
            reason=plan.reason,
            refined=plan.refined,
            cached=cached,
            plan_s=round(plan.plan_s, 4),
            length_m=_r(traj.length) if traj else None,
            cusps=traj.cusps if traj else None,
            min_clearance_cm=None
            if plan.min_clearance_m is None
            else _r(plan.min_clearance_m * 100.0, 2),
            start=tuple(scene.start),
            goal=tuple(scene.goal),
            path=payload.path_segments(traj, c.path_step_m),
            coarse=payload.path_segments(plan.coarse, c.path_step_m),
            cusp_poses=payload.cusp_poses(traj),
            footprints=payload.path_footprints(traj, self.geom, c.footprint_step_m),
        )

    def plan_request(self, req: SceneRequest) -> PlanResponse:
        scene = self.resolve(req)
        plan, cached = self.plan(scene)
        return self.plan_response(scene, plan, cached)

    # -- execution ----------------------------------------------------------------------

    def _loop_config(self, seed: int | None) -> ClosedLoopConfig:
        if seed is None:
            return self.closed_loop
        return override(self.closed_loop, {"plant_seed": int(seed)}, source="seed")

    def _make_plant(self, kind: str, seed: int | None):
        if kind not in PLANT_KINDS:
            raise BadSceneError(f"unknown plant {kind!r}; one of {', '.join(PLANT_KINDS)}")
        cfg = self._loop_config(seed)
        try:
            return build_plant(kind, cfg, self.geom)
        except ParknssError as exc:
            msg = str(exc)
            if not msg.startswith(f"{kind} plant"):
                msg = f"{kind} plant unavailable: {msg}"
            raise PlantUnavailableError(msg) from exc

    def simulate(self, req: SimulateRequest) -> SimulateResponse:
        """Plan (or reuse the plan of) the scene and drive it through ``req.plant``."""
        scene = self.resolve(req)
        self._make_plant(req.plant, req.seed)  # fail fast, before planning
        plan, cached = self.plan(scene)
        cfg = self._loop_config(req.seed)
        if plan.trajectory is None:
            outcome = not_plannable(req.plant, plan)
        else:
            _, (outcome,) = run_cell(
                scene, [req.plant], cfg, self.interface, None, self.geom, plan.trajectory
            )
        run = self._run(outcome, cfg.plant_seed if req.plant == "reference" else None)
        return SimulateResponse(
            plan=self.plan_response(scene, plan, cached), outcome=run.outcome, series=run.series
        )

    def fidelity(self, req: FidelityRequest) -> FidelityResponse:
        """Drive the scene's plan under the chain and under the truth with one plant noise
        seed (``req.seed``, else the seed ``parknss fidelity`` gives this cell) and score
        the chain's run against the truth's (:func:`parknss.sim.fidelity.compare_outcomes`,
        the targets of the fidelity config on this one cell)."""
        from parknss.experiments.fidelity import fidelity_specs
        from parknss.sim.fidelity import (
            cell_seed,
            compare_outcomes,
            load_fidelity_config,
            summarize_fidelity,
        )

        fcfg = load_fidelity_config(self.cfg.fidelity_config)
        scene = self.resolve(req)
        for kind in FIDELITY_PLANTS:
            self._make_plant(kind, None)  # fail fast, before planning
        plan, cached = self.plan(scene)
        if req.seed is not None:
            seed = int(req.seed)
        else:  # the spec parknss fidelity names a grid cell by; a scene's name otherwise
            spec = scene.meta.name if req.index is None else (
                fidelity_specs(grid=req.grid, cells=str(req.index))[0])
            seed = cell_seed(fcfg.seed, spec)
        cfg = self._loop_config(seed)
        if plan.trajectory is None:
            chain, truth = (not_plannable(k, plan) for k in FIDELITY_PLANTS)
        else:
            _, (chain, truth) = run_cell(
                scene, list(FIDELITY_PLANTS), cfg, self.interface, None, self.geom,
                plan.trajectory,
            )  # fmt: skip
        cell = None
        targets: list[TargetCheck] = []
        if plan.trajectory is not None:
            cell = compare_outcomes(chain, truth, scene.meta.name, fcfg.iso)
            summary = summarize_fidelity([cell], fcfg.targets)
            targets = [TargetCheck(label=t.label, measured=t.measured, limit=t.limit,
                                   passed=t.passed) for t in summary.targets]  # fmt: skip
        return FidelityResponse(
            plan=self.plan_response(scene, plan, cached),
            seed=seed,
            chain=self._run(chain, None),
            truth=self._run(truth, seed),
            fidelity=None if cell is None else payload.finite(cell.to_json()),
            targets=targets,
        )

    def _run(self, outcome, seed: int | None) -> Run:
        """The response form of a closed-loop outcome: its numbers and decimated series."""
        doc = outcome.to_json()
        result = RunOutcome(
            plant=outcome.plant,
            completed=outcome.completed,
            reason=outcome.reason,
            goal_error_cm=doc["goal_error_cm"],
            heading_error_deg=doc["heading_error_deg"],
            clearance_cm=doc["clearance_cm"],
            duration_s=round(outcome.duration_s, 3),
            wall_s=round(outcome.wall_s, 3),
            realtime_factor=doc["realtime_factor"],
            driven_length_m=round(outcome.driven_length_m, 3),
            gear_changes=outcome.gear_changes,
            steps=outcome.steps,
            seed=seed,
        )
        series = (
            payload.decimate_series(
                outcome.series, self.cfg.series_rate_hz, self.cfg.max_series_points
            )
            if outcome.series
            else None
        )
        return Run(outcome=result, series=series)
