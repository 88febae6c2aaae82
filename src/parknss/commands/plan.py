"""``parknss plan``: plan one parking scene or a whole scenario grid.

``parknss plan --scene FILE|CELL`` plans one scene (a scene JSON file, a grid cell 0-35,
or ``robust:N`` for robustness cell 0-251), refines the path when the refinement stage
is available, draws the scene to a PNG and prints a summary (or one JSON object).
``parknss plan --grid 36`` (or ``12`` for the tuning core, ``252`` for the robustness
grid) plans every cell and prints a table (or one JSON list) with, per cell: plannable,
search and refinement time, path length, cusps and the minimum dense clearance.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import typer

from parknss.errors import ParknssError, PlanningError

GRIDS = ("36", "12", "252")


def _log(msg: str) -> None:
    typer.echo(f"[plan] {msg}", err=True)


def resolve_scene(spec: str, scenarios_config: str | None = None):
    """A Scene from a JSON file path, a grid cell index 0-35, or ``robust:N`` (0-251)."""
    from parknss.sim import scenarios as sc

    cfg = sc.load_scenarios_config(scenarios_config)
    text = spec.strip()
    if text.isdigit():
        return sc.grid_scene(int(text), cfg)
    if text.lower().startswith("robust:") and text[7:].isdigit():
        return sc.robust_scene(int(text[7:]), cfg)
    path = Path(text)
    if path.suffix.lower() == ".json" or path.exists():
        return sc.Scene.load(path)
    raise PlanningError(f"--scene {spec!r}: not a scene file, a cell 0-35 or robust:N")


def _refine(scene, coarse, geom, cfg=None):
    """Run the refinement stage if it is installed: (trajectory|None, ok, reason, s).

    ``cfg`` is the planning config (its ``refine`` section and margin); None: the default.
    """
    try:
        from parknss.sim.planning.refine import refine
    except ImportError:
        return None, False, "refinement unavailable", 0.0
    t0 = time.perf_counter()
    try:
        res = refine(scene, coarse, geom, cfg)
    except ParknssError as exc:
        return None, False, f"refinement error: {exc}", time.perf_counter() - t0
    return res.trajectory, bool(res.ok), str(res.reason), time.perf_counter() - t0


def plan_scene(scene, planning_config: str | None = None, refine: bool = True) -> dict:
    """Plan (and refine) one scene; a JSON-ready summary plus the trajectories."""
    from parknss.sim.planning.hybrid_astar import (
        HybridAStar,
        load_planning_config,
        verify_trajectory,
    )
    from parknss.vehicle import VehicleGeometry

    cfg = load_planning_config(planning_config)
    geom = VehicleGeometry()
    res = HybridAStar(cfg, geom).plan(scene)
    out = {
        "cell": scene.meta.cell if scene.meta.robust_index is None else scene.meta.robust_index,
        "name": scene.meta.name,
        "plannable": bool(res.found),
        "reason": res.reason,
        "search_time_s": round(res.stats.time_s, 4),
        "refine_time_s": 0.0,
        "plan_time_s": round(res.stats.time_s, 4),
        "length_m": None,
        "cusps": None,
        "min_clearance_m": None,
        "coarse_min_clearance_m": None,
        "refined": False,
        "refine_reason": "",
        "expansions": res.stats.expansions,
    }
    refined = None
    if res.found:
        final = res.trajectory
        out["coarse_min_clearance_m"] = round(res.min_clearance_m, 4)
        if refine:
            traj, ok, reason, secs = _refine(scene, res.trajectory, geom, cfg)
            out["refine_time_s"] = round(secs, 4)
            out["plan_time_s"] = round(res.stats.time_s + secs, 4)
            out["refine_reason"] = reason
            if traj is not None:
                refined = traj
            if ok and traj is not None and traj.segments:
                passed, clr = verify_trajectory(traj, scene, geom, cfg)
                if passed:
                    final = traj
                    out["refined"] = True
                else:
                    out["refine_reason"] = f"refined path failed the dense check ({clr:.3f} m)"
        _, clr = verify_trajectory(final, scene, geom, cfg)
        out["length_m"] = round(final.length, 3)
        out["cusps"] = final.cusps
        out["min_clearance_m"] = round(clr, 4) if math.isfinite(clr) else None
    return {"summary": out, "coarse": res.trajectory, "refined": refined}


def plan_cell_job(
    grid: str,
    index: int,
    planning_config: str | None = None,
    scenarios_config: str | None = None,
    refine: bool = True,
) -> dict:
    """Executor job: plan one cell of a grid; returns the JSON summary."""
    from parknss.sim import scenarios as sc

    cfg = sc.load_scenarios_config(scenarios_config)
    scene = sc.robust_scene(index, cfg) if grid == "252" else sc.grid_scene(index, cfg)
    return plan_scene(scene, planning_config, refine)["summary"]


def _fmt(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def grid_table(rows: list[dict]) -> str:
    """A fixed-width table of grid results and a summary line."""
    head = (
        f"{'cell':>4} {'name':<34} {'plan':>4} {'search s':>9} {'refine s':>9} "
        f"{'length m':>9} {'cusps':>5} {'min clr m':>9}  reason"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        note = r["reason"] if not r["plannable"] else r["refine_reason"]
        lines.append(
            f"{r['cell']:>4} {r['name']:<34} {'yes' if r['plannable'] else 'no':>4} "
            f"{r['search_time_s']:>9.3f} {r['refine_time_s']:>9.3f} "
            f"{_fmt(r['length_m'], '9.2f'):>9} {_fmt(r['cusps'], '5d'):>5} "
            f"{_fmt(r['min_clearance_m'], '9.3f'):>9}  {note}"
        )
    ok = [r for r in rows if r["plannable"]]
    lines.append("-" * len(head))
    lines.append(f"plannable {len(ok)}/{len(rows)}")
    if ok:
        times = sorted(r["search_time_s"] for r in ok)
        clr = min(r["min_clearance_m"] for r in ok if r["min_clearance_m"] is not None)
        lines.append(
            f"search time median {times[len(times) // 2]:.3f} s, max {times[-1]:.3f} s; "
            f"min clearance {clr:.3f} m"
        )
    return "\n".join(lines)


def register(app: typer.Typer) -> None:
    @app.command("plan")
    def plan(
        scene: str | None = typer.Option(
            None, "--scene", help="Scene JSON file, grid cell 0-35, or robust:N (0-251)."
        ),
        grid: str | None = typer.Option(
            None, "--grid", help="Plan a whole grid: 36 (default grid), 12 (core), 252."
        ),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
        out: Path | None = typer.Option(None, "--out", help="Folder for figures and JSON."),
        workers: int = typer.Option(1, "--workers", help="Parallel workers for --grid."),
        config: Path | None = typer.Option(None, "--config", help="Planning YAML."),
        scenarios_config: Path | None = typer.Option(
            None, "--scenarios-config", help="Scenarios YAML."
        ),
        no_refine: bool = typer.Option(False, "--no-refine", help="Coarse path only."),
    ) -> None:
        """Plan one parking scene (and draw it) or a whole scenario grid."""
        if (scene is None) == (grid is None):
            raise PlanningError("give exactly one of --scene FILE|CELL or --grid 36|12|252")
        cfg_path = str(config) if config else None
        sc_path = str(scenarios_config) if scenarios_config else None
        if scene is not None:
            _plan_one(scene, as_json, out, cfg_path, sc_path, not no_refine)
        else:
            _plan_grid(grid, as_json, out, workers, cfg_path, sc_path, not no_refine)


def _plan_one(spec, as_json, out, cfg_path, sc_path, refine) -> None:
    from parknss.report.plan_figure import draw_plan

    scene = resolve_scene(spec, sc_path)
    result = plan_scene(scene, cfg_path, refine)
    summary = result["summary"]
    folder = out or Path("runs/plan")
    fig = draw_plan(
        scene,
        folder / f"plan_{scene.meta.name}.png",
        coarse=result["coarse"],
        refined=result["refined"],
    )
    summary["figure"] = str(fig)
    if out is not None:
        (out / f"plan_{scene.meta.name}.json").write_text(json.dumps(summary, indent=2))
    _log(f"drew {fig}")
    if as_json:
        typer.echo(json.dumps(summary, indent=2))
    else:
        for key, value in summary.items():
            typer.echo(f"{key:>24}: {value}")


def _plan_grid(grid, as_json, out, workers, cfg_path, sc_path, refine) -> None:
    from parknss.experiments.executor import Job, run_jobs
    from parknss.sim.scenarios import N_CELLS, N_ROBUST, core_cells, load_scenarios_config

    if grid not in GRIDS:
        raise PlanningError(f"--grid {grid!r}: one of {', '.join(GRIDS)}")
    if grid == "36":
        cells = list(range(N_CELLS))
    elif grid == "12":
        cells = core_cells(load_scenarios_config(sc_path))
    else:
        cells = list(range(N_ROBUST))
    kind = "252" if grid == "252" else "36"
    jobs = [
        Job(
            "parknss.commands.plan:plan_cell_job",
            {
                "grid": kind,
                "index": i,
                "planning_config": cfg_path,
                "scenarios_config": sc_path,
                "refine": refine,
            },
            name=f"cell {i}",
        )
        for i in cells
    ]
    rows = run_jobs(jobs, workers=workers, progress=True, desc=f"plan grid {grid}")
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / f"plan_grid_{grid}.json").write_text(json.dumps(rows, indent=2))
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
    else:
        typer.echo(grid_table(rows))
