"""``parknss reproduce``: run the paper's tables and figures and write an HTML report."""

from __future__ import annotations

import json
import time
from datetime import UTC, datetime
from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    @app.command("reproduce")
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
        as_json: bool = typer.Option(False, "--json", help="Print the run summary as JSON."),
    ) -> None:
        """Reproduce the paper's tables and figures (on the synthetic campaign by default)."""
        from parknss.experiments.registry import RunContext, artefacts, get, git_revision
        from parknss.nss.config import NSSConfig
        from parknss.report.html import write_report

        arts = artefacts()
        if list_:
            for art in arts.values():
                typer.echo(f"{art.name:16s} {art.title} ({art.paper_ref})")
            return
        chosen = list(arts.values()) if name == "all" else [get(name)]
        stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S")
        out = out or Path("runs") / f"reproduce-{stamp}{'-quick' if quick else ''}"
        out.mkdir(parents=True, exist_ok=True)
        ctx = RunContext(
            out_dir=out,
            quick=quick,
            executor=executor,
            workers=workers,
            address=address,
            data=data,
            cache_dir=out / "cache",
            config=config,
        )
        sections = []
        for art in chosen:
            typer.echo(f"[reproduce] {art.name}: {art.title}", err=True)
            t0 = time.perf_counter()
            res = art.make(ctx)
            res.wall_s = time.perf_counter() - t0
            sections.append((art, res))
        meta = {
            "artefacts": [a.name for a, _ in sections],
            "quick": quick,
            "executor": executor,
            "workers": workers,
            "data": str(data or "bundled"),
            "git_revision": git_revision(),
            "created_utc": stamp,
            "config": {
                "experiments": ctx.experiments_config().model_dump(mode="json"),
                "budget": "quick" if quick else "full",
                "nss_base": NSSConfig().model_dump(mode="json"),
            },
        }
        report = write_report(out / "report.html", "parknss reproduction report", sections, meta)
        summary = {
            "report": str(report),
            **meta,
            "wall_s": {a.name: round(r.wall_s, 2) for a, r in sections},
            "files": sorted(
                str(p.relative_to(out))
                for p in out.rglob("*")
                if p.is_file() and "cache" not in p.parts
            ),
        }
        (out / "run.json").write_text(json.dumps(summary, indent=2))
        if as_json:
            typer.echo(json.dumps(summary, indent=2))
        else:
            typer.echo(f"report: {report}")
