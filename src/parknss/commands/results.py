"""``parknss results list|verify``: what the result store holds
(:mod:`parknss.experiments.store`; ``--store DIR``, else $PARKNSS_RESULTS, else the
checkout's ``results/``). ``verify`` checks that every file parses and matches its key,
and exits non-zero, naming the first bad file, when one does not."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from parknss.errors import ParknssError


def register(app: typer.Typer) -> None:
    results_app = typer.Typer(help="The result store: list and verify stored fits.",
                              no_args_is_help=True)
    app.add_typer(results_app, name="results")
    store_opt = typer.Option(None, "--store", help="Result store folder (default: results/).")
    config_opt = typer.Option(None, "--config", help="Experiments YAML (its store.dir).")

    @results_app.command("list")
    def list_cmd(
        store: str | None = store_opt,
        config: Path | None = config_opt,
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
    ) -> None:
        """One line per stored fit: key, name, data hash, code version, revision, times."""
        from parknss.experiments.store import code_version, listing, results_root

        root = results_root(store, config)
        rows, bad = listing(root)
        if as_json:
            doc = {"store": str(root), "code_version": code_version(), "entries": rows,
                   "invalid": bad}
            typer.echo(json.dumps(doc, indent=2))
            return
        for line in rows + [f"INVALID {b}" for b in bad]:
            typer.echo(line)
        typer.echo(f"{len(rows)} fits in {root} (code version here: {code_version()})"
                   + (f"; {len(bad)} invalid files (parknss results verify)" if bad else ""))

    @results_app.command("verify")
    def verify_cmd(store: str | None = store_opt, config: Path | None = config_opt) -> None:
        """Check every stored file: it parses and its key matches its contents and path."""
        from parknss.experiments.store import listing, results_root

        root = results_root(store, config)
        rows, bad = listing(root)
        for b in bad:
            typer.echo(f"INVALID {b}")
        if bad:
            raise ParknssError(f"{len(bad)} of {len(rows) + len(bad)} files in {root} are not "
                               f"valid store entries, first: {bad[0]}")
        typer.echo(f"{len(rows)} fits in {root}: all valid")
