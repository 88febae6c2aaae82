"""Hybrid A*: plans are kinematically valid, collision-free by the exact dense check, and
degenerate requests end with a reason inside the time budget."""

import itertools
import math
import time
from dataclasses import replace

import numpy as np
import pytest

from parknss.errors import ConfigError
from parknss.sim import geometry as g
from parknss.sim.planning.hybrid_astar import (
    HybridAStar,
    PlanningConfig,
    load_planning_config,
)
from parknss.sim.scenarios import Obstacle, Scene, grid_scene
from parknss.vehicle import VehicleGeometry, min_turning_radius

G = VehicleGeometry()
CFG = PlanningConfig(time_budget_s=30.0)  # correctness here; speed is benchmarks/bench_plan.py
PLANNER = HybridAStar(CFG, G)


def _wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def _check_plan(scene, result):
    assert result.found, (scene.meta.name, result.reason, result.detail)
    traj = result.trajectory
    segs = traj.segments
    assert segs, "a plan between distinct poses has segments"
    first, last = segs[0].poses[0], segs[-1].poses[-1]
    assert np.allclose(first[:2], scene.start[:2], atol=1e-9)
    assert abs(_wrap(first[2] - scene.start[2])) < 1e-9
    assert np.allclose(last[:2], scene.goal[:2], atol=1e-6)
    assert abs(_wrap(last[2] - scene.goal[2])) < 1e-6  # the goal up to whole turns
    headings = traj.poses()[:, 2]
    assert np.abs(np.diff(headings)).max() < 0.1  # one continuous (unwrapped) heading
    kmax = 1.0 / min_turning_radius(G)
    for a, b in itertools.pairwise(segs):
        assert a.direction == -b.direction  # segments split exactly at cusps
        np.testing.assert_allclose(a.poses[-1], b.poses[0], atol=1e-9)
    for seg in segs:
        d = np.diff(seg.poses[:, :2], axis=0)
        step = np.hypot(d[:, 0], d[:, 1])
        moving = step > 1e-6
        heading = seg.poses[:-1, 2]
        along = d[:, 0] * np.cos(heading) + d[:, 1] * np.sin(heading)
        # every move goes the segment's way, at a curvature the steering can reach
        assert np.all(np.sign(along[moving]) == seg.direction)
        dth = np.abs(_wrap(np.diff(seg.poses[:, 2])))
        arc = step / np.sinc(0.5 * dth / np.pi)  # arc length of the chord's circle
        assert np.all(dth[moving] / arc[moving] <= kmax * (1 + 1e-9))
    # the exact dense check, independently of the planner's own verification
    obstacles = scene.obstacle_arrays()
    worst = math.inf
    for seg in segs:
        dense = g.densify(seg.poses, 0.02, math.radians(0.5))
        assert np.all(g.inside_bounds(dense, G, scene.bounds))
        worst = min(worst, float(g.clearance(dense, G, obstacles).min()))
    assert worst >= CFG.safety_margin_m - 1e-9
    assert abs(worst - result.min_clearance_m) < 1e-6
    assert traj.cusps == len(segs) - 1
    assert result.stats.time_s < CFG.time_budget_s + 0.5


@pytest.mark.parametrize("cell", [14, 2, 28, 4])
def test_grid_cells_plan_cleanly(cell):
    # 14 perpendicular, 2 parallel 1.35 L, 28 angled tight, 4 parallel 1.2 car lengths
    scene = grid_scene(cell)
    _check_plan(scene, PLANNER.plan(scene))


@pytest.mark.parametrize("search", ["from_start", "from_goal"])
def test_single_tree_modes(search):
    scene = grid_scene(34)
    planner = HybridAStar(PlanningConfig(search=search, start_lead_ins_m=(), time_budget_s=30.0), G)
    _check_plan(scene, planner.plan(scene))


def _box(cx, cy, length, width, angle=0.0, kind="box"):
    return Obstacle(kind, g.convex_polygon(g.rectangle(cx, cy, length, width, angle)))


def test_goal_inside_an_obstacle():
    scene = grid_scene(14)
    gx, gy, _ = scene.goal
    blocked = replace(scene, obstacles=(*scene.obstacles, _box(gx, gy, 1.0, 1.0)))
    res = PLANNER.plan(blocked)
    assert not res.found and res.reason == "goal in collision" and res.trajectory is None


def test_start_in_collision():
    scene = grid_scene(14)
    sx, sy, _ = scene.start
    blocked = replace(scene, obstacles=(*scene.obstacles, _box(sx + 3.0, sy + 1.0, 0.5, 0.5)))
    res = PLANNER.plan(blocked)
    assert not res.found and res.reason == "start in collision"


def test_goal_off_the_map():
    scene = grid_scene(14)
    res = PLANNER.plan(replace(scene, goal=(scene.bounds[2] - 1.0, 0.0, 0.0)))
    assert not res.found and res.reason == "goal off the map"


def test_unreachable_goal_is_detected_without_searching():
    scene = grid_scene(14)
    _, ymin, _, ymax = scene.bounds
    wall = Obstacle("wall", g.convex_polygon([[-4, ymin], [-3.8, ymin], [-3.8, ymax], [-4, ymax]]))
    t0 = time.perf_counter()
    res = PLANNER.plan(replace(scene, obstacles=(*scene.obstacles, wall)))
    assert not res.found and res.reason == "goal unreachable"
    assert res.stats.expansions == 0 and time.perf_counter() - t0 < 1.0


def test_kinematically_impossible_goal_ends_within_the_budget():
    # a 2.6 m corridor: the rear axle can reach the goal, but the car cannot turn around
    scene = Scene((-8.0, -1.3, 8.0, 1.3), (), (-5.0, 0.0, 0.0), (4.0, 0.0, math.pi))
    planner = HybridAStar(PlanningConfig(time_budget_s=0.8), G)
    t0 = time.perf_counter()
    res = planner.plan(scene)
    elapsed = time.perf_counter() - t0
    assert not res.found
    assert res.reason in (
        "time budget exhausted", "expansion budget exhausted", "search space exhausted"
    )
    assert elapsed < 0.8 + 0.5


def test_the_search_budget_is_a_count_of_expansions():
    """The budget that decides a plan is node expansions, not time: one expansion short
    of the plan's count ends without it, exactly the count finds the same plan, whatever
    the wall-clock guard (so a grid plans the same on any machine, under any load)."""
    scene = grid_scene(3)  # a parallel slot: some tens of expansions
    full = PLANNER.plan(scene)
    n = full.stats.expansions
    assert full.found and n > 5
    once = {"retry_weights": ()}  # no second search at a greedier weight
    short = HybridAStar(PlanningConfig(max_expansions=n - 1, time_budget_s=30.0, **once), G)
    short = short.plan(scene)
    assert not short.found and short.reason == "expansion budget exhausted"
    assert short.stats.expansions == n - 1 and short.stats.attempts == 1
    exact = HybridAStar(PlanningConfig(max_expansions=n, time_budget_s=300.0), G).plan(scene)
    assert exact.found and exact.stats.expansions == n
    for a, b in zip(exact.trajectory.segments, full.trajectory.segments, strict=True):
        np.testing.assert_array_equal(a.poses, b.poses)


def test_start_equals_goal_is_an_empty_plan():
    scene = grid_scene(14)
    res = PLANNER.plan(replace(scene, start=scene.goal))
    assert res.found and res.trajectory.length == 0.0 and res.trajectory.cusps == 0


def test_planning_config_file_and_errors(tmp_path):
    assert load_planning_config() == PlanningConfig()
    bad = tmp_path / "p.yaml"
    bad.write_text("safety_margin: 0.2\n")
    with pytest.raises(ConfigError, match="safety_margin"):
        load_planning_config(bad)
    bad.write_text("search: sideways\n")
    with pytest.raises(ConfigError, match="search"):
        load_planning_config(bad)


def test_tie_keys_equal_within_noise_and_order_otherwise():
    """Costs equal up to a moved scene's last bits share a key (the search then takes
    them in insertion order, the same in every frame); different costs keep their order."""
    from parknss.sim.planning.hybrid_astar import tie_key

    q = PlanningConfig().tie_quantum
    assert q > 0
    a = 0.1 + 0.2  # 0.30000000000000004
    assert a != 0.3 and tie_key(a, q) == tie_key(0.3, q)
    assert tie_key(17.7 * (1 + 1e-15), q) == tie_key(17.7, q)
    assert tie_key(17.7, q) < tie_key(17.7 + 10 * q, q)
    assert tie_key(1.5, 0.0) == 1.5  # 0: raw floats
