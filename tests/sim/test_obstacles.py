"""Obstacles as drawn (issue 17): convex parts checked against shapely, walls, the
normalisation of degenerate vertices (counted), one-line refusals, caps, local frame."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import LineString, Polygon
from shapely.ops import unary_union

from parknss.errors import PlanningError
from parknss.sim import geometry as g
from parknss.sim.obstacles import ObstacleInputConfig, clean_vertices, drawn_obstacle
from parknss.sim.scenarios import Scene

L_SHAPE = [[0, 0], [4, 0], [4, 1], [1, 1], [1, 3], [0, 3]]


def _star(rng: np.random.Generator, n: int) -> np.ndarray:
    """A random simple star-shaped polygon (n vertices around the origin, CCW)."""
    ang = np.sort(rng.uniform(0, 2 * math.pi, n))
    r = rng.uniform(0.5, 3.0, n)
    return np.column_stack([r * np.cos(ang), r * np.sin(ang)])


def _convex(p: np.ndarray) -> bool:
    e = np.roll(p, -1, axis=0) - p
    cross = e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1)
    return bool(np.all(cross >= -1e-9))


def test_parts_are_convex_and_tile_the_polygon_exactly():
    rng = np.random.default_rng(17)
    for _ in range(40):
        poly = _star(rng, int(rng.integers(5, 14)))
        if not Polygon(poly).is_valid:
            continue
        out = drawn_obstacle(poly)
        shapes = [Polygon(p) for p in out.parts]
        assert all(_convex(p) for p in out.parts)
        union = unary_union(shapes)
        ref = Polygon(poly)
        assert union.symmetric_difference(ref).area < 1e-9 * ref.area
        assert sum(s.area for s in shapes) == pytest.approx(ref.area, rel=1e-9)  # no overlap
        # the exact distance to the outline is the minimum over the parts
        pts = rng.uniform(-5, 5, (20, 2))
        d_parts = np.min([g.point_distance(pts, p) for p in out.parts], axis=0)
        d_ref = np.array([ref.distance(__import__("shapely").Point(q)) for q in pts])
        np.testing.assert_allclose(d_parts, d_ref, atol=1e-9)


def test_l_shape_splits_in_two_and_convex_stays_bit_for_bit():
    out = drawn_obstacle(L_SHAPE)
    assert len(out.parts) == 2 and not out.wall and out.removed == 0
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    same = drawn_obstacle(square)
    assert len(same.parts) == 1 and np.array_equal(same.parts[0], square)


def test_lines_and_zero_area_polygons_become_walls_of_the_configured_thickness():
    cfg = ObstacleInputConfig(wall_thickness_m=0.2)
    wall = drawn_obstacle([[0, 0], [5, 0]], "w", "polyline", cfg)
    assert wall.wall and Polygon(wall.vertices).area == pytest.approx(5.2 * 0.2)
    bent = drawn_obstacle([[0, 0], [5, 0], [5, 4]], "w", "polyline", cfg)
    ref = LineString([[0, 0], [5, 0], [5, 4]]).buffer(0.1, cap_style="square", join_style="mitre")
    assert unary_union([Polygon(p) for p in bent.parts]).symmetric_difference(ref).area < 1e-9
    flat = drawn_obstacle([[0, 0], [1, 1], [2, 2]], "sliver", "polygon", cfg)
    assert flat.wall and flat.removed == 1


def test_duplicate_and_collinear_vertices_are_removed_and_counted():
    v = np.array([[0, 0], [1, 0], [1, 0], [2, 0], [2, 2], [0, 2], [0, 1]], dtype=float)
    kept, removed = clean_vertices(v, 1e-6, closed=True)
    assert removed == 3 and len(kept) == 4
    scene = Scene.from_json(
        {
            "bounds": [-5, -5, 5, 5],
            "start": [-3, 3, 0],
            "goal": [3, 3, 0],
            "obstacles": [{"kind": "box", "vertices": v.tolist()}],
        }
    )
    assert "3 duplicate/collinear vertices removed" in scene.notes[0]
    assert len(scene.obstacles[0].vertices) == 4


@pytest.mark.parametrize(
    ("vertices", "extra", "message"),
    [
        ([[0, 0], [2, 2], [2, 0], [0, 2]], {}, "not simple"),
        ([[0, 0], [1, 0], [math.nan, 1]], {}, "finite"),
        (L_SHAPE, {"holes": [[[0.2, 0.2], [0.4, 0.2], [0.4, 0.4]]]}, "holes"),
        (L_SHAPE, {"shape": "circle"}, "shape must be"),
        ([[0, 0], [0, 0], [0, 0]], {}, "2 distinct vertices"),
    ],
)
def test_bad_obstacles_are_refused_with_one_line(vertices, extra, message):
    doc = {
        "bounds": [-5, -5, 5, 5],
        "start": [-3, 3, 0],
        "goal": [3, 3, 0],
        "obstacles": [{"vertices": vertices, **extra}],
    }
    with pytest.raises(PlanningError, match=message) as err:
        Scene.from_json(doc)
    assert "\n" not in str(err.value)


def test_caps_refuse_huge_scenes_at_once():
    cfg = ObstacleInputConfig(max_obstacles=10, max_vertices_total=30)
    box = [[0, 0], [0.1, 0], [0.1, 0.1], [0, 0.1]]
    doc = {
        "bounds": [-5, -5, 5, 5],
        "start": [-3, 3, 0],
        "goal": [3, 3, 0],
        "obstacles": [{"vertices": box}] * 100_000,
    }
    with pytest.raises(PlanningError, match="more than max_obstacles"):
        Scene.from_json(doc, cfg=cfg)
    doc["obstacles"] = [{"vertices": box}] * 9
    with pytest.raises(PlanningError, match="max_vertices_total"):
        Scene.from_json(doc, cfg=cfg)
    with pytest.raises(PlanningError, match="max_vertices_per_obstacle"):
        drawn_obstacle(
            _star(np.random.default_rng(0), 50),
            cfg=ObstacleInputConfig(max_vertices_per_obstacle=20),
        )


@pytest.mark.parametrize("offset", [0.0, 4.0e9])
def test_far_coordinates_are_judged_in_a_local_frame(offset):
    """Issue 17: TPCAP 13-15 lie near 4e9 m; area and convexity used absolute coordinates
    and called valid polygons 'no area' / 'not convex'."""
    box = np.array([[0.0, 0.0], [0.3, 0.0], [0.3, 0.2], [0.0, 0.2]]) + offset
    np.testing.assert_array_equal(g.convex_polygon(box), box)
    out = drawn_obstacle(np.array(L_SHAPE, float) * 0.1 + offset)
    assert len(out.parts) == 2 and not out.wall
    assert sum(Polygon(p - offset).area for p in out.parts) == pytest.approx(0.06, rel=1e-6)
