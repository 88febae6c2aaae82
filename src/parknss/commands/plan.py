"""``parknss plan``: plan one parking scene or a whole scenario grid.

``parknss plan --scene FILE|CELL`` plans one scene (a scene JSON file, a grid cell 0-35,
or ``robust:N`` for robustness cell 0-251) exactly as ``parknss simulate`` will drive it
(:func:`parknss.sim.planner.plan_scene`: the closed-loop config's steering reserve and
margin), draws it to a PNG and prints a summary (or one JSON object). ``--no-reserve``
plans as the planner alone instead (full steering lock, planning.yaml's margin): a plan
that no other command drives. ``parknss plan --grid 36`` (``12``: the tuning core,
``252``: the robustness grid) plans every cell through the one executor and prints a
table (or one JSON list).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from parknss.errors import PlanningError


def _log(msg: str) -> None:
    typer.echo(f"[plan] {msg}", err=True)


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
        executor: str = typer.Option("local", "--executor", help="local (loky pool) or ray."),
        address: str | None = typer.Option(None, "--address", help="Ray cluster address."),
        config: Path | None = typer.Option(None, "--config", help="Planning YAML."),
        closed_loop_config: Path | None = typer.Option(
            None, "--closed-loop-config", help="Closed-loop YAML (steering reserve, margin)."
        ),
        scenarios_config: Path | None = typer.Option(
            None, "--scenarios-config", help="Scenarios YAML."
        ),
        no_refine: bool = typer.Option(False, "--no-refine", help="Coarse path only."),
        no_reserve: bool = typer.Option(
            False, "--no-reserve", help="Full lock, planning.yaml margin: not what is driven."
        ),
    ) -> None:
        """Plan one parking scene (and draw it) or a whole scenario grid."""
        from parknss.sim.closed_loop import SimConfigFiles
        from parknss.sim.planner import NO_RESERVE

        if (scene is None) == (grid is None):
            raise PlanningError("give exactly one of --scene FILE|CELL or --grid 36|12|252")
        files = SimConfigFiles(closed_loop_config, None, config, scenarios_config)
        overrides = NO_RESERVE if no_reserve else None
        settings = {"refine": not no_refine, "closed_loop_overrides": overrides}
        if scene is not None:
            _plan_one(scene, files, settings, as_json, out)
            return
        from parknss.sim.planner import plan_grid, plan_grid_table

        rows = plan_grid(
            grid, files=files, executor=executor, workers=workers, address=address, **settings
        )
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            (out / f"plan_grid_{grid}.json").write_text(json.dumps(rows, indent=2))
        typer.echo(json.dumps(rows, indent=2) if as_json else plan_grid_table(rows))


def _plan_one(spec: str, files, settings: dict, as_json: bool, out: Path | None) -> None:
    from parknss.report.plan_figure import draw_plan
    from parknss.sim.planner import plan_named_scene

    scene, plan = plan_named_scene(spec, files, **settings)
    summary = plan.to_json(scene)
    folder = out or Path("runs/plan")
    png = folder / f"plan_{scene.meta.name}.png"
    summary["figure"] = str(draw_plan(scene, png, coarse=plan.coarse, refined=plan.refinement))
    if out is not None:
        (out / f"plan_{scene.meta.name}.json").write_text(json.dumps(summary, indent=2))
    _log(f"drew {summary['figure']}")
    if as_json:
        typer.echo(json.dumps(summary, indent=2))
    else:
        for key, value in summary.items():
            typer.echo(f"{key:>24}: {value}")
