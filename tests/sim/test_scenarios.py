"""Scenario grids: addressing, slot geometry, perturbations and the JSON scene format."""

import json
import math

import numpy as np
import pytest

from parknss.errors import ConfigError, PlanningError
from parknss.sim import geometry as g
from parknss.sim import scenarios as sc
from parknss.vehicle import VehicleGeometry

G = VehicleGeometry()
CFG = sc.ScenariosConfig()


def _cars(scene):
    return [o.vertices for o in scene.obstacles if o.kind == "car"]


def test_grid_addressing_is_a_bijection():
    cells = [sc.cell(i) for i in range(sc.N_CELLS)]
    combos = {(c.bay, c.approach, c.tier, c.barrier) for c in cells}
    assert len(combos) == 36
    for c in cells:
        assert sc.cell_index(c.bay, c.approach, c.tier, c.barrier) == c.index
    assert sc.cell(0) == sc.Cell(0, "parallel", "left", 0, False)
    assert sc.cell(35) == sc.Cell(35, "angled", "right", 2, True)
    for bad in (-1, 36, 1.5, "3"):
        with pytest.raises(PlanningError):
            sc.cell(bad)


def test_core_and_robustness_addressing():
    core = sc.core_cells()
    assert len(core) == 12 and all(sc.cell(i).tier == 1 for i in core)
    assert {(sc.cell(i).bay, sc.cell(i).approach, sc.cell(i).barrier) for i in core} == {
        (b, a, r) for b in sc.BAYS for a in sc.APPROACHES for r in (False, True)
    }
    addresses = {sc.robust_address(i) for i in range(sc.N_ROBUST)}
    assert len(addresses) == 252 == 36 * 7
    assert sc.robust_address(37) == (1, "skew_neg")
    with pytest.raises(PlanningError):
        sc.robust_address(252)


def test_every_grid_scene_is_well_formed():
    for i in range(sc.N_CELLS):
        s = sc.grid_scene(i)
        assert s.meta.cell == i and s.meta.perturbation == "nominal"
        obstacles = s.obstacle_arrays()
        for pose in (s.start, s.goal):
            assert g.inside_bounds([pose], G, s.bounds)[0]
            assert g.clearance([pose], G, obstacles)[0] >= 0.1
        assert any(o.kind == "barrier" for o in s.obstacles) == s.meta.barrier
        assert len(_cars(s)) == 2 * CFG.neighbours_per_side


def test_parallel_tiers_are_the_documented_gaps():
    for tier, factor in enumerate((1.5, 1.35, 1.2)):
        s = sc.grid_scene(sc.cell_index("parallel", "left", tier, False))
        cars = _cars(s)
        near_rear = max(c[:, 0].max() for c in cars if c[:, 0].max() < 0)
        near_front = min(c[:, 0].min() for c in cars if c[:, 0].min() > 0)
        assert abs((near_front - near_rear) - factor * G.length) < 1e-9
        # goal: centred in the gap, aligned with the row, curb offset from the curb
        fp = g.footprint(s.goal, G)
        assert abs(fp[:, 0].mean()) < 1e-9 and abs(s.goal[2]) < 1e-12
        curb = next(o.vertices for o in s.obstacles if o.kind == "curb")
        assert abs(fp[:, 1].min() - curb[:, 1].max() - CFG.parallel.curb_offset_m) < 1e-9


def test_bay_tiers_are_car_width_plus_extra():
    for bay in ("perpendicular", "angled"):
        angle = math.radians(90.0 if bay == "perpendicular" else 60.0)
        for tier, extra in enumerate((1.0, 0.7, 0.4)):
            s = sc.grid_scene(sc.cell_index(bay, "left", tier, True))
            cars = _cars(s)
            axis = np.array([math.cos(angle), math.sin(angle)])
            normal = np.array([-axis[1], axis[0]])
            # neighbours are centred in bays of the slot's width: their centre-lines are one
            # bay pitch apart across the bay axis, and the goal car sits midway
            centres = sorted(float(c.mean(axis=0) @ normal) for c in cars)
            pitch = np.diff(centres)
            assert np.allclose(pitch[[0, 2]], G.width + extra)
            goal_c = g.footprint(s.goal, G).mean(axis=0) @ normal
            assert abs(goal_c - 0.5 * (centres[1] + centres[2])) < 1e-9
            assert abs((centres[2] - centres[1]) - 2 * (G.width + extra)) < 1e-9
            assert abs(s.goal[2] - angle) < 1e-12


def test_right_approach_mirrors_parallel_and_perpendicular():
    for bay in ("parallel", "perpendicular"):
        left = sc.build_scene(bay, "left", 1, True)
        right = sc.build_scene(bay, "right", 1, True)
        assert math.isclose(right.start[0], -left.start[0]) and right.start[1] == left.start[1]
        assert math.isclose(math.cos(right.start[2]), -math.cos(left.start[2]))
        lx = sorted(np.round(o.vertices[:, 0].mean(), 9) for o in left.obstacles)
        rx = sorted(np.round(-o.vertices[:, 0].mean(), 9) for o in right.obstacles)
        assert lx == rx
    # angled bays keep their slant: the goal is the same, the start comes from the other side
    la, ra = sc.build_scene("angled", "left", 1, True), sc.build_scene("angled", "right", 1, True)
    assert la.goal == ra.goal and la.start[0] < 0 < ra.start[0]


def test_perturbations():
    base = sc.grid_scene(3)
    skew = sc.robust_scene(0 * 36 + 3)
    for a, b in zip(_cars(base), _cars(skew), strict=True):
        ea, eb = a[1] - a[0], b[1] - b[0]
        turn = math.atan2(eb[1], eb[0]) - math.atan2(ea[1], ea[0])
        assert abs(turn - math.radians(5.0)) < 1e-9
        np.testing.assert_allclose(a.mean(axis=0), b.mean(axis=0), atol=1e-9)
    jit = sc.robust_scene(2 * 36 + 3)
    x, y, th = base.start
    d = np.array(jit.start[:2]) - (x, y)
    along = d @ (math.cos(th), math.sin(th))
    left = d @ (-math.sin(th), math.cos(th))
    assert np.allclose([along, left], [0.25, 0.25]) and math.isclose(
        jit.start[2] - th, math.radians(3)
    )
    for variant, delta in ((4, -0.075), (5, 0.075)):
        s = sc.robust_scene(variant * 36 + 3)
        assert math.isclose(s.meta.slot_size_m - base.meta.slot_size_m, delta, abs_tol=1e-9)
    # combined = skew +5 deg, jitter a and tighter (a perpendicular cell: the start does not
    # depend on the slot there)
    combined = sc.robust_scene(6 * 36 + 15)
    assert combined.start == sc.robust_scene(2 * 36 + 15).start
    for a, b in zip(_cars(sc.grid_scene(15)), _cars(combined), strict=True):
        ea, eb = a[1] - a[0], b[1] - b[0]
        turn = math.atan2(eb[1], eb[0]) - math.atan2(ea[1], ea[0])
        assert abs((turn + math.pi) % (2 * math.pi) - math.pi - math.radians(5.0)) < 1e-9
    assert math.isclose(
        combined.meta.slot_size_m, sc.grid_scene(15).meta.slot_size_m - 0.075, abs_tol=1e-9
    )


def test_json_round_trip(tmp_path):
    for scene in (sc.grid_scene(29), sc.robust_scene(200)):
        back = sc.Scene.from_json(json.loads(json.dumps(scene.to_json())))
        assert back.start == scene.start and back.goal == scene.goal
        assert back.bounds == scene.bounds and back.meta == scene.meta
        for a, b in zip(back.obstacles, scene.obstacles, strict=True):
            assert a.kind == b.kind
            np.testing.assert_allclose(a.vertices, b.vertices, atol=1e-9)
    path = sc.grid_scene(0).save(tmp_path / "s.json")
    assert sc.Scene.load(path).meta.name == "parallel-left-t0-open"


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.pop("goal"), "missing key 'goal'"),
        (lambda d: d.update(start=[0, 0]), "start"),
        (lambda d: d.update(bounds=[5, 0, 1, 1]), "xmin < xmax"),
        (lambda d: d["obstacles"][0].update(vertices=[[0, 0], [2, 2], [2, 0], [0, 2]]), "simple"),
        (lambda d: d["obstacles"].append({"kind": "car"}), "vertices"),
        (lambda d: d["meta"].update(colour="red"), "unknown meta"),
        (lambda d: d.update(goal=[0, "a", 0]), "goal"),
        (lambda d: d.update(format="other"), "format"),
    ],
)
def test_malformed_scene_files_name_the_file_and_problem(tmp_path, mutate, message):
    data = sc.grid_scene(0).to_json()
    mutate(data)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(data))
    with pytest.raises(PlanningError, match=message) as err:
        sc.Scene.load(p)
    assert str(p) in str(err.value)


def test_unreadable_scene_files(tmp_path):
    with pytest.raises(PlanningError, match="not found"):
        sc.Scene.load(tmp_path / "missing.json")
    p = tmp_path / "broken.json"
    p.write_text("{not json")
    with pytest.raises(PlanningError, match="not valid JSON"):
        sc.Scene.load(p)


def test_config_file_matches_defaults():
    assert sc.load_scenarios_config() == sc.ScenariosConfig()


def test_grid_cells_and_scene_names(tmp_path):
    assert sc.grid_cells("36") == list(range(36)) and len(sc.grid_cells("252")) == 252
    assert sc.grid_cells("12") == sc.core_cells()
    assert sc.grid_cells("36", spec="0-2,9") == [0, 1, 2, 9]
    for grid, spec in (("35", None), ("12", "0"), ("36", "x")):
        with pytest.raises(ConfigError):
            sc.grid_cells(grid, spec=spec)
    assert sc.resolve_scene("7").meta.cell == 7
    robust = sc.robust_scene(40).to_json()
    assert sc.resolve_scene("robust:40").to_json() == sc.cell_scene("252", 40).to_json() == robust
    path = sc.grid_scene(3).save(tmp_path / "s.json")
    assert sc.resolve_scene(str(path)).to_json() == sc.grid_scene(3).to_json()
    with pytest.raises(PlanningError, match="not a scene file"):
        sc.resolve_scene("cell seven")


def test_a_map_outline_round_trips_and_bad_ones_are_refused():
    from parknss.sim.geometry import inside_map
    from parknss.sim.planning.frame import move_scene

    scene = move_scene(sc.grid_scene(3), 0.6, (50.0, -20.0))  # the map: a rotated box
    back = sc.Scene.from_json(scene.to_json())
    assert back.map_outline == scene.map_outline and back.bounds == scene.bounds
    A, b = back.map_planes()
    for p in scene.map_outline:  # the corners lie on the edges
        assert np.max(A @ np.asarray(p) - b) == pytest.approx(0.0, abs=1e-9)
    # the bounding box's corner is outside the rotated map
    corner = (scene.bounds[0] + 0.5, scene.bounds[1] + 0.5, 0.0)
    assert not inside_map([corner], VehicleGeometry(), back)[0]
    assert inside_map([scene.goal], VehicleGeometry(), back)[0]
    doc = scene.to_json()
    doc["map_outline"] = doc["map_outline"][::-1]  # clockwise
    with pytest.raises(PlanningError, match="convex and counter-clockwise"):
        sc.Scene.from_json(doc)
    doc["map_outline"] = [[0.0, 0.0], [1.0, float("nan")], [0.0, 1.0]]
    with pytest.raises(PlanningError, match="finite"):
        sc.Scene.from_json(doc)
