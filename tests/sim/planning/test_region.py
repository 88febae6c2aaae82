"""The search region: grids sized by the problem, refused before allocation, grown on demand."""

import math
from dataclasses import replace

import numpy as np
import pytest

from parknss.errors import ParknssError
from parknss.sim.planning.hybrid_astar import HybridAStar, PlanningConfig, verify_trajectory
from parknss.sim.planning.region import (
    GridMemoryError,
    check_grid_memory,
    grid_memory_bytes,
    search_region,
)
from parknss.sim.scenarios import Obstacle, Scene, grid_scene
from parknss.vehicle import VehicleGeometry

G = VehicleGeometry()
CFG = PlanningConfig(time_budget_s=30.0)


def test_memory_estimate_grows_with_the_region_and_never_overflows():
    small = grid_memory_bytes((0.0, 0.0, 50.0, 50.0), 0.05, 0.25)
    big = grid_memory_bytes((0.0, 0.0, 100.0, 100.0), 0.05, 0.25)
    assert 3.5 < big / small < 4.5
    # 8 bytes a field node (1e6 nodes) + 320 bytes a heuristic cell (4e4 cells)
    assert small == pytest.approx(8 * 1005**2 + 320 * 200**2)
    assert grid_memory_bytes((-1e308, -1e308, 1e308, 1e308), 0.05, 0.25) == math.inf
    with pytest.raises(GridMemoryError, match=r"more than can be counted.*max_grid_memory_mb"):
        check_grid_memory((-1e308, 0.0, 1e308, 10.0), 0.05, 0.25, 800.0)
    with pytest.raises(ParknssError, match=r"1e\+06 m x 10 m search region need .* GiB"):
        check_grid_memory((0.0, 0.0, 1e6, 10.0), 0.05, 0.25, 800.0)
    assert check_grid_memory((0.0, 0.0, 50.0, 50.0), 0.05, 0.25, 800.0) == small


def _in_corner(scene: Scene, size: float, far: int = 0) -> Scene:
    """``scene`` in the corner of a size x size map, with ``far`` boxes beyond 60 m."""
    x0, y0 = scene.bounds[:2]
    rng = np.random.default_rng(0)
    boxes = [
        Obstacle("box", np.array([[x, y], [x + 5, y], [x + 5, y + 2], [x, y + 2]]))
        for x, y in rng.uniform(60.0, size - 20.0, size=(far, 2))
    ]
    return replace(
        scene, bounds=(x0, y0, x0 + size, y0 + size), obstacles=scene.obstacles + tuple(boxes)
    )


@pytest.mark.parametrize("size", [1000.0, 1e6, 1e308])
def test_a_corner_of_a_huge_map_plans_as_the_small_map(size):
    scene = grid_scene(2)
    ref = HybridAStar(CFG, G).plan(scene)
    res = HybridAStar(CFG, G).plan(_in_corner(scene, size, far=50 if size < 1e5 else 0))
    assert ref.found and res.found
    assert res.trajectory.length == pytest.approx(ref.trajectory.length, abs=1e-9)
    assert res.trajectory.cusps == ref.trajectory.cusps


def test_start_and_goal_far_apart_are_refused_in_one_line():
    scene = _in_corner(grid_scene(2), 1e308)
    far = replace(scene, goal=(1e300, 5.0, 0.0))
    with pytest.raises(GridMemoryError) as err:
        HybridAStar(CFG, G).plan(far)
    assert "\n" not in str(err.value)
    far = replace(_in_corner(grid_scene(2), 1e6), goal=(9e5, 5.0, 0.0))
    with pytest.raises(GridMemoryError, match="GiB"):
        HybridAStar(CFG, G).plan(far)


def test_the_region_covers_the_small_scenes_whole():
    for cell in (0, 17, 35):
        scene = grid_scene(cell)
        assert search_region(scene, CFG.region_margin_m) == scene.bounds


def test_the_region_grows_when_the_way_leads_outside_it():
    # a wall between start and goal; the only gap is 6-20 m above them
    wall = Obstacle("wall", np.array([[-0.5, -20.0], [0.5, -20.0], [0.5, 6.0], [-0.5, 6.0]]))
    scene = Scene((-20.0, -20.0, 20.0, 20.0), (wall,), (-8.0, 0.0, 0.0), (8.0, 0.0, 0.0))
    cfg = CFG.model_copy(update={"region_margin_m": 1.0, "max_expansions": 3000})
    res = HybridAStar(cfg, G).plan(scene)
    assert res.found, (res.reason, res.detail)
    assert res.trajectory.poses()[:, 1].max() > 6.0  # through the gap
    assert verify_trajectory(res.trajectory, scene, G, cfg)[0]


def test_an_unreachable_goal_on_a_huge_map_is_a_reason_not_an_error():
    # the goal boxed in: the region grows to the memory limit, then the search answers
    box = [
        Obstacle("wall", np.array(v, dtype=float))
        for v in (
            [[4.0, -4.0], [12.0, -4.0], [12.0, -3.5], [4.0, -3.5]],
            [[4.0, 3.5], [12.0, 3.5], [12.0, 4.0], [4.0, 4.0]],
            [[3.5, -4.0], [4.0, -4.0], [4.0, 4.0], [3.5, 4.0]],
            [[12.0, -4.0], [12.5, -4.0], [12.5, 4.0], [12.0, 4.0]],
        )
    ]
    scene = Scene((-1e6, -1e6, 1e6, 1e6), tuple(box), (-8.0, 0.0, 0.0), (7.0, 0.0, 0.0))
    res = HybridAStar(CFG, G).plan(scene)
    assert not res.found and res.reason == "goal unreachable"
    assert "max_grid_memory_mb" in res.detail
