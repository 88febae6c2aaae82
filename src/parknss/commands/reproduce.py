"""``parknss reproduce``: run the paper's tables and figures and write an HTML report
(:func:`parknss.experiments.reproduce.reproduce`) into a run folder that the same
artefacts and budget resume (cache) and that is refused, holding anything else, unless
``--overwrite``; fits are read from the result store (``--store DIR|off``) and only the
missing ones are fitted (``--refit``: all; ``--stored-only``: none, an artefact whose fits
the store lacks is reported "not measured")."""

from __future__ import annotations

import json
from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    @app.command("reproduce", short_help="The paper's tables and figures; HTML report.")
    def reproduce(
        name: str = typer.Argument("all", help="Artefact name, or 'all'."),
        list_: bool = typer.Option(False, "--list", help="List the artefacts and exit."),
        quick: bool = typer.Option(False, "--quick", help="Tiny budgets (smoke test)."),
        executor: str = typer.Option("local", "--executor", help="local | ray"),
        workers: int | None = typer.Option(None, "--workers", help="Parallel workers."),
        address: str | None = typer.Option(None, "--address", help="Ray cluster address."),
        data: Path | None = typer.Option(None, "--data", help="Campaign folder."),
        out: Path | None = typer.Option(None, "--out", help="Run folder."),
        config: Path | None = typer.Option(
            None, "--config", help="Studies YAML (default configs/experiments.yaml)."
        ),
        overwrite: bool = typer.Option(
            False, "--overwrite", help="Replace what --out holds (another run, an artefact)."
        ),
        as_json: bool = typer.Option(False, "--json", help="Print the run summary as JSON."),
        store: str | None = typer.Option(
            None, "--store", help="Result store folder or 'off' (default: results/)."
        ),
        refit: bool = typer.Option(False, "--refit", help="Refit what the store holds."),
        stored_only: bool = typer.Option(
            False, "--stored-only", help="Fit nothing: build what the store holds, mark the "
            "rest not measured."
        ),
    ) -> None:
        """Reproduce the paper's tables and figures (on the synthetic campaign by default)."""
        from parknss.experiments.reproduce import ReproduceInputs, artefact_list
        from parknss.experiments.reproduce import reproduce as run

        if list_:
            typer.echo(artefact_list())
            return
        inputs = ReproduceInputs(name=name, quick=quick, executor=executor, workers=workers,
                                 address=address, data=data, out=out, config=config,
                                 overwrite=overwrite, store=store, refit=refit,
                                 stored_only=stored_only)
        summary = run(inputs, lambda msg: typer.echo(msg, err=True))
        if as_json:
            typer.echo(json.dumps(summary, indent=2))
            return
        if summary["quick"]:
            typer.echo("smoke test (--quick): no verdict on the paper's findings")
        for claim, verdict in summary["verdicts"].items():
            typer.echo(f"  {verdict:14s} {claim}")
        typer.echo(f"report: {summary['report']}")
