"""``parknss fidelity``: the learned chain against the truth (the reference vehicle) in
closed loop, cell by cell, on the same plans (:mod:`parknss.experiments.fidelity`).
Writes a run folder (``--out``; resumable cell by cell; refused if it holds anything but
the same run unless ``--overwrite``)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from parknss.commands.simulate import (
    ADDRESS,
    CONFIG,
    EXECUTOR,
    INTERFACE,
    JSON,
    OVERWRITE,
    PLANNING,
    SCENARIOS,
    VEHICLE,
    WORKERS,
)


def register(app: typer.Typer) -> None:
    @app.command("fidelity", short_help="The chain against the truth in closed loop.")
    def fidelity(
        grid: str | None = typer.Option(None, "--grid", help="36, 12 or 252."),
        cells: str | None = typer.Option(None, "--cells", help="Grid subset, e.g. 0-5,9."),
        tpcap: Path | None = typer.Option(
            None, "--tpcap", help="Folder of TPCAP Case<N>.csv files (every case)."
        ),
        scene: list[str] | None = typer.Option(
            None, "--scene", help="A scene (file, cell, robust:N); repeat for more."
        ),
        fidelity_config: Path | None = typer.Option(
            None, "--fidelity-config", help="Seeds and targets (configs/fidelity.yaml)."
        ),
        candidate: str = typer.Option(
            "chain",
            "--candidate",
            help=(
                "chain; reference: the truth under another noise seed (the ceiling); nss "
                "or actuators: diagnosis hybrids (truth actuators + the chain's NSS, the "
                "chain's actuators + the truth's body)."
            ),
        ),
        no_figures: bool = typer.Option(False, "--no-figures", help="Skip the cell figures."),
        workers: int = WORKERS,
        executor: str = EXECUTOR,
        address: str | None = ADDRESS,
        as_json: bool = JSON,
        out: Path = typer.Option(Path("runs/fidelity"), "--out", help="Run folder."),
        overwrite: bool = OVERWRITE,
        config: Path | None = CONFIG,
        interface: Path | None = INTERFACE,
        planning_config: Path | None = PLANNING,
        scenarios_config: Path | None = SCENARIOS,
        vehicle: Path | None = VEHICLE,
    ) -> None:
        """Drive the same plans under the chain and the truth; score the chain's fidelity."""
        from parknss.experiments.fidelity import fidelity_specs, run_fidelity
        from parknss.sim.closed_loop import SimConfigFiles

        files = SimConfigFiles(config, interface, planning_config, scenarios_config, vehicle)
        specs = fidelity_specs(grid, cells, tpcap, scene)
        label = f"grid {grid}" if grid else f"TPCAP {tpcap}" if tpcap else "scenes"
        label += {"chain": "", "reference": " (reference, ceiling)"}.get(
            candidate, f" ({candidate} hybrid)"
        )
        doc = run_fidelity(
            specs, out, label=label, files=files, fidelity_config=fidelity_config,
            figures=not no_figures, candidate=candidate, executor=executor, workers=workers,
            address=address, overwrite=overwrite,
        )  # fmt: skip
        if as_json:
            return typer.echo(json.dumps(doc, indent=2))
        typer.echo(doc["text"])
        typer.echo(
            f"wall {doc['wall_s']:.1f} s with {workers} worker(s); report "
            f"{doc['files']['fidelity.html']}"
        )
