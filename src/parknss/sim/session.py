"""One scene in closed loop: plan it once, drive the plan under each plant.

:func:`run_cell` is the unit every entry point shares (``parknss simulate``, the grid
job, the web simulator); :func:`simulate_scene` resolves a scene name (a scene file, a
grid cell, ``robust:N``), runs it and returns a :class:`SceneRun` with the JSON summary
that ``parknss simulate`` prints. Figures of a run are drawn by
:func:`parknss.report.sim_figures.draw_scene_run`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parknss.outputs import atomic_file, inside, safe_stem
from parknss.sim import scenarios as sc
from parknss.sim.closed_loop import (
    ClosedLoopConfig,
    Outcome,
    SimConfigFiles,
    execute,
    load_closed_loop_config,
)
from parknss.sim.control.interface import InterfaceConfig
from parknss.sim.control.mpc import PreviewMpc
from parknss.sim.planner import Plan, plan_scene
from parknss.sim.planning.hybrid_astar import PlanningConfig
from parknss.sim.plants import SimPlant, make_plant
from parknss.sim.scene_formats import load_scene
from parknss.sim.trajectory import Trajectory
from parknss.vehicle import VehicleGeometry


def build_plant(kind: str, cfg: ClosedLoopConfig, geom: VehicleGeometry | None = None) -> SimPlant:
    """The plant ``kind`` as the closed-loop config sets it up (reference vehicle file,
    chain artefact, noise seed); one-line ParknssError when it cannot be built here."""
    return make_plant(
        kind,
        geom=geom,
        vehicle_yaml=cfg.reference_vehicle,
        chain_path=cfg.chain_path,
        seed=cfg.plant_seed,
    )


def check_plants(
    kinds: list[str], cfg: ClosedLoopConfig | None = None, geom: VehicleGeometry | None = None
) -> None:
    """Fail fast, with one line, when a plant of ``kinds`` cannot be built here (or, given
    the car ``geom``, was identified on another car)."""
    cfg = cfg if cfg is not None else load_closed_loop_config()
    for kind in kinds:
        build_plant(kind, cfg, geom)


def not_plannable(plant_name: str, plan: Plan) -> Outcome:
    """The outcome recorded for a cell the planner could not solve."""
    return Outcome(False, "not plannable", plant_name, duration_s=0.0, wall_s=plan.plan_s)


def run_cell(
    scene: sc.Scene,
    plants: list[str],
    cfg: ClosedLoopConfig | None = None,
    interface_cfg: InterfaceConfig | None = None,
    planning: PlanningConfig | str | Path | None = None,
    geom: VehicleGeometry | None = None,
    trajectory: Trajectory | None = None,
) -> tuple[Plan, list[Outcome]]:
    """Plan ``scene`` once (unless ``trajectory`` is given) and execute it under each plant
    (kinds of :data:`~parknss.sim.plants.PLANT_KINDS`)."""
    cfg = cfg or ClosedLoopConfig()
    geom = geom or VehicleGeometry()
    if trajectory is None:
        plan = plan_scene(scene, cfg, planning, geom)
    else:
        plan = Plan(trajectory, "given", trajectory)
    outcomes = []
    mpc = PreviewMpc(cfg.tracker.mpc)
    for kind in plants:
        plant = build_plant(kind, cfg, geom)
        if plan.trajectory is None:
            outcomes.append(not_plannable(plant.name, plan))
        else:
            outcomes.append(execute(scene, plan.trajectory, plant, cfg, interface_cfg, geom, mpc))
    return plan, outcomes


@dataclass
class SceneRun:
    """One scene planned once and driven under one or more plants."""

    scene: sc.Scene
    plan: Plan
    outcomes: list[Outcome]
    geom: VehicleGeometry | None = None  # the car planned and driven (None: default car)

    def to_json(self) -> dict:
        """The summary ``parknss simulate --json`` prints (without figures): the plan
        (``plan``: exactly ``parknss plan --json``'s document), the first plant's result
        at top level and every run under ``runs``."""
        plan, traj, meta = self.plan, self.plan.trajectory, self.scene.meta
        doc: dict = {
            "scene": meta.name,
            "cell": meta.cell if meta.robust_index is None else meta.robust_index,
            "plannable": traj is not None,
            "plan_reason": plan.reason,
            "refined": plan.refined,
            "plan_s": round(plan.plan_s, 4),
            "cusps": traj.cusps if traj else None,
            "planned_length_m": traj.length if traj else None,
        }
        first = self.outcomes[0].to_json()
        for key in ("plant", "completed", "reason", "goal_error_cm", "heading_error_deg"):
            doc[key] = first[key]
        for key in ("clearance_cm", "duration_s", "realtime_factor"):
            doc[key] = first[key]
        doc["runs"] = [o.to_json() for o in self.outcomes]
        doc["plan"] = plan.to_json(self.scene)
        if self.scene.notes:
            doc["scene_notes"] = list(self.scene.notes)
        return doc

    def write_series(self, out: Path) -> dict[str, str]:
        """Write each run's 100 Hz time series as ``series_<scene>_<plant>.csv`` in
        ``out``; {plant: path}."""
        paths = {}
        for o in self.outcomes:
            name = safe_stem(self.scene.meta.name, what="scene name")
            p = inside(out, f"series_{name}_{o.plant}.csv")
            write_series(o.series, p)
            paths[o.plant] = str(p)
        return paths


def write_series(series: dict[str, np.ndarray], path: Path) -> None:
    """One CSV with a header of the column names and one row per 10 ms sample."""
    cols = list(series)
    mat = np.column_stack([series[c] for c in cols])
    with atomic_file(path) as tmp:
        np.savetxt(tmp, mat, delimiter=",", header=",".join(cols), comments="", fmt="%.6g")


def simulate_scene(
    spec: str | sc.Scene, plants: list[str], files: SimConfigFiles | None = None
) -> SceneRun:
    """Plan a scene (a scene file, grid cell 0-35, ``robust:N``, or a Scene) once and
    execute it under each plant, with the configs and the car of ``files``."""
    files = files or SimConfigFiles()
    cfg = files.closed_loop_config()
    geom = files.vehicle_geometry()
    check_plants(plants, cfg, geom)
    scene = (
        spec if isinstance(spec, sc.Scene) else load_scene(spec, files.scenarios_config(), geom)
    )
    plan, outcomes = run_cell(scene, plants, cfg, files.interface_config(), files.planning, geom)
    return SceneRun(scene, plan, outcomes, geom)


def _f(v, spec: str) -> str:
    width = int(spec.split(".")[0]) if spec[0].isdigit() else 0
    return "-".rjust(width) if v is None else format(v, spec)


def summary_text(doc: dict) -> str:
    """The table ``parknss simulate`` prints for a :meth:`SceneRun.to_json` document:
    one row per plant (result, goal error cm, heading error deg, clearance cm, duration
    s), then the figure paths."""
    lines = [f"scene {doc['scene']}: plannable {doc['plannable']} ({doc['plan_reason']})"]
    head = ("plant", "result", "goal cm", "head deg", "clr cm", "dur s")
    lines.append("{:<10} {:<10} {:>8} {:>8} {:>7} {:>7}".format(*head))
    for r in doc["runs"]:
        lines.append(
            f"{r['plant']:<10} {r['reason']:<10} {_f(r['goal_error_cm'], '8.2f')} "
            f"{_f(r['heading_error_deg'], '8.2f')} {_f(r['clearance_cm'], '7.1f')} "
            f"{_f(r['duration_s'], '7.2f')}"
        )
    lines += [f"{k}: {v}" for k, v in doc.get("figures", {}).items()]
    return "\n".join(lines)
