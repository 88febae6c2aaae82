"""The search's fast collision check against exact polygon geometry."""

import math

import numpy as np

from parknss.sim import geometry as g
from parknss.sim.planning.collision_field import FieldChecker
from parknss.sim.planning.reeds_shepp import arc_poses
from parknss.sim.scenarios import grid_scene
from parknss.vehicle import VehicleGeometry

G = VehicleGeometry()


def _scene_checker(cell, margin=0.1):
    scene = grid_scene(cell)
    obstacles = scene.obstacle_arrays()
    return scene, obstacles, FieldChecker(obstacles, scene.bounds, G, margin)


def test_field_clearance_matches_exact_geometry_near_obstacles():
    for cell in (5, 17, 29):
        scene, obstacles, ch = _scene_checker(cell)
        rng = np.random.default_rng(cell)
        gx, gy, _ = scene.goal
        poses = np.column_stack(
            [
                gx + rng.uniform(-3, 3, 600),
                gy + rng.uniform(-1.5, 3, 600),
                scene.goal[2] + rng.uniform(-0.6, 0.6, 600),
            ]
        )
        inside = g.inside_bounds(poses, G, scene.bounds)
        exact = g.clearance(poses, G, obstacles)
        est = ch.clearance(poses)
        assert np.all(est[~inside] == -1.0)
        m = inside & (exact < ch.field.cap - 0.05)
        assert m.sum() > 100
        # never optimistic beyond the interpolation tolerance, and close everywhere
        assert np.max(est[m] - exact[m]) < 0.01
        assert np.max(np.abs(est[m] - exact[m])) < 0.01
        # the search's accept decision is sound: nothing accepted that violates the margin
        assert not np.any(ch.free(poses) & (exact < 0.1))


def test_crossing_obstacle_without_vertex_containment_is_caught():
    # a thin wall crossing the car's middle: no wall vertex inside the car, no car corner
    # inside the wall; only the edge/axis samples can see it
    wall = g.convex_polygon([[1.0, -5.0], [1.2, -5.0], [1.2, 5.0], [1.0, 5.0]])
    ch = FieldChecker([wall], (-10.0, -10.0, 10.0, 10.0), G, 0.1)
    pose = np.array([[0.0, 0.0, 0.0]])
    assert g.intersects(g.footprints(pose, G), wall)[0]
    assert not ch.free(pose)[0]
    assert ch.clearance(pose)[0] < 0.1


def test_reach_along_stops_before_contact_and_certifies_free_paths():
    scene, obstacles, ch = _scene_checker(5)
    lip = ch.lipschitz(1 / 4.6)
    # drive straight forward from the goal (in the tight slot) toward the front neighbour
    s = np.arange(0.0, 1.21, 0.1)
    path = arc_poses(scene.goal, 0.0, s)
    r = float(ch.reach_along([path], np.array([lip]))[0])
    stop = arc_poses(scene.goal, 0.0, [r * 0.1])
    exact_at_stop = g.clearance(stop, G, obstacles)[0]
    assert 0.0 < r < len(s) - 1
    assert exact_at_stop >= 0.1
    assert exact_at_stop < 0.1 + 0.05  # cut back to within the dense spacing of contact
    # every dense pose before the stop clears the margin
    dense = g.densify(arc_poses(scene.goal, 0.0, np.linspace(0, r * 0.1, 20)), 0.02)
    assert g.clearance(dense, G, obstacles).min() >= 0.1
    # a path in the open lane is certified whole
    lane = arc_poses((-5.0, 1.5, 0.0), 0.0, s)
    assert ch.path_ok(lane, lip)


def test_lipschitz_bound_holds_for_body_points():
    ch = FieldChecker([], (-50, -50, 50, 50), G, 0.1)
    k = 1 / 4.6
    lip = ch.lipschitz(k)
    poses = arc_poses((0.0, 0.0, 0.3), k, np.linspace(0, 2.0, 201))
    corners = g.footprints(poses, G)
    speed = np.hypot(*np.diff(corners, axis=0).transpose(2, 0, 1)) / 0.01
    assert speed.max() <= lip + 1e-6
    assert speed.max() > lip - 0.01  # tight
    assert abs(ch.lipschitz(0.0) - 1.0) < 1e-12
    assert math.isclose(lip, ch.lipschitz(-k))
