"""A reproduce stopped in the closed-loop grid (parknss.experiments.reproduce) keeps every
finished cell in the result store, writes a report marked partial and exits 143 with one
line; the same command again resumes from the kept cells and ends where an uninterrupted
run ends. A tiny grid: two cells, the kinematic plant only."""

from __future__ import annotations

import functools
import json
import os
import re
import signal
from pathlib import Path

import parknss.sim.grid as grid
from parknss.cli import main
from parknss.experiments.store import entries

TIMINGS = ("wall_s", "plan_s", "realtime_factor")


def _config(tmp_path: Path) -> Path:
    p = tmp_path / "experiments.yaml"
    p.write_text("full:\n  sim_cells: [0, 1]\n  sim_plants: [kinematic]\n  sim_scene: 0\n")
    return p


def _args(cfg: Path, out: Path, store: Path) -> list[str]:
    return ["reproduce", "table5", "--config", str(cfg), "--out", str(out),
            "--store", str(store), "--workers", "1"]


def _cells(store: Path) -> dict[int, list[dict]]:
    """The stored cells' rows without their timings, by cell index."""
    out = {}
    for _, e in entries(store):
        assert not isinstance(e, str), e
        out[e.kwargs["index"]] = [{k: v for k, v in r.items() if k not in TIMINGS}
                                  for r in e.result]
    return out


def _table_v(report: Path) -> str:
    return re.search(r"<h3>Table V:.*?</table>", report.read_text(), re.S).group(0)


def test_a_killed_grid_keeps_its_cells_reports_partial_and_resumes(tmp_path, monkeypatch,
                                                                    capsys):
    cfg, store, out = _config(tmp_path), tmp_path / "store", tmp_path / "run"
    real = grid.cell_job
    calls: list[int] = []

    @functools.wraps(real)
    def stopped_after_one(**kw):
        if calls:  # the second cell: SIGTERM arrives (the CLI's handler raises it here)
            os.kill(os.getpid(), signal.SIGTERM)
        calls.append(kw["index"])
        return real(**kw)

    monkeypatch.setattr(grid, "cell_job", stopped_after_one)
    assert main(_args(cfg, out, store)) == 143
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("parknss: terminated: interrupted during table5: 0 of 1 "
                              "artefacts finished; 1 of 2 of its jobs")
    assert "run the same command again to resume" in err[-1]
    assert list(_cells(store)) == [0]  # the finished cell is kept
    report = (out / "report.html").read_text()
    assert "Partial report." in report and "1 of 2 of its jobs" in report

    monkeypatch.setattr(grid, "cell_job", real)
    assert main([*_args(cfg, out, store), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["partial"] is None
    assert summary["sources"]["table5"] == {"run_cache": 1, "store": 0, "fitted": 1}
    assert "Partial report." not in (out / "report.html").read_text()

    # the cells as an uninterrupted run computes them
    kw = {k: v for k, v in entries(store)[0][1].kwargs.items() if k not in ("inputs", "index")}
    fresh = {i: [{k: v for k, v in r.items() if k not in TIMINGS}
                 for r in real(**kw, index=i)] for i in (0, 1)}
    assert _cells(store) == fresh
    # --stored-only rebuilds Table V from the stored cells alone, no closed loop run
    monkeypatch.setattr(grid, "cell_job", None)  # any cell run would fail
    assert main([*_args(cfg, tmp_path / "stored", store), "--stored-only"]) == 0
    assert _table_v(tmp_path / "stored" / "report.html") == _table_v(out / "report.html")
