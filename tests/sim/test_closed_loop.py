"""The closed loop: completion on hand-made and planned scenes, collision, livelock and
timeout detection, one scene and the grid job and summary (library), the tuning descent,
and one smoke test per command (simulate, grid, tune)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from helpers.scenes import arc_scene, shuffle_scene
from parknss.cli import main
from parknss.config import override
from parknss.report.sim_figures import draw_scene_run
from parknss.sim import geometry
from parknss.sim.closed_loop import ClosedLoopConfig, execute, load_closed_loop_config
from parknss.sim.control.interface import InterfaceConfig
from parknss.sim.grid import cell_job, run_grid_report, summarize, table_v
from parknss.sim.plants import KinematicPlant, ReferencePlant
from parknss.sim.scenarios import Obstacle, Scene
from parknss.sim.session import simulate_scene, summary_text
from parknss.sim.tuning import TuningConfig, coordinate_descent, objective
from parknss.vehicle import VehicleGeometry


def test_kinematic_run_is_complete_and_consistent():
    scene, traj = arc_scene()
    out = execute(scene, traj, KinematicPlant())
    s = out.series
    assert out.completed and out.steps == len(s["t"])
    assert s["gear_cmd"][-1] == 0 and s["gear"][-1] == 0
    # reported clearance is the exact minimum over the driven poses
    poses = np.column_stack([s["x"], s["y"], s["heading"]])
    exact = geometry.clearance(poses, VehicleGeometry(), scene.obstacle_arrays()).min()
    assert out.clearance_cm == pytest.approx(exact * 100.0, abs=0.05)
    assert out.driven_length_m == pytest.approx(traj.length, abs=0.05)
    assert out.duration_s == pytest.approx(s["t"][-1])


def test_reference_plant_completes_the_hand_made_scene():
    scene, traj = arc_scene()
    out = execute(scene, traj, ReferencePlant(seed=1))
    assert out.completed, out.reason
    assert out.goal_error_cm < 5.0 and out.heading_error_deg < 2.0
    moving = np.abs(out.series["vx"]) > 0.2
    assert np.nanmax(np.abs(out.series["lateral_error"][moving])) < 0.05
    # gear changes only at (true) standstill: the pose does not move across a change
    change = np.flatnonzero(np.diff(out.series["gear"]) != 0)
    step = np.hypot(np.diff(out.series["x"]), np.diff(out.series["y"]))
    assert np.all(step[change] < 1e-3)


def test_collision_is_detected_at_the_first_contact():
    scene, traj = arc_scene()
    wall = np.array([[5.5, -0.5], [6.0, -0.5], [6.0, 0.5], [5.5, 0.5]])
    blocked = Scene(scene.bounds, (Obstacle("wall", wall),), scene.start, scene.goal)
    out = execute(blocked, traj, KinematicPlant())
    assert not out.completed and out.reason == "collision"
    assert out.clearance_cm == 0.0
    s, geom = out.series, VehicleGeometry()
    last = np.array([[s["x"][-1], s["y"][-1], s["heading"][-1]]])
    before = np.array([[s["x"][-2], s["y"][-2], s["heading"][-2]]])
    assert geometry.collides(last, geom, [wall])[0]
    assert not geometry.collides(before, geom, [wall])[0]


class DeadDrive(KinematicPlant):
    """A car whose drive never moves it (livelock bait)."""

    def step(self, cmd):
        self.speed_target = 0.0
        return super().step(cmd)


def test_livelock_and_timeout_are_detected():
    scene, traj = arc_scene()
    out = execute(scene, traj, DeadDrive(), ClosedLoopConfig(livelock_s=2.0))
    assert out.reason == "livelock" and not out.completed
    assert out.duration_s == pytest.approx(2.0, abs=0.02)
    assert out.goal_error_cm == pytest.approx(100 * np.hypot(*np.subtract(scene.goal[:2], 0)))
    fixed = ClosedLoopConfig(timeout_s=1.0, timeout_per_segment_s=0.0)
    out = execute(scene, traj, KinematicPlant(), fixed)
    assert out.reason == "timeout" and out.duration_s == pytest.approx(1.0)
    # each segment after the first adds its seconds to the limit (two segments here) ...
    out = execute(scene, traj, KinematicPlant(), ClosedLoopConfig(timeout_s=1.0))
    assert out.reason == "timeout" and out.duration_s == pytest.approx(1.0 + 3.0)
    # ... up to timeout_max_s, and never below timeout_s
    assert ClosedLoopConfig(timeout_s=1.0, timeout_max_s=2.5).time_limit(traj) == 2.5
    assert ClosedLoopConfig(timeout_s=9.0, timeout_max_s=2.5).time_limit(traj) == 9.0


def test_stroke_level_stop_feedback_keeps_a_shuffle_on_its_plan():
    """20 strokes of 15 cm: the kinematic plant stops where it is asked to, so a fixed
    1 cm stop offset loses 1 cm of arc on every stroke and the heading drifts by degrees;
    fed back, the offset goes to zero after the first stop of each gear."""
    scene, traj = shuffle_scene()
    runs = {}
    for gain in (0.0, 0.5):
        cfg = override(load_closed_loop_config(), {"tracker": {"stop_adapt_gain": gain}})
        runs[gain] = execute(scene, traj, KinematicPlant(), cfg)
        assert runs[gain].completed
    assert runs[0.0].heading_error_deg > 1.5 and runs[0.0].goal_error_cm > 0.5
    assert runs[0.5].heading_error_deg < 0.1 and runs[0.5].goal_error_cm < 0.1


def test_planned_grid_cell_job_and_summary():
    rows = cell_job("36", 26, ["kinematic"])
    assert len(rows) == 1 and rows[0]["plannable"] and rows[0]["completed"]
    assert rows[0]["goal_error_cm"] < 3.0 and rows[0]["clearance_cm"] > 20.0
    fake = [dict(rows[0], goal_error_cm=g, completed=g < 50) for g in (1.0, 2.0, 60.0)]
    s = summarize(fake, "kinematic")
    assert (s.completed, s.plannable, s.goal_median_cm, s.goal_max_cm) == (2, 3, 2.0, 60.0)
    assert s.over_20cm_goal == 1
    assert objective(fake, TuningConfig(failure_penalty_cm=30.0)) == pytest.approx(21.0 + 10.0)


def test_coordinate_descent_finds_a_bowl_minimum():
    target = {"kp": 2.2, "ki": 0.6}

    def bowl(g):
        return sum((np.log(g[k]) - np.log(v)) ** 2 for k, v in target.items())

    cfg = TuningConfig(gains=("kp", "ki"), rounds=30, min_step=0.01)
    res = coordinate_descent(bowl, InterfaceConfig(), cfg)
    assert res.objective < bowl({"kp": 1.5, "ki": 1.0})
    assert res.gains["kp"] == pytest.approx(2.2, rel=0.1)
    assert res.gains["ki"] == pytest.approx(0.6, rel=0.1)


def test_one_scene_is_planned_once_driven_and_drawn(tmp_path):
    run = simulate_scene("26", ["kinematic", "reference"])
    doc = run.to_json()
    for key in ("completed", "goal_error_cm", "heading_error_deg", "clearance_cm", "duration_s"):
        assert key in doc
    assert doc["completed"] and [r["plant"] for r in doc["runs"]] == ["kinematic", "reference"]
    assert doc["plan"]["trajectory"] == run.plan.trajectory.digest()
    assert doc["planned_length_m"] == run.plan.trajectory.length
    figures = draw_scene_run(run, tmp_path)
    assert set(figures) == {"fig8", "fig9"}
    assert all(Path(p).is_file() for p in figures.values())
    series = run.write_series(tmp_path)
    assert Path(series["reference"]).read_text().startswith("t,x,y,heading")
    assert "reference" in summary_text(doc)


def test_grid_report_writes_the_cells_and_table_v(tmp_path):
    doc = run_grid_report("36", ["kinematic"], tmp_path, cells="26")
    assert doc["summary"]["kinematic"]["completed"] == 1 and doc["cells"] == 1
    assert (tmp_path / "grid_36_cells.csv").read_text().count("\n") == 2
    assert json.loads((tmp_path / "grid_36.json").read_text())["summary"] == doc["summary"]
    assert "Completed maneuvers" in table_v(doc["summary"])


def test_simulate_command_prints_one_json(tmp_path, capsys):
    assert main(["simulate", "--scene", "26", "--json", "--out", str(tmp_path)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["completed"] and (tmp_path / doc["figures"]["fig8"].split("/")[-1]).is_file()
    assert main(["simulate", "--scene", "26", "--plant", "bicycle"]) == 2
    assert "unknown plant" in capsys.readouterr().err


def test_grid_command_prints_one_json(tmp_path, capsys):
    args = ["grid", "--grid", "36", "--cells", "26", "--plants", "kinematic", "--json"]
    assert main([*args, "--executor", "local", "--out", str(tmp_path)]) == 0
    assert json.loads(capsys.readouterr().out)["summary"]["kinematic"]["completed"] == 1
    assert main(["grid", "--grid", "35"]) == 2
    assert "--grid '35'" in capsys.readouterr().err


def test_tune_command_refuses_an_unknown_plant(tmp_path, capsys):
    assert main(["tune", "--plant", "bicycle", "--out", str(tmp_path)]) == 2
    assert "unknown plant" in capsys.readouterr().err


def test_config_file_matches_the_defaults():
    assert load_closed_loop_config() == ClosedLoopConfig()
