"""Issue 17 on the planner: obstacles as drawn, degenerate vertices, solver errors, the lock
on refined paths, and the budget over preprocessing."""

from __future__ import annotations

import math
from dataclasses import replace

import casadi
import numpy as np
import pytest
from shapely.geometry import Polygon

from parknss.config import override
from parknss.sim import geometry
from parknss.sim.closed_loop import ClosedLoopConfig
from parknss.sim.planner import plan_scene, planning_geometry
from parknss.sim.planning import refine as refine_mod
from parknss.sim.planning import refine_problem
from parknss.sim.planning.hybrid_astar import HybridAStar, load_planning_config
from parknss.sim.planning.refine import KAPPA_RTOL, refine
from parknss.sim.planning.refine_obca import dual_warm_start, halfspaces
from parknss.sim.planning.refine_profile import step_curvature
from parknss.sim.scenarios import Obstacle, Scene, grid_scene
from parknss.vehicle import VehicleGeometry

GEOM = VehicleGeometry()


def _l_and_wall_scene() -> Scene:
    """Drive 14 m along a lane past an L-shaped kerb (non-convex) reaching into it and a
    wall drawn as a line on the other side."""
    doc = {
        "bounds": [-12.0, -6.0, 12.0, 6.0],
        "start": [-9.0, 0.0, 0.0],
        "goal": [6.0, 0.0, 0.0],
        "obstacles": [
            {
                "kind": "kerb",
                "vertices": [[-3, -6], [1, -6], [1, -1.6], [-0.5, -1.6], [-0.5, -3.5], [-3, -3.5]],
            },
            {"kind": "wall", "shape": "polyline", "vertices": [[-6, 2.6], [0, 2.6], [4, 3.2]]},
        ],
    }
    return Scene.from_json(doc)


def test_l_shaped_obstacle_and_a_wall_line_are_planned_around_with_the_margin():
    scene = _l_and_wall_scene()
    assert len(scene.obstacles[0].convex_parts()) == 2 and "wall" in scene.notes[1]
    loop = ClosedLoopConfig()
    plan = plan_scene(scene, loop)
    assert plan.trajectory is not None and plan.refined, plan.refine_reason
    # the dense clearance against the shapes as drawn (shapely), not only their parts
    poses = np.concatenate([geometry.densify(s.poses, 0.02) for s in plan.trajectory.segments])
    fps = geometry.footprints(poses[::5], GEOM)
    shapes = [Polygon(o.vertices) for o in scene.obstacles]
    exact = min(Polygon(fp).distance(s) for fp in fps for s in shapes)
    assert exact >= loop.plan_margin_m - 1e-6
    assert plan.min_clearance_m == pytest.approx(
        geometry.dense_clearance(poses, GEOM, scene.obstacle_arrays())[0], abs=1e-9
    )


def test_collinear_and_duplicate_vertices_do_not_break_the_refinement():
    """Issue 17: grid cell 14 with an edge midpoint (and a repeated vertex) on a car:
    the dual warm start divided by zero and CasADi raised out of `plan`."""
    scene = grid_scene(14)
    car = scene.obstacles[0].vertices
    messy = np.insert(car, 1, 0.5 * (car[0] + car[1]), axis=0)
    messy = np.insert(messy, 3, messy[2], axis=0)
    raw = replace(scene, obstacles=(Obstacle("car", messy), *scene.obstacles[1:]))
    A, _ = halfspaces(messy[[0, 1, 2, 4, 5]])  # a collinear vertex: parallel normals
    lam, mu = dual_warm_start(np.array([[0.0, 5.0, 0.0]]), messy[[0, 1, 2, 4, 5]], A, GEOM)
    assert np.all(np.isfinite(lam)) and np.all(np.isfinite(mu))
    plan = plan_scene(raw, ClosedLoopConfig())  # raw arrays, not cleaned on load
    assert plan.trajectory is not None and plan.refined, plan.refine_reason
    loaded = Scene.from_json(
        {
            **scene.to_json(),
            "obstacles": [
                {"kind": "car", "vertices": messy.tolist()},
                *scene.to_json()["obstacles"][1:],
            ],
        }
    )
    assert "2 duplicate/collinear vertices removed" in loaded.notes[0]


def test_any_solver_error_becomes_the_flagged_coarse_fallback(monkeypatch):
    scene = grid_scene(14)
    cfg = load_planning_config()
    coarse = HybridAStar(cfg, GEOM).plan(scene).trajectory

    def broken(*_a, **_k):
        raise RuntimeError("nlpsol: Assertion 'is_regular' failed")

    refine_problem.clear_programs()  # every segment's program is built (and fails)
    monkeypatch.setattr(casadi, "nlpsol", broken)  # what the program build calls
    res = refine(scene, coarse, GEOM, cfg)
    assert not res.ok and res.trajectory.source == "coarse_fallback"
    assert "solver error (RuntimeError" in res.reason

    def explode(*_a, **_k):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr("parknss.sim.planner.refine_path", explode)
    plan = plan_scene(scene, ClosedLoopConfig())
    assert plan.trajectory is not None and not plan.refined
    assert plan.refine_reason.startswith("refinement error (ZeroDivisionError")


@pytest.mark.parametrize("cell", [2, 14, 26, 30])
def test_refined_paths_keep_within_the_steering_lock(cell):
    """Issue 17: the end-pose blend added up to 1.1 % curvature beyond the lock on
    full-lock arcs in the last metre of each gear segment."""
    loop = ClosedLoopConfig()
    plan = plan_scene(grid_scene(cell), loop)
    assert plan.refined, plan.refine_reason
    g = planning_geometry(GEOM, loop.steer_reserve)
    k_max = math.tan(math.radians(g.steer_lock_deg / g.steer_ratio)) / g.wheelbase
    for seg in plan.trajectory.segments:
        assert np.abs(step_curvature(seg.poses)).max() <= k_max * (1 + KAPPA_RTOL)


def test_a_segment_at_the_lock_keeps_its_coarse_poses(monkeypatch):
    """When the path has no curvature to spare for the end offset, the segment is the
    coarse one (exactly on the lock), not a path beyond it."""
    monkeypatch.setattr(refine_mod, "KAPPA_RTOL", -0.5)  # every solution 'exceeds' the lock
    scene = grid_scene(14)
    cfg = load_planning_config()
    coarse = HybridAStar(cfg, GEOM).plan(scene).trajectory
    res = refine(scene, coarse, GEOM, cfg)
    assert res.ok
    kept = [d.get("status") == "kept (at the lock)" for d in res.segments]
    assert any(kept)
    for seg, ref, k in zip(res.trajectory.segments, coarse.segments, kept, strict=True):
        if k:
            np.testing.assert_array_equal(seg.poses, ref.poses)


def test_the_budget_covers_the_setup(monkeypatch):
    cfg = override(load_planning_config(), {"time_budget_s": 1e-6}, source="test")
    res = HybridAStar(cfg, GEOM).plan(grid_scene(26))
    assert not res.found and res.reason == "time budget exhausted"
