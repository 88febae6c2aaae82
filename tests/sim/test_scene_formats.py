"""Benchmark scene formats (issue 17): TPCAP case CSVs (read in place from
../shared/planning/tpcap) and a hand-written CommonRoad XML fixture."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from helpers.paths import TESTS, TPCAP
from parknss.errors import PlanningError
from parknss.sim.obstacles import SceneImportConfig
from parknss.sim.scenarios import Scene
from parknss.sim.scene_formats import load_scene, read_commonroad, read_tpcap
from parknss.vehicle import VehicleGeometry

XML = TESTS / "sim" / "fixtures" / "commonroad_parking.xml"
needs_tpcap = pytest.mark.skipif(not TPCAP.is_dir(), reason="../shared/planning/tpcap missing")


@needs_tpcap
def test_all_twenty_tpcap_cases_load():
    for i in range(1, 21):
        scene = read_tpcap(TPCAP / f"Case{i}.csv")
        raw = np.array([float(t) for t in (TPCAP / f"Case{i}.csv").read_text().split(",")])
        assert len(scene.obstacles) == int(raw[6])
        assert scene.meta.name == f"tpcap-case{i}"
        for ob in scene.obstacles:
            assert all(len(p) >= 3 for p in ob.convex_parts())
        # the map is the start/goal box widened by 8 m (the source's convention), drawn in
        # the goal's frame: each side 8 m beyond the nearer of start and goal
        A, b = scene.map_planes()
        poses = np.array([scene.start[:2], scene.goal[:2]])
        np.testing.assert_allclose((b[None, :] - poses @ A.T).min(axis=0), 8.0, atol=1e-9)
        corners = np.asarray(scene.map_outline)
        assert scene.bounds == pytest.approx((*corners.min(axis=0), *corners.max(axis=0)))


@needs_tpcap
@pytest.mark.parametrize("case", [13, 14, 15])
def test_far_tpcap_cases_are_shifted_to_a_local_frame(case):
    """Cases 13-15 lie near 4e9 m: a local frame, its origin in meta; same geometry."""
    raw = np.array([float(t) for t in (TPCAP / f"Case{case}.csv").read_text().split(",")])
    scene = read_tpcap(TPCAP / f"Case{case}.csv")
    ox, oy = scene.meta.origin_m
    assert abs(ox) > 1e6 and max(abs(v) for v in scene.bounds) < 1e3
    assert scene.start[0] + ox == pytest.approx(raw[0], abs=1e-6)
    assert scene.goal[1] + oy == pytest.approx(raw[4], abs=1e-6)
    round_trip = Scene.from_json(scene.to_json())
    assert len(round_trip.obstacle_arrays()) == len(scene.obstacle_arrays())


def test_a_hand_written_tpcap_case_with_a_non_convex_obstacle_and_a_line(tmp_path):
    nums = [
        0,
        0,
        0,
        10,
        0,
        0,
        2,
        6,
        2,
        3,
        3,
        7,
        3,
        7,
        4,
        4,
        4,
        4,
        6,
        3,
        6,  # an L (6 vertices)
        3,
        -3,
        7,
        -3,
    ]  # a wall drawn as a line (2 vertices)
    path = tmp_path / "Case99.csv"
    path.write_text(",".join(str(v) for v in nums))
    scene = read_tpcap(path)
    assert len(scene.obstacles[0].convex_parts()) == 2
    assert "wall" in scene.notes[-1]
    assert scene.bounds == (-8.0, -8.0, 18.0, 8.0)
    path.write_text("1,2,3")
    with pytest.raises(PlanningError, match="not a TPCAP case"):
        read_tpcap(path)
    path.write_text(",".join(str(v) for v in nums[:-1]))
    with pytest.raises(PlanningError, match="expected 25 numbers"):
        read_tpcap(path)


def test_commonroad_static_obstacles_and_planning_problem():
    geom = VehicleGeometry()
    scene = read_commonroad(XML, geom)
    kinds = [o.kind for o in scene.obstacles]
    assert kinds == ["parkedVehicle", "parkedVehicle", "pillar"]
    car = Polygon(scene.obstacles[0].vertices)  # rotated by its state: 1.9 wide in x
    assert car.bounds == pytest.approx((-3.95, -5.3, -2.05, -0.5), abs=1e-6)
    pillar = Polygon(scene.obstacles[2].vertices)
    assert pillar.contains(Point(8.0, -1.0).buffer(0.2999, 64))  # the polygon holds the circle
    assert len(scene.obstacles[2].vertices) == SceneImportConfig().circle_segments
    # CommonRoad places the car by its centre; the scene by the rear axle
    back = 0.5 * geom.length - geom.rear_overhang
    assert scene.start == pytest.approx((-8.0 - back, 3.0, 0.0))
    assert scene.goal[:2] == pytest.approx((0.0, -2.9 - back), abs=1e-6)
    assert scene.goal[2] == pytest.approx(math.pi / 2, abs=1e-3)
    assert scene.meta.name == "commonroad-commonroad_parking-100"  # file and problem
    walls = read_commonroad(XML, geom, SceneImportConfig(commonroad_lanelet_walls=True))
    assert len(walls.obstacles) == 5 and walls.obstacles[-1].kind == "lanelet bound"


def test_commonroad_refusals(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text("<commonRoad><planningProblem id='1'/></commonRoad>")
    with pytest.raises(PlanningError, match="initialState"):
        read_commonroad(bad)
    bad.write_text("<scenario/>")
    with pytest.raises(PlanningError, match="not <commonRoad>"):
        read_commonroad(bad)
    bad.write_text("<commonRoad")
    with pytest.raises(PlanningError, match="not valid XML"):
        read_commonroad(bad)


def test_load_scene_takes_every_kind_of_scene_spec(tmp_path):
    assert load_scene(str(XML)).meta.name.startswith("commonroad-")
    assert load_scene("7").meta.cell == 7
    small = VehicleGeometry(length=4.5, width=1.8, rear_overhang=0.9, wheelbase=2.7)
    big_slot = load_scene("0").meta.slot_size_m
    assert load_scene("0", geom=small).meta.slot_size_m == pytest.approx(big_slot * 4.5 / 4.95)


_CR = """<commonRoad benchmarkID="ZAM_Hand-1_1_T-1">
  <lanelet id="7">
    <leftBound><point><x>0</x><y>13</y></point><point><x>20</x><y>13</y></point></leftBound>
    <rightBound><point><x>0</x><y>10</y></point><point><x>20</x><y>10</y></point></rightBound>
  </lanelet>
  <planningProblem id="1">
    <initialState><position><point><x>2</x><y>5</y></point></position>
      <orientation><exact>0</exact></orientation></initialState>
    <goalState><position><polygon>
      <point><x>10</x><y>0</y></point><point><x>14</x><y>0</y></point>
      <point><x>14</x><y>1</y></point><point><x>11</x><y>1</y></point>
      <point><x>11</x><y>3</y></point><point><x>10</x><y>3</y></point>
      <point><x>10</x><y>0</y></point></polygon></position>
      <orientation><exact>0.5</exact></orientation></goalState>
  </planningProblem>
  <planningProblem id="2">
    <initialState><position><point><x>2</x><y>5</y></point></position>
      <orientation><exact>0</exact></orientation></initialState>
    <goalState><position><lanelet ref="7"/></position></goalState>
  </planningProblem>
</commonRoad>"""


def test_commonroad_goals_by_area_centroid_lanelet_and_problem(tmp_path):
    """A closed L-shaped polygon goal (first point repeated; area 4 + 2 m², centroid
    ((4·12 + 2·10.5) / 6, (4·0.5 + 2·2) / 6) = (11.5, 1.0), where the vertex mean is
    (11.43, 1.14)); planning problem 2 with a lanelet goal: the 20 m x 3 m lane's centroid
    (10, 11.5), heading along its centre line (0 rad)."""
    path = tmp_path / "hand.xml"
    path.write_text(_CR)
    geom = VehicleGeometry()
    back = 0.5 * geom.length - geom.rear_overhang  # goal is the car's centre; scene: rear axle
    one = read_commonroad(path, geom)
    gx, gy, gth = one.goal
    assert gth == pytest.approx(0.5)
    assert gx + back * math.cos(0.5) == pytest.approx(11.5, abs=1e-9)
    assert gy + back * math.sin(0.5) == pytest.approx(1.0, abs=1e-9)
    two = load_scene(f"{path}#2", None, geom)
    assert two.goal[2] == pytest.approx(0.0, abs=1e-12)
    assert two.goal[0] + back == pytest.approx(10.0, abs=1e-9)
    assert two.goal[1] == pytest.approx(11.5, abs=1e-9)
    assert two.start == one.start
    with pytest.raises(PlanningError, match=r"no planning problem '3' \(the file has: 1, 2\)"):
        read_commonroad(path, geom, problem_id="3")
