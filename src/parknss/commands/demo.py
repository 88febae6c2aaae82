"""``parknss demo``: the main job on the bundled synthetic campaign and the shipped plant.

Describes the campaign, evaluates and rates the shipped NSS and chain, parks one grid cell
through the kinematic plant and the deployed plant (models/plant), and writes every figure and
``summary.json`` to ``--out`` (:func:`parknss.experiments.demo.run_demo`), a run folder
refused if it holds anything but the same demo unless ``--overwrite``. ``--json`` prints
the summary document (what ``summary.json`` holds) on stdout, the tables and progress on
stderr.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer


def _log(msg: str) -> None:
    typer.echo(f"[demo] {msg}", err=True)


def register(app: typer.Typer) -> None:
    @app.command("demo", short_help="Describe, evaluate, rate and park the shipped plant.")
    def demo(
        out: Path = typer.Option(Path("runs/demo"), "--out", help="Run folder."),
        data: Path | None = typer.Option(
            None, "--data", help="Campaign folder (default: the bundled synthetic campaign)."
        ),
        cell: int = typer.Option(26, "--cell", help="Grid cell (0-35) to park in closed loop."),
        nss: Path | None = typer.Option(
            None, "--nss", help="NSS model folder (default: the shipped one, models/nss)."
        ),
        chain: Path | None = typer.Option(
            None, "--chain", help="Chain artefact folder (default: the shipped models/chain)."
        ),
        overwrite: bool = typer.Option(
            False, "--overwrite", help="Replace what --out holds (another run, an artefact)."
        ),
        as_json: bool = typer.Option(False, "--json", help="Print the summary as one JSON "
                                     "document (tables and progress on stderr)."),
    ) -> None:
        """Describe the campaign, evaluate and rate the shipped plant, park through it."""
        from parknss.experiments.demo import DemoInputs, run_demo, summary_text

        shipped = {"nss": nss, "chain": chain}  # None: DemoInputs' shipped default
        inputs = DemoInputs(out=out, data=data, cell=cell, overwrite=overwrite,
                            **{k: v for k, v in shipped.items() if v is not None})
        doc = run_demo(inputs, _log, _log if as_json else typer.echo)
        typer.echo(json.dumps(doc, indent=2) if as_json else summary_text(doc))
        _log(f"done in {doc['wall_s']} s: artefacts in {out} (summary.json, PNG figures)")
