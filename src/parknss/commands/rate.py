"""``parknss rate``: ISO/TS 18571 rating of a model's predictions against a campaign.

``--model M`` rates an NSS open loop from the logged actuals, ``--chain C`` a chain
artefact (e.g. the shipped ``models/chain``) from the logged commands (the paper's Fig. 7
setting), ``--replay-truth`` a synthetic campaign's noise-free ``truth_*`` channels (the
sensor-noise ceiling); each trial's vx, yaw rate, ax and ay against the logged channel, raw
and 5 Hz filtered (:mod:`parknss.chain.rating`). Writes ``ratings.csv``, ``ratings.json``
and ``iso_rating.png`` (Fig. 7) to ``--out`` (:func:`parknss.experiments.rating.rate_run`:
a run folder refused if it holds anything but the same rating unless ``--overwrite``) and
prints the summary table, or with ``--json`` one JSON document.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer


def _log(msg: str) -> None:
    typer.echo(f"[rate] {msg}", err=True)


def register(app: typer.Typer) -> None:
    @app.command("rate", short_help="ISO/TS 18571 rating of vx, yaw rate, ax, ay.")
    def rate(
        data: Path = typer.Option(..., "--data", help="Campaign folder (campaign.json)."),
        model: Path | None = typer.Option(None, "--model", help="Model checkpoint to rate."),
        chain: Path | None = typer.Option(
            None, "--chain", help="Chain artefact to rate from the commands (models/chain)."
        ),
        replay_truth: bool = typer.Option(
            False, "--replay-truth", help="Rate the truth_* channels (sensor-noise ceiling)."
        ),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
        out: Path = typer.Option(Path("runs/rate"), "--out", help="Folder for CSV/JSON/PNG."),
        config: Path | None = typer.Option(None, "--config", help="Rating YAML (RateConfig)."),
        overwrite: bool = typer.Option(
            False, "--overwrite", help="Replace what --out holds (another run, an artefact)."
        ),
    ) -> None:
        """ISO/TS 18571 rating of vx, yaw rate, ax, ay per trial, raw and 5 Hz filtered."""
        from parknss.chain.rating import RateInputs
        from parknss.experiments.rating import rate_run

        inputs = RateInputs(data=data, model=model, chain=chain, replay_truth=replay_truth,
                            config=config)
        run = rate_run(inputs, out, overwrite=overwrite, progress=_log)
        if as_json:
            typer.echo(json.dumps(run.doc, indent=2))
        else:
            typer.echo(run.table.table())
            typer.echo(f"wrote {run.doc['files']['csv']}, {run.doc['files']['figure']}")
