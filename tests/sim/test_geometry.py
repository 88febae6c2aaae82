"""Exact footprint geometry against shapely (an independent implementation)."""

import math

import numpy as np
import pytest
from shapely.geometry import MultiPoint, Point, Polygon

from parknss.errors import PlanningError
from parknss.sim import geometry as g
from parknss.sim.planning.reeds_shepp import arc_poses
from parknss.vehicle import VehicleGeometry, arc_step

G = VehicleGeometry()


def _random_convex(rng, centre_span=5.0):
    pts = rng.normal(size=(int(rng.integers(3, 10)), 2)) * rng.uniform(0.2, 2.5)
    hull = MultiPoint([tuple(p) for p in pts + rng.uniform(-centre_span, centre_span, 2)])
    return np.array(hull.convex_hull.exterior.coords)[:-1]


def _random_poses(rng, n, span=6.0):
    return np.column_stack(
        [
            rng.uniform(-span, span, n),
            rng.uniform(-span, span, n),
            rng.uniform(-math.pi, math.pi, n),
        ]
    )


def test_footprint_matches_the_vehicle_rectangle():
    fp = g.footprint((2.0, -1.0, 0.7), G)
    poly = Polygon(fp)
    assert poly.is_valid and poly.exterior.is_ccw
    assert abs(poly.area - G.length * G.width) < 1e-9
    # the rear axle lies rear_overhang ahead of the rear edge, on the centre line
    rear_mid = 0.5 * (fp[0] + fp[3])
    assert abs(np.hypot(*(rear_mid - [2.0, -1.0])) - G.rear_overhang) < 1e-12
    grown = Polygon(g.footprint((2.0, -1.0, 0.7), G, margin=0.1))
    assert abs(grown.area - (G.length + 0.2) * (G.width + 0.2)) < 1e-9


def test_intersection_and_distance_agree_with_shapely():
    rng = np.random.default_rng(0)
    poses = _random_poses(rng, 120)
    fps = g.footprints(poses, G)
    worst, mismatches, touching = 0.0, 0, 0
    for _ in range(25):
        ob = g.convex_polygon(_random_convex(rng), "obstacle")
        d = g.distance(fps, ob)
        hit = g.intersects(fps, ob)
        ref_poly = Polygon(ob)
        for i in range(len(poses)):
            fp = Polygon(fps[i])
            worst = max(worst, abs(fp.distance(ref_poly) - d[i]))
            mismatches += fp.intersects(ref_poly) != hit[i]
            touching += hit[i]
    assert worst < 1e-9
    assert mismatches == 0
    assert 0 < touching < 120 * 25  # both outcomes exercised


def test_point_distance_and_clearance_agree_with_shapely():
    rng = np.random.default_rng(1)
    obstacles = [g.convex_polygon(_random_convex(rng, 8.0), "o") for _ in range(6)]
    pts = rng.uniform(-9, 9, (400, 2))
    for ob in obstacles:
        ref = np.array([Polygon(ob).distance(Point(p)) for p in pts])
        np.testing.assert_allclose(g.point_distance(pts, ob), ref, atol=1e-9)
    poses = _random_poses(rng, 200, 9.0)
    clr = g.clearance(poses, G, obstacles)
    ref = np.array(
        [min(Polygon(f).distance(Polygon(o)) for o in obstacles) for f in g.footprints(poses, G)]
    )
    np.testing.assert_allclose(clr, ref, atol=1e-9)
    # with a cutoff, every value below it is exact and none is above the truth
    cut = g.clearance(poses, G, obstacles, cutoff=0.5)
    below = ref < 0.5
    np.testing.assert_allclose(cut[below], ref[below], atol=1e-9)
    assert np.all(cut <= ref + 1e-9)
    # margins
    assert np.array_equal(g.collides(poses, G, obstacles, margin=0.3), ref < 0.3)
    assert np.array_equal(g.collides(poses, G, obstacles), ref <= 1e-12)


def test_convex_polygon_validation():
    square = [[0, 0], [1, 0], [1, 1], [0, 1]]
    ccw = g.convex_polygon(square)
    cw = g.convex_polygon(square[::-1])
    assert Polygon(cw).exterior.is_ccw and Polygon(ccw).exterior.is_ccw
    with pytest.raises(PlanningError, match="not convex"):
        g.convex_polygon([[0, 0], [2, 0], [1, 0.5], [2, 2], [0, 2]], "dart")
    with pytest.raises(PlanningError, match="no area"):
        g.convex_polygon([[0, 0], [1, 1], [2, 2]])
    with pytest.raises(PlanningError, match="at least 3"):
        g.convex_polygon([[0, 0], [1, 1]])
    with pytest.raises(PlanningError, match="finite"):
        g.convex_polygon([[0, 0], [1, 0], [np.nan, 1]])


def test_densify_spacing_and_exactness_on_arcs():
    kappa = 1 / 4.6
    coarse = arc_poses((1.0, 2.0, 0.4), kappa, np.linspace(0.0, -3.0, 7))  # reverse arc
    dense = g.densify(coarse, 0.02, math.radians(0.5))
    steps = np.hypot(*np.diff(dense[:, :2], axis=0).T)
    assert steps.max() <= 0.02 + 1e-12
    assert np.abs(np.diff(dense[:, 2])).max() <= math.radians(0.5) + 1e-12
    # every inserted pose lies on the arc: compare with the analytic arc at the same heading
    s = (dense[:, 2] - 0.4) / kappa
    exact = arc_poses((1.0, 2.0, 0.4), kappa, s)
    np.testing.assert_allclose(dense[:, :3], exact, atol=1e-12)
    # the original poses are kept, in order
    assert all(np.any(np.all(np.isclose(dense[:, :3], p), axis=1)) for p in coarse)


def test_dense_clearance_finds_the_corner_between_samples():
    # a post just outside the sweep of the outer front corner, midway between two samples
    kappa = 1 / 4.6
    sparse_poses = arc_poses((0.0, 0.0, 0.0), kappa, np.linspace(0.0, 3.0, 3))  # 1.5 m apart
    mid = arc_poses((0.0, 0.0, 0.0), kappa, [0.75])[0]
    corner = g.footprint(mid, G)[1]  # front-right corner, the outer one in a left turn
    outward = corner - (0.0, 4.6)  # from the turning centre
    c = corner + 0.15 * outward / np.hypot(*outward)
    post = g.convex_polygon(g.rectangle(c[0], c[1], 0.04, 0.04, math.atan2(*outward[::-1])))
    sparse = g.clearance(sparse_poses, G, [post]).min()
    dense_min, _ = g.dense_clearance(sparse_poses, G, [post])
    truth = g.clearance(arc_poses((0.0, 0.0, 0.0), kappa, np.linspace(0, 3, 30001)), G, [post])
    assert sparse > truth.min() + 0.1  # the sparse check misses the pass
    assert abs(dense_min - truth.min()) < 2e-3  # 2 cm steps resolve it
    assert dense_min >= truth.min() - 1e-12


def test_inside_bounds():
    bounds = (-10.0, -5.0, 10.0, 5.0)
    assert g.inside_bounds([(0, 0, 0)], G, bounds)[0]
    assert not g.inside_bounds([(7.0, 0, 0)], G, bounds)[0]  # front bumper at 10.95
    assert g.inside_bounds([(5.9, 0, 0)], G, bounds)[0]


def test_arc_interpolation_lies_on_the_arc_step():
    """geometry.arc_interpolate (the arc through two poses) against vehicle.arc_step (the
    arc from a pose and a curvature), forward and reverse, straight and curved."""
    rng = np.random.default_rng(1)
    n = 300
    p0 = np.column_stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.uniform(-3, 3, n)])
    kappa = np.where(rng.random(n) < 0.2, 0.0, rng.uniform(-0.22, 0.22, n))
    s = rng.uniform(-2.0, 2.0, n)  # signed travel: reverse pairs too
    p1 = np.column_stack(arc_step(p0[:, 0], p0[:, 1], p0[:, 2], s, kappa * s))
    tau = rng.uniform(0.0, 1.0, n)
    want = np.column_stack(arc_step(p0[:, 0], p0[:, 1], p0[:, 2], tau * s, tau * kappa * s))
    np.testing.assert_allclose(g.arc_interpolate(p0, p1, tau), want, atol=1e-12)


def test_collision_broad_phase_changes_nothing():
    """geometry.collides (bounding-circle broad phase, then SAT) equals SAT on every pair,
    also for poses grazing an obstacle."""
    rng = np.random.default_rng(2)
    geom = VehicleGeometry()
    obstacles = [g.rectangle(x, y, 4.9, 1.9, a) for x, y, a in rng.uniform(-6, 6, (6, 3))]
    poses = np.column_stack(
        [rng.uniform(-9, 9, 3000), rng.uniform(-9, 9, 3000), rng.uniform(-3.2, 3.2, 3000)]
    )
    fp = g.footprints(poses, geom)
    brute = np.zeros(len(poses), dtype=bool)
    for obs in obstacles:
        brute |= g.intersects(fp, obs)
    assert 100 < brute.sum() < len(poses) - 100
    np.testing.assert_array_equal(g.collides(poses, geom, obstacles), brute)
    cx, cy, r = g.body_circles(poses, geom)
    assert np.all(np.hypot(fp[..., 0] - cx[:, None], fp[..., 1] - cy[:, None]) <= r + 1e-9)
