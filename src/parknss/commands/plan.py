"""``parknss plan``: plan one parking scene or a whole scenario grid.

``parknss plan --scene FILE|CELL`` plans one scene (a scene JSON file, a TPCAP case CSV,
a CommonRoad XML scenario, a grid cell 0-35, or ``robust:N`` for robustness cell 0-251;
an imported scene is also written as scene JSON beside the figure) for the car of
``--vehicle`` (default: the car the shipped chain was identified on) exactly as
``parknss simulate`` will drive it (:func:`parknss.sim.planner.plan_scene`: the
closed-loop config's steering reserve and margin), draws it to an SVG (not with
``--no-figure``) and prints a summary (or one JSON object). ``--no-reserve`` plans as the
planner alone instead (full steering lock, planning.yaml's margin): a plan that no other
command drives.
``parknss plan --grid 36`` (``12``: the tuning core, ``252``: the robustness grid) plans
every cell through the one executor and prints a table (or one JSON list). The figure
goes to ``--out`` (default ``runs/plan/<scene>``), a run folder refused if it holds
anything but the same plan unless ``--overwrite`` (:mod:`parknss.experiments.scenes`).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from parknss.errors import PlanningError


def _log(msg: str) -> None:
    typer.echo(f"[plan] {msg}", err=True)


def register(app: typer.Typer) -> None:
    @app.command("plan", short_help="Plan one parking scene or a scenario grid.")
    def plan(
        scene: str | None = typer.Option(
            None, "--scene", help="Scene JSON, TPCAP .csv, CommonRoad .xml, cell 0-35, robust:N."
        ),
        problem: str | None = typer.Option(
            None, "--problem", help="CommonRoad planning problem id (unknown id: lists them)."
        ),
        grid: str | None = typer.Option(
            None, "--grid", help="Plan a whole grid: 36 (default grid), 12 (core), 252."
        ),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
        out: Path | None = typer.Option(None, "--out", help="Folder for figures and JSON."),
        overwrite: bool = typer.Option(
            False, "--overwrite", help="Replace what --out holds (another run, an artefact)."
        ),
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
        vehicle: Path | None = typer.Option(
            None, "--vehicle", help="Vehicle YAML (default: the chain's car)."
        ),
        no_refine: bool = typer.Option(False, "--no-refine", help="Coarse path only."),
        no_figure: bool = typer.Option(
            False, "--no-figure", help="--scene: no SVG figure."
        ),
        no_reserve: bool = typer.Option(
            False, "--no-reserve", help="Full lock, planning.yaml margin: not what is driven."
        ),
    ) -> None:
        """Plan one parking scene (and draw it) or a whole scenario grid."""
        from parknss.sim.closed_loop import SimConfigFiles
        from parknss.sim.planner import NO_RESERVE

        if (scene is None) == (grid is None):
            raise PlanningError("give exactly one of --scene FILE|CELL or --grid 36|12|252")
        files = SimConfigFiles(closed_loop_config, None, config, scenarios_config, vehicle)
        overrides = NO_RESERVE if no_reserve else None
        settings = {"refine": not no_refine, "closed_loop_overrides": overrides,
                    "out": out, "overwrite": overwrite}
        if problem is not None:
            if scene is None or not scene.lower().endswith(".xml"):
                raise PlanningError("--problem needs --scene FILE.xml (a CommonRoad file)")
            scene = f"{scene}#{problem}"
        if scene is not None:
            from parknss.experiments.scenes import plan_one

            summary = plan_one(scene, files, figure=not no_figure, **settings)
            if summary["figure"]:
                _log(f"drew {summary['figure']}")
            if as_json:
                return typer.echo(json.dumps(summary, indent=2))
            for key, value in summary.items():
                typer.echo(f"{key:>24}: {value}")
            return
        from parknss.experiments.scenes import plan_grid_run
        from parknss.sim.planner import plan_grid_table

        rows = plan_grid_run(
            grid, files, executor=executor, workers=workers, address=address, **settings
        )
        typer.echo(json.dumps(rows, indent=2) if as_json else plan_grid_table(rows))
