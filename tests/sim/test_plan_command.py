"""Planning a scene: the one ``plan_scene`` (library), the plan ``parknss plan`` prints is
the plan ``parknss simulate`` drives, grid rows and table, and the ``plan`` command."""

import json

import numpy as np
import pytest

from parknss.cli import main
from parknss.config import override
from parknss.sim import planner
from parknss.sim.closed_loop import SimConfigFiles, load_closed_loop_config
from parknss.sim.planner import (
    NO_RESERVE,
    TIMING_KEYS,
    plan_cell_job,
    plan_grid_table,
    plan_named_scene,
    plan_scene,
)
from parknss.sim.planning.hybrid_astar import verify_trajectory
from parknss.sim.scenarios import grid_scene

KEYS = {"cell", "plannable", "plan_time_s", "length_m", "cusps", "min_clearance_m"}


def test_plan_command_prints_one_json_document_and_draws(tmp_path, capsys):
    assert main(["plan", "--scene", "14", "--json", "--no-refine", "--out", str(tmp_path)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= KEYS
    assert out["cell"] == 14 and out["plannable"] is True
    assert out["min_clearance_m"] >= 0.2 and out["cusps"] >= 0
    assert (out["steer_reserve"], out["margin_m"]) == (0.1, 0.2)  # what simulate drives
    svg = tmp_path / "plan_perpendicular-left-t1-open.svg"
    assert svg.is_file() and svg.read_text().startswith("<?xml")
    assert out["figure"] == str(svg)
    assert json.loads((tmp_path / "plan_perpendicular-left-t1-open.json").read_text()) == out


def test_no_figure_plans_the_same_and_draws_nothing(tmp_path, capsys):
    args = ["plan", "--scene", "14", "--json", "--no-refine"]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    drawn = json.loads(capsys.readouterr().out)
    assert main([*args, "--no-figure", "--out", str(tmp_path / "b")]) == 0
    bare = json.loads(capsys.readouterr().out)
    assert bare["figure"] is None and drawn["figure"].endswith(".svg")
    skip = {"figure", "plan_time_s", *TIMING_KEYS}
    assert {k: v for k, v in bare.items() if k not in skip} == {
        k: v for k, v in drawn.items() if k not in skip}
    assert sorted(p.suffix for p in (tmp_path / "b").glob("plan_*")) == [".json"]


def test_bad_requests_exit_2_with_one_line(tmp_path, capsys):
    assert main(["plan"]) == 2
    assert main(["plan", "--scene", "77"]) == 2
    assert main(["plan", "--scene", str(tmp_path / "none.json")]) == 2
    assert main(["plan", "--grid", "35"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert all(line.startswith("parknss: error:") for line in err)


def _static(doc: dict) -> dict:
    return {k: v for k, v in doc.items() if k not in (*TIMING_KEYS, "figure")}


@pytest.mark.parametrize("cell", ["0", "8", "26"])
def test_the_plan_printed_is_the_plan_driven(cell, tmp_path, capsys):
    """``parknss plan --scene N --json`` and the plan ``parknss simulate --scene N`` drives
    are identical: same settings, same path (digest of every pose, speed, steering and
    time stamp the tracker reads), same clearance; cells 0, 8 and 26 (cell 8's path was
    left coarse at IPOPT's iteration cap in the world frame; every plannable cell of the
    36 grid refines in the canonical frame)."""
    assert main(["plan", "--scene", cell, "--json", "--out", str(tmp_path / "plan")]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert main(["simulate", "--scene", cell, "--json", "--out", str(tmp_path / "sim")]) == 0
    driven = json.loads(capsys.readouterr().out)
    assert printed["plannable"] and driven["completed"]
    assert _static(printed) == _static(driven["plan"])
    assert printed["length_m"] == round(driven["planned_length_m"], 3)
    assert (printed["cusps"], printed["refined"]) == (driven["cusps"], driven["refined"])
    assert printed["refined"]


def test_no_reserve_plans_as_the_planner_alone():
    scene = grid_scene(20)
    loop = load_closed_loop_config()
    free = plan_scene(scene, override(loop, NO_RESERVE), refine=False)
    kept = plan_scene(scene, loop, refine=False)
    assert (free.steer_reserve, free.margin_m) == (0.0, 0.1)
    assert (kept.steer_reserve, kept.margin_m) == (0.1, 0.2)
    assert free.trajectory.info["turning_radius_m"] < kept.trajectory.info["turning_radius_m"]
    files = SimConfigFiles()
    _, same = plan_named_scene("20", files, refine=False, closed_loop_overrides=NO_RESERVE)
    assert same.trajectory.digest() == free.trajectory.digest()


def test_a_scene_file_plans_like_its_cell(tmp_path):
    path = grid_scene(20).save(tmp_path / "scene.json")
    scene, plan = plan_named_scene(str(path), refine=False)
    assert plan.trajectory is not None and scene.meta.cell == 20
    assert plan.trajectory.digest() == plan_named_scene("20", refine=False)[1].trajectory.digest()


def test_grid_rows_and_table():
    rows = [plan_cell_job("36", i, refine=False) for i in (18, 20)]
    assert all(set(r) >= KEYS and r["plannable"] for r in rows)
    table = plan_grid_table(rows)
    assert "plannable 2/2" in table and "perpendicular-right-t0-open" in table


def _fake_refine(shift_y):
    """A stand-in refinement: the coarse path shifted sideways, reported the way
    :func:`parknss.sim.planning.refine.refine` reports (its own exact dense check)."""
    from types import SimpleNamespace

    from parknss.sim.trajectory import Segment, Trajectory

    def refine(scene, coarse, geom, config):
        shift = np.array([0.0, shift_y, 0.0])
        traj = Trajectory([Segment(s.poses + shift, s.direction) for s in coarse.segments])
        _, clr = verify_trajectory(traj, scene, geom, config)
        return SimpleNamespace(trajectory=traj, ok=True, reason="solved", min_clearance_m=clr,
                               segments=[{"status": "Solve_Succeeded"} for _ in traj.segments])

    return refine


def test_refined_path_is_used_only_if_it_clears_the_planning_margin(monkeypatch):
    scene = grid_scene(20)
    monkeypatch.setattr(planner, "refine_path", _fake_refine(0.0))
    good = plan_scene(scene)
    assert good.refined and good.refine_reason == "solved"
    # a "refined" path pushed 3 m sideways hits the neighbours: fall back to the coarse one
    monkeypatch.setattr(planner, "refine_path", _fake_refine(-3.0))
    bad = plan_scene(scene)
    assert not bad.refined and "failed the dense check" in bad.refine_reason
    assert bad.trajectory is bad.coarse
    # the fake's "refined" path is the refinement's input, rounded to canonical_snap
    assert bad.min_clearance_m == pytest.approx(good.min_clearance_m, abs=1e-5)
    assert bad.min_clearance_m >= 0.2
