"""Scenario grids in closed loop and Table V (``parknss grid``).

Each cell is one executor job (:func:`cell_job`, through :func:`parknss.executor.run_jobs`
on the local pool or Ray): the cell is planned once (:func:`parknss.sim.planner.plan_scene`)
and executed under every plant; a job returns one JSON row per (cell, plant).
:func:`summarize` aggregates the rows of one plant into the Table V statistics
(:class:`GridSummary`), :func:`grid_report` per plant and, on the robustness grid, per
perturbation; :func:`table_v` renders them as text. :func:`run_grid_report` is the whole
``parknss grid`` job: run, summarise, write the per-cell CSV and the JSON report into its
run folder (:func:`parknss.outputs.run_folder`).
"""

from __future__ import annotations

import csv
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parknss.config import override
from parknss.outputs import atomic_file, run_folder
from parknss.sim import scenarios as sc
from parknss.sim.closed_loop import SimConfigFiles
from parknss.sim.session import check_plants, run_cell


def cell_job(
    grid: str,
    index: int,
    plants: list[str],
    closed_loop_config: str | None = None,
    interface_config: str | None = None,
    interface_overrides: dict | None = None,
    planning_config: str | None = None,
    scenarios_config: str | None = None,
    vehicle: str | None = None,
) -> list[dict]:
    """Executor job: one cell of grid "36" or "252" under each plant; JSON rows. The
    grid is built for the run's car (``vehicle`` YAML, else the chain's car)."""
    files = SimConfigFiles(
        closed_loop_config, interface_config, planning_config, scenarios_config, vehicle
    )
    geom = files.vehicle_geometry()
    scene = sc.cell_scene(grid, index, files.scenarios_config(), geom)
    cfg = files.closed_loop_config()
    icfg = override(files.interface_config(), interface_overrides, source="interface overrides")
    plan, outcomes = run_cell(scene, plants, cfg, icfg, planning_config, geom)
    rows = []
    for o in outcomes:
        row = o.to_json()
        row.update(
            grid=grid,
            index=index,
            cell=scene.meta.cell,
            name=scene.meta.name,
            perturbation=scene.meta.perturbation,
            plannable=plan.trajectory is not None,
            plan_reason=plan.reason,
            refined=plan.refined,
            plan_s=round(plan.plan_s, 4),
            plan_clearance_cm=None
            if plan.min_clearance_m is None
            else plan.min_clearance_m * 100.0,
        )
        rows.append(row)
    return rows


def run_grid(
    grid: str,
    plants: list[str],
    cells: list[int],
    workers: int = 1,
    *,
    files: SimConfigFiles | None = None,
    interface_overrides: dict | None = None,
    executor: str = "local",
    address: str | None = None,
    cache_dir: str | Path | None = None,
    progress: bool = True,
    store=None,
    tally=None,
) -> list[dict]:
    """Run ``cells`` of grid "36", "12" or "252" under ``plants`` through the executor;
    one JSON row per (cell, plant), cells in the order given. With a result ``store``
    (``parknss reproduce``) each cell is looked up there first and kept there as soon as
    it finishes (:mod:`parknss.experiments.derived`)."""
    files = files or SimConfigFiles()
    kwargs = {
        "plants": plants,
        "closed_loop_config": files.closed_loop,
        "interface_config": files.interface,
        "interface_overrides": interface_overrides,
        "planning_config": files.planning,
        "scenarios_config": files.scenarios,
        "vehicle": files.vehicle,
    }
    results = sc.run_cells(
        "parknss.sim.grid:cell_job",
        grid,
        cells,
        kwargs,
        executor=executor,
        workers=workers,
        address=address,
        cache_dir=cache_dir,
        progress=progress,
        desc=f"grid {grid}",
        store=store,
        tally=tally,
    )
    return [row for rows in results for row in rows]


@dataclass
class GridSummary:
    """Table V statistics of one plant over a set of cells (goal errors over every
    executed cell, failed runs at their final pose; cm, s)."""

    plant: str
    cells: int
    plannable: int
    completed: int
    goal_mean_cm: float | None
    goal_median_cm: float | None
    goal_max_cm: float | None
    clearance_mean_cm: float | None
    under_floor: int
    over_20cm_goal: int
    collisions: int
    livelocks: int
    timeouts: int
    duration_mean_s: float | None
    sim_s: float
    wall_s: float

    @property
    def realtime_factor(self) -> float | None:
        return self.sim_s / self.wall_s if self.wall_s > 0 else None

    def to_json(self) -> dict:
        out = dict(self.__dict__)
        out["realtime_factor"] = self.realtime_factor
        return out


def summarize(rows: list[dict], plant: str, floor_cm: float = 20.0) -> GridSummary:
    """Aggregate the rows of one plant (see :class:`GridSummary`)."""
    mine = [r for r in rows if r["plant"] == plant]
    ran = [r for r in mine if r["plannable"]]
    goals = np.array([r["goal_error_cm"] for r in ran], float)
    clr = np.array([r["clearance_cm"] for r in ran if r["clearance_cm"] is not None], float)

    def stat(fn, a):
        return float(fn(a)) if len(a) else None

    return GridSummary(
        plant=plant,
        cells=len(mine),
        plannable=len(ran),
        completed=sum(r["completed"] for r in ran),
        goal_mean_cm=stat(np.mean, goals),
        goal_median_cm=stat(np.median, goals),
        goal_max_cm=stat(np.max, goals),
        clearance_mean_cm=stat(np.mean, clr),
        under_floor=int(np.sum(clr < floor_cm)),
        over_20cm_goal=int(np.sum(goals > 20.0)),
        collisions=sum(r["reason"] == "collision" for r in ran),
        livelocks=sum(r["reason"] == "livelock" for r in ran),
        timeouts=sum(r["reason"] == "timeout" for r in ran),
        duration_mean_s=stat(np.mean, np.array([r["duration_s"] for r in ran], float)),
        sim_s=float(sum(r["duration_s"] for r in ran)),
        wall_s=float(sum(r["wall_s"] for r in mine)),
    )


def grid_report(rows: list[dict], plants: list[str], grid: str, floor_cm: float) -> dict:
    """Summaries per plant and, for the robustness grid, per perturbation."""
    doc = {"summary": {p: summarize(rows, p, floor_cm).to_json() for p in plants}}
    if grid == "252":
        doc["heldout"] = {
            p: {
                pert: summarize(
                    [r for r in rows if r["perturbation"] == pert], p, floor_cm
                ).to_json()
                for pert in sc.PERTURBATIONS
                if any(r["perturbation"] == pert for r in rows)
            }
            for p in plants
        }
    return doc


def _f(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def table_v(summaries: dict, heldout: dict | None = None) -> str:
    """Table V as fixed-width text: one column per plant, plus the held-out block."""
    plants = list(summaries)
    lines = [f"{'':<40}" + "".join(f"{p:>14}" for p in plants)]

    def row(label, fn):
        lines.append(f"{label:<40}" + "".join(f"{fn(summaries[p]):>14}" for p in plants))

    row("Completed maneuvers", lambda s: f"{s['completed']}/{s['plannable']}")
    row("Plannable cells", lambda s: f"{s['plannable']}/{s['cells']}")
    row("Goal error, mean [cm]", lambda s: _f(s["goal_mean_cm"], ".1f"))
    row("Goal error, median [cm]", lambda s: _f(s["goal_median_cm"], ".1f"))
    row("Goal error, max [cm]", lambda s: _f(s["goal_max_cm"], ".1f"))
    row("Driven clearance, mean [cm]", lambda s: _f(s["clearance_mean_cm"], ".1f"))
    row("Cells under the 20 cm sensor floor", lambda s: str(s["under_floor"]))
    row("Cells with goal error > 20 cm", lambda s: str(s["over_20cm_goal"]))
    row(
        "Collisions / livelocks / timeouts",
        lambda s: "{collisions}/{livelocks}/{timeouts}".format(**s),
    )
    row("Duration, mean [s]", lambda s: _f(s["duration_mean_s"], ".1f"))
    row("Real-time factor (per process)", lambda s: _f(s["realtime_factor"], ".1f"))
    if heldout:
        lines.append("Held-out axes; goal error mean/med/max [cm] (plannable cells)")
        perts = list(next(iter(heldout.values())))
        for pert in perts:
            cells = []
            for p in plants:
                s = heldout[p][pert]
                cells.append(
                    f"{_f(s['goal_mean_cm'], '.1f')}/{_f(s['goal_median_cm'], '.1f')}/"
                    f"{_f(s['goal_max_cm'], '.1f')}"
                )
            n = heldout[plants[0]][pert]["plannable"]
            lines.append(f"  {pert + f' ({n})':<38}" + "".join(f"{c:>14}" for c in cells))
    return "\n".join(lines)


def write_rows_csv(rows: list[dict], path: Path) -> None:
    """The per-(cell, plant) rows as one CSV (columns of the first row)."""
    cols = list(rows[0]) if rows else []
    with atomic_file(path) as tmp, tmp.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)


def run_grid_report(
    grid: str,
    plants: list[str],
    out: Path,
    *,
    cells: str | None = None,
    files: SimConfigFiles | None = None,
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    overwrite: bool = False,
) -> dict:
    """``parknss grid``: run grid ``grid`` ("36", "12", "252"; ``cells``: a subset such as
    "0-5,9") under ``plants``, write ``grid_<grid>_cells.csv`` and ``grid_<grid>.json``
    to the run folder ``out`` (refused if it holds anything but the same grid run, unless
    ``overwrite``); the report (Table V summaries, wall and simulated seconds, the CSV
    path)."""
    files = files or SimConfigFiles()
    cfg = files.closed_loop_config()
    check_plants(plants, cfg, files.vehicle_geometry())  # fail fast, before any cell runs
    idx = sc.grid_cells(grid, files.scenarios_config(), cells)
    identity = {"grid": grid, "plants": plants, "cells": idx, **config_paths(files)}
    with run_folder(out, command="parknss grid", args=identity, overwrite=overwrite) as run:
        t0 = time.perf_counter()
        rows = run_grid(grid, plants, idx, workers, files=files, executor=executor,
                        address=address)
        wall = time.perf_counter() - t0
        doc = {"grid": grid, "plants": plants, "cells": len(idx), "workers": workers}
        doc.update(grid_report(rows, plants, grid, cfg.clearance_floor_cm))
        sim = sum(r["duration_s"] for r in rows)
        doc["wall_s"] = round(wall, 2)
        doc["sim_s"] = round(sim, 2)
        doc["realtime_factor_wall"] = round(sim / wall, 2) if wall > 0 else None
        csv_path = out / f"grid_{grid}_cells.csv"
        write_rows_csv(rows, csv_path)
        doc["csv"] = str(csv_path)
        run.write_json(f"grid_{grid}.json", doc)
    return doc


def config_paths(files: SimConfigFiles) -> dict[str, Path | None]:
    """The config files of a simulator run as paths (a run folder's manifest arguments)."""
    return {f"{k}_config": None if v is None else Path(v) for k, v in files.to_json().items()}
