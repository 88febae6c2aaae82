"""``parknss results list|verify|park``: what the result store holds
(:mod:`parknss.experiments.store`; ``--store DIR``, else $PARKNSS_RESULTS, else the
checkout's ``results/``). ``verify`` checks that every file parses and matches its key,
and exits non-zero, naming the first bad file, when one does not; ``park OUT`` copies the
training states of a run folder's unfinished fits into the store
(:mod:`parknss.experiments.parked`)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from parknss.errors import ParknssError


def register(app: typer.Typer) -> None:
    results_app = typer.Typer(help="The result store: list and verify stored fits, park "
                              "unfinished ones.",
                              short_help="The result store of study fits.",
                              no_args_is_help=True)
    app.add_typer(results_app, name="results")
    store_opt = typer.Option(None, "--store", help="Result store folder (default: results/).")
    config_opt = typer.Option(None, "--config", help="Experiments YAML (its store.dir).")
    from parknss.commands.results_lineage import add_commands

    add_commands(results_app, store_opt, config_opt)

    @results_app.command("list", short_help="One line per stored fit.")
    def list_cmd(
        store: str | None = store_opt,
        config: Path | None = config_opt,
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
    ) -> None:
        """One line per stored fit: key, name, data hash, code version, revision, times."""
        from parknss.experiments import parked
        from parknss.experiments.lineage import accepted_versions, describe
        from parknss.experiments.store import code_version, listing, results_root

        root = results_root(store, config)
        rows, bad = listing(root)
        held, bad_held = parked.listing(root)
        bad += bad_held
        if as_json:
            doc = {"store": str(root), "code_version": code_version(), "entries": rows,
                   "accepted_versions": accepted_versions(root, code_version()),
                   "parked": held, "invalid": bad}
            typer.echo(json.dumps(doc, indent=2))
            return
        for line in rows + held + [f"INVALID {b}" for b in bad]:
            typer.echo(line)
        typer.echo(f"{len(rows)} fits in {root}, {len(held)} unfinished parked; "
                   f"{describe(root, code_version())}"
                   + (f"; {len(bad)} invalid files (parknss results verify)" if bad else ""))

    @results_app.command("verify", short_help="Check every stored file and parked state.")
    def verify_cmd(store: str | None = store_opt, config: Path | None = config_opt) -> None:
        """Check every stored file: it parses, its key matches its contents and path, its
        content matches its digest; every parked state reads whole and sits under its own
        key; the lineage reads."""
        from parknss.experiments import parked
        from parknss.experiments.lineage import describe, read_lineage
        from parknss.experiments.store import code_version, listing, results_root

        root = results_root(store, config)
        read_lineage(root)
        rows, bad = listing(root)
        held, bad_held = parked.listing(root)
        bad += bad_held
        for b in bad:
            typer.echo(f"INVALID {b}")
        if bad:
            raise ParknssError(f"{len(bad)} of {len(rows) + len(held) + len(bad)} files in "
                               f"{root} are not valid store entries or parked states, first: "
                               f"{bad[0]}")
        typer.echo(f"{len(rows)} fits and {len(held)} parked states in {root}: all valid; "
                   f"{describe(root, code_version())}")
        dirty = sum("+dirty (" in r for r in rows)
        if dirty:
            same = sum("+dirty (code as committed)" in r for r in rows)
            typer.echo(f"{dirty} entries were made from a dirty tree; {same} of them with the "
                       "code (CODE_FILES, or a derived job's code) as committed at their revision")
        stale = sum(" stale " in r for r in rows)
        if stale:
            typer.echo(f"{stale} fits are of a code version not accepted here (stale): "
                       "parknss results migrate checks whether this code computes their numbers")

    @results_app.command("park", short_help="Copy unfinished fits' states into the store.")
    def park_cmd(
        out: Path = typer.Argument(..., help="A parknss reproduce or study run folder."),
        store: str | None = store_opt,
        config: Path | None = config_opt,
    ) -> None:
        """Copy the training state of each unfinished fit of run folder OUT into the store
        (inflight/<key>/), so a later sitting resumes it; commit it with the store."""
        from parknss.experiments.parked import park_run
        from parknss.experiments.store import results_root

        root = results_root(store, config)
        outcomes = park_run(out, root)
        for o in outcomes:
            typer.echo(o.line())
        n = sum(o.parked is not None for o in outcomes)
        typer.echo(f"{n} of {len(outcomes)} state folders parked in {root}")

