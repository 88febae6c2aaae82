"""The canonical frame: a rigid motion of the whole scene moves the plan with it."""

import math
from dataclasses import replace

import numpy as np
import pytest

from parknss.sim.planning.frame import CanonicalFrame, CanonicalScene, move_scene
from parknss.sim.planning.hybrid_astar import HybridAStar, PlanningConfig
from parknss.sim.scenarios import Scene, grid_scene
from parknss.vehicle import VehicleGeometry

G = VehicleGeometry()
PLANNER = HybridAStar(PlanningConfig(time_budget_s=30.0, canonical_frame=True), G)


def moved(scene: Scene, angle: float, shift, mirror: bool) -> Scene:
    """``scene`` mirrored in y (first, when ``mirror``), rotated by ``angle`` rad about the
    origin and shifted; the map is the bounding box of the moved map (a world-axis box
    that changes size with the rotation, unlike the outline ``move_scene`` also keeps)."""
    return replace(move_scene(scene, angle, shift, mirror), map_outline=None)


def test_frame_round_trip_and_handedness():
    f = CanonicalFrame.of((3.0, -4.0, 1.0), (1.0, 2.0, 0.5))
    pts = np.array([[1.0, 2.0], [-7.5, 3.25]])
    back = f.to_world_xy(*f.to_canon_xy(pts).T)
    np.testing.assert_allclose(np.column_stack(back), pts, atol=1e-12)
    assert f.to_canon_xy(np.array([1.0, 2.0])) == pytest.approx([0.0, 0.0])
    assert f.to_canon_pose((3.0, -4.0, 1.0))[1] >= 0.0  # the start is on the left
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    q = f.to_canon_polygon(square)
    area = 0.5 * np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1])
    assert area == pytest.approx(1.0)  # still counter-clockwise


@pytest.mark.parametrize("cell", [2, 9])
def test_random_rigid_motions_give_the_same_plan(cell):
    base = grid_scene(cell)
    xmin, ymin, xmax, ymax = base.bounds
    base = replace(base, bounds=(xmin - 40.0, ymin - 40.0, xmax + 40.0, ymax + 40.0))
    ref = PLANNER.plan(base)
    rng = np.random.default_rng(cell)
    for mirror in (False, True, bool(rng.integers(2))):
        angle = float(rng.uniform(-math.pi, math.pi))
        shift = rng.uniform(-1e4, 1e4, size=2)
        scene = moved(base, angle, shift, mirror)
        res = PLANNER.plan(scene)
        assert res.found == ref.found, (mirror, angle, shift)
        if ref.found:
            assert res.trajectory.length == pytest.approx(ref.trajectory.length, abs=1e-6)
            assert res.trajectory.cusps == ref.trajectory.cusps
            # the plan moved with the scene
            expect = moved(
                replace(base, start=tuple(ref.trajectory.segments[-1].poses[-2])),
                angle, shift, mirror,
            ).start
            got = res.trajectory.segments[-1].poses[-2]
            np.testing.assert_allclose(got[:2], expect[:2], atol=1e-6)


def test_the_world_frame_option_is_the_identity():
    scene = grid_scene(3)
    canon = CanonicalScene.of(scene, canonical=False)
    assert canon.start == tuple(scene.start) and canon.goal == tuple(scene.goal)
    assert canon.bounds == tuple(scene.bounds)
    for a, b in zip(canon.obstacles, scene.obstacle_arrays(), strict=True):
        np.testing.assert_array_equal(a, b)
