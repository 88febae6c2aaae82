"""The ``parknss plan`` command: one JSON document, a figure, clear errors."""

import json

import numpy as np

from parknss.cli import main
from parknss.commands.plan import grid_table, plan_cell_job
from parknss.sim.scenarios import grid_scene

KEYS = {"cell", "plannable", "plan_time_s", "length_m", "cusps", "min_clearance_m"}


def test_plan_one_cell_prints_one_json_document_and_draws(tmp_path, capsys):
    assert main(["plan", "--scene", "14", "--json", "--no-refine", "--out", str(tmp_path)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= KEYS
    assert out["cell"] == 14 and out["plannable"] is True
    assert out["min_clearance_m"] >= 0.1 and out["cusps"] >= 0
    png = tmp_path / "plan_perpendicular-left-t1-open.png"
    assert png.is_file() and png.read_bytes()[:4] == b"\x89PNG"
    assert json.loads((tmp_path / "plan_perpendicular-left-t1-open.json").read_text()) == out


def test_plan_a_scene_file(tmp_path, capsys):
    path = grid_scene(20).save(tmp_path / "scene.json")
    assert (
        main(["plan", "--scene", str(path), "--json", "--no-refine", "--out", str(tmp_path)]) == 0
    )
    assert json.loads(capsys.readouterr().out)["plannable"] is True


def test_bad_requests_exit_2_with_one_line(tmp_path, capsys):
    assert main(["plan"]) == 2
    assert main(["plan", "--scene", "77"]) == 2
    assert main(["plan", "--scene", str(tmp_path / "none.json")]) == 2
    assert main(["plan", "--grid", "35"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert all(line.startswith("parknss: error:") for line in err)


def test_grid_rows_and_table():
    rows = [plan_cell_job("36", i, refine=False) for i in (18, 20)]
    assert all(set(r) >= KEYS and r["plannable"] for r in rows)
    table = grid_table(rows)
    assert "plannable 2/2" in table and "perpendicular-right-t0-open" in table


def _fake_refine_module(shift_y):
    """A stand-in refinement stage honouring the agreed API (refine.py is built elsewhere)."""
    import types
    from dataclasses import dataclass

    from parknss.sim.trajectory import Segment, Trajectory

    @dataclass
    class RefineResult:
        trajectory: Trajectory
        ok: bool
        reason: str
        solve_time_s: float

    def refine(scene, coarse, geom, config=None):
        shift = np.array([0.0, shift_y, 0.0])
        segs = [Segment(s.poses + shift, s.direction) for s in coarse.segments]
        return RefineResult(Trajectory(segs, source="refined"), True, "solved", 0.01)

    mod = types.ModuleType("parknss.sim.planning.refine")
    mod.refine = refine
    mod.RefineResult = RefineResult
    return mod


def test_refined_path_is_used_only_if_it_passes_the_dense_check(monkeypatch):
    import sys

    from parknss.commands.plan import plan_scene

    scene = grid_scene(20)
    monkeypatch.setitem(sys.modules, "parknss.sim.planning.refine", _fake_refine_module(0.0))
    good = plan_scene(scene)["summary"]
    assert good["refined"] is True and good["refine_reason"] == "solved"
    # a "refined" path pushed 3 m sideways hits the neighbours: fall back to the coarse one
    monkeypatch.setitem(sys.modules, "parknss.sim.planning.refine", _fake_refine_module(-3.0))
    bad = plan_scene(scene)["summary"]
    assert bad["refined"] is False and "failed the dense check" in bad["refine_reason"]
    assert bad["min_clearance_m"] == good["min_clearance_m"] >= 0.1
