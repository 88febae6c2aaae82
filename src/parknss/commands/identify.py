"""``parknss identify``: from logs to a plant and its model card in one command
(:func:`parknss.experiments.identify.pipeline.run_identify`; docs/identify.md).

``parknss identify LOGS --mapping M.yaml --out CAR`` (or ``--data CAMPAIGN``) imports and
describes the campaign (refused early in one line unless it supports every workflow),
fits the NSS (``--recipe paper|fast|coarse``; ``--nss DIR`` reuses a fitted one whose data hash
and training config match), selects and builds the actuator chain, rates it, tunes the
interface gains, runs the closed-loop grid of the car's geometry, the fidelity against
the truth where one exists, the exports, and writes CAR/model_card.html and .json. A rerun
skips finished stages whose inputs are unchanged and resumes an interrupted one.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer


def _log(msg: str) -> None:
    typer.echo(f"[identify] {msg}", err=True)


def register(app: typer.Typer) -> None:
    @app.command("identify", short_help="From logs to a plant and its model card, resumably.")
    def identify(
        logs: Path | None = typer.Argument(None, help="Folder of logs, one file per trial."),
        out: Path = typer.Option(..., "--out", help="The car folder (every stage's product)."),
        mapping: Path | None = typer.Option(None, "--mapping", help="Channel-mapping YAML."),
        data: Path | None = typer.Option(None, "--data", help="An imported campaign instead."),
        recipe: str | None = typer.Option(
            None, "--recipe", help="NSS recipe: coarse (default: coarse-step epochs, then a "
            "full-rate finish; ~1/7 the CPU of paper), paper (3200 epochs) or fast."),
        set_: list[str] = typer.Option(None, "--set", help="NSS section.field=value."),
        nss: Path | None = typer.Option(
            None, "--nss", help="Fitted NSS to reuse if its data hash and config match."),
        allow_code_change: bool = typer.Option(
            False, "--allow-code-change",
            help="Reuse --nss even if its training code is not shown equal by the lineage."),
        selection: Path | None = typer.Option(
            None, "--selection", help="selection.json or chain folder whose winners to use."),
        actuator_config: Path | None = typer.Option(
            None, "--actuator-config", help="Actuator YAML."),
        interface: Path | None = typer.Option(
            None, "--interface", help="Interface gains YAML to use instead of tuning."),
        stages: str | None = typer.Option(
            None, "--stages", help="Comma list of stages to run (default: all)."),
        skip_export: bool = typer.Option(False, "--skip-export", help="No FMU/ONNX."),
        set_identify: list[str] = typer.Option(
            None, "--identify-set", help="identify.yaml field=value (e.g. grid_cells=0-5)."),
        executor: str = typer.Option("local", "--executor", help="local | ray"),
        workers: int = typer.Option(1, "--workers", help="Parallel workers."),
        address: str | None = typer.Option(None, "--address", help="Ray cluster address."),
        overwrite: bool = typer.Option(
            False, "--overwrite", help="Replace what --out holds (another run, an artefact)."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
    ) -> None:
        """From logs to a plant and its model card: every stage, resumable."""
        from parknss.config import parse_set
        from parknss.experiments.identify.config import IdentifyInputs
        from parknss.experiments.identify.pipeline import run_identify, summary_text
        from parknss.nss.config import cli_overrides

        names = tuple(s.strip() for s in stages.split(",") if s.strip()) if stages else None
        inputs = IdentifyInputs(
            out=out, logs=logs, mapping=mapping, data=data, recipe=recipe,
            nss_overrides=cli_overrides(set_), nss=nss, allow_code_change=allow_code_change,
            selection=selection, actuator_config=actuator_config, interface=interface,
            stages=names,
            skip_export=skip_export, executor=executor, workers=workers, address=address,
            overrides=parse_set(set_identify, option="--identify-set"), overwrite=overwrite)
        doc = run_identify(inputs, _log)
        typer.echo(json.dumps(doc, indent=2, default=str) if as_json else summary_text(doc))
