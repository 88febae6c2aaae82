"""``parknss simulate`` (one scene, Figs. 8/9: :mod:`parknss.experiments.scenes`), ``grid``
(Table V: :mod:`parknss.sim.grid`) and ``tune`` (interface gains: :mod:`parknss.sim.tuning`);
grid and tune fan out through the one executor (``--executor local|ray``). Each writes a
run folder (``--out``) refused if it holds anything but the same run unless
``--overwrite`` (:func:`parknss.outputs.run_folder`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import typer

if TYPE_CHECKING:
    from parknss.sim.closed_loop import SimConfigFiles

CONFIG = typer.Option(None, "--config", help="Closed-loop YAML (configs/closed_loop.yaml).")
INTERFACE = typer.Option(None, "--interface", help="Interface gains YAML.")
PLANNING = typer.Option(None, "--planning-config", help="Planning YAML.")
SCENARIOS = typer.Option(None, "--scenarios-config", help="Scenarios YAML.")
VEHICLE = typer.Option(
    None, "--vehicle", help="Vehicle YAML (default: the chain's car; e.g. "
    "configs/tpcap_vehicle.yaml for the TPCAP benchmark's car)."
)
EXECUTOR = typer.Option("local", "--executor", help="local (loky pool) or ray.")
ADDRESS = typer.Option(None, "--address", help="Ray cluster address (--executor ray).")
WORKERS = typer.Option(1, "--workers", help="Parallel workers.")
JSON = typer.Option(False, "--json", help="Print one JSON document.")
OVERWRITE = typer.Option(
    False, "--overwrite", help="Replace what --out holds (another run, an artefact)."
)


def _files(*paths: Path | None) -> SimConfigFiles:
    from parknss.sim.closed_loop import SimConfigFiles

    return SimConfigFiles(*paths)


def register(app: typer.Typer) -> None:
    @app.command("simulate", short_help="One planned scene in closed loop (Figs. 8, 9).")
    def simulate(
        scene: str = typer.Option(
            ..., "--scene", help="Scene JSON, TPCAP .csv, CommonRoad .xml, cell 0-35, robust:N."
        ),
        plant: str = typer.Option("kinematic", "--plant", help="kinematic, chain or reference."),
        compare: str | None = typer.Option(
            None, "--compare", help="Plants on the same plan, e.g. kinematic,reference."
        ),
        as_json: bool = JSON,
        out: Path | None = typer.Option(
            None, "--out", help="Run folder (default runs/simulate/<scene>)."
        ),
        overwrite: bool = OVERWRITE,
        series: bool = typer.Option(False, "--series", help="Also write time-series CSVs."),
        config: Path | None = CONFIG,
        interface: Path | None = INTERFACE,
        planning_config: Path | None = PLANNING,
        scenarios_config: Path | None = SCENARIOS,
        vehicle: Path | None = VEHICLE,
    ) -> None:
        """Execute one planned scene in closed loop; draw Fig. 8 and Fig. 9."""
        from parknss.experiments.scenes import simulate_one
        from parknss.sim.plants import parse_plants
        from parknss.sim.session import summary_text

        plants = parse_plants(plant if compare is None else f"{plant},{compare}")
        files = _files(config, interface, planning_config, scenarios_config, vehicle)
        doc = simulate_one(scene, plants, files, out=out, series=series, overwrite=overwrite)
        typer.echo(json.dumps(doc, indent=2) if as_json else summary_text(doc))

    @app.command("grid", short_help="A scenario grid in closed loop (Table V).")
    def grid(
        grid: str = typer.Option("36", "--grid", help="36, 12 (tuning core) or 252."),
        plants: str = typer.Option("kinematic,reference", "--plants", help="Comma list."),
        cells: str | None = typer.Option(None, "--cells", help="Subset, e.g. 0-5,9."),
        workers: int = WORKERS,
        executor: str = EXECUTOR,
        address: str | None = ADDRESS,
        as_json: bool = JSON,
        out: Path = typer.Option(Path("runs/grid"), "--out", help="CSV/JSON folder."),
        overwrite: bool = OVERWRITE,
        config: Path | None = CONFIG,
        interface: Path | None = INTERFACE,
        planning_config: Path | None = PLANNING,
        scenarios_config: Path | None = SCENARIOS,
        vehicle: Path | None = VEHICLE,
    ) -> None:
        """Run a scenario grid in closed loop under several plants; print Table V."""
        from parknss.sim.grid import run_grid_report, table_v
        from parknss.sim.plants import parse_plants

        files = _files(config, interface, planning_config, scenarios_config, vehicle)
        doc = run_grid_report(
            grid, parse_plants(plants), out, cells=cells, files=files,
            executor=executor, workers=workers, address=address, overwrite=overwrite,
        )  # fmt: skip
        if as_json:
            return typer.echo(json.dumps(doc, indent=2))
        typer.echo(table_v(doc["summary"], doc.get("heldout")))
        typer.echo(
            f"wall {doc['wall_s']:.1f} s with {workers} worker(s); simulated {doc['sim_s']:.0f} s"
            f" (x{doc['realtime_factor_wall']} real time overall); CSV {doc['csv']}"
        )

    @app.command("tune", short_help="Tune the interface gains on the 12-cell core.")
    def tune(
        plant: str | None = typer.Option(None, "--plant", help="Default: chain, else reference."),
        workers: int = WORKERS,
        executor: str = EXECUTOR,
        address: str | None = ADDRESS,
        rounds: int | None = typer.Option(None, "--rounds", help="Descent rounds."),
        as_json: bool = JSON,
        out: Path = typer.Option(Path("runs/tune"), "--out", help="Output folder."),
        overwrite: bool = OVERWRITE,
        config: Path | None = CONFIG,
        interface: Path | None = INTERFACE,
        planning_config: Path | None = PLANNING,
        scenarios_config: Path | None = SCENARIOS,
        vehicle: Path | None = VEHICLE,
    ) -> None:
        """Tune the interface gains on the 12-cell core; write interface_tuned.yaml."""
        from parknss.sim.tuning import tune_gains

        files = _files(config, interface, planning_config, scenarios_config, vehicle)
        doc = tune_gains(
            plant, out, rounds=rounds, files=files, executor=executor, workers=workers,
            address=address, log=lambda m: typer.echo(f"[sim] {m}", err=True),
            overwrite=overwrite,
        )  # fmt: skip
        if as_json:
            return typer.echo(json.dumps(doc, indent=2))
        typer.echo(
            f"plant {doc['plant']}: objective {doc['initial_objective']:.3f} -> "
            f"{doc['objective']:.3f} in {doc['evaluations']} evaluations"
        )
        for k, v in doc["gains"].items():
            typer.echo(f"  {k} = {v:.4g}")
        typer.echo(f"wrote {doc['yaml']}")
