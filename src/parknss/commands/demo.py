"""``parknss demo``: the main job on the bundled synthetic campaign and the shipped plant."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from parknss.config import BUNDLED_CAMPAIGN


def _log(msg: str) -> None:
    typer.echo(f"[demo] {msg}", err=True)


def register(app: typer.Typer) -> None:
    @app.command("demo")
    def demo(
        out: Path = typer.Option(Path("runs/demo"), "--out", help="Run folder."),
        data: Path | None = typer.Option(
            None, "--data", help="Campaign folder (default: the bundled synthetic campaign)."
        ),
    ) -> None:
        """Describe the campaign, draw a trial, evaluate the shipped plant, park through it."""
        from parknss.data.describe import describe_campaign
        from parknss.data.io import read_campaign
        from parknss.report.trial_figure import draw_trial

        out.mkdir(parents=True, exist_ok=True)
        src = data or BUNDLED_CAMPAIGN
        _log(f"campaign: {src} (synthetic reference vehicle unless you gave --data)")
        campaign = read_campaign(src)
        summary = describe_campaign(campaign)
        typer.echo(summary.table())
        (out / "campaign_summary.json").write_text(json.dumps(summary.to_json(), indent=2))
        fig = draw_trial(campaign[0], out / "trial.png")
        _log(f"drew {campaign[0].id} to {fig}")
        _log(f"done: artefacts in {out}")
