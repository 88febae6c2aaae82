"""``parknss results canary|migrate|seal``: the store's lineage and content digests
(:mod:`parknss.experiments.canary`, :mod:`parknss.experiments.lineage`). ``canary``
runs the canary under this checkout's training code and prints its digest (``--record``
records it for this code version); ``migrate`` runs it and records this code version
equivalent to every version whose canary on this CPU model had the same digest, so the
store keeps their fits; ``seal`` adds a content digest to entries stored without one."""

from __future__ import annotations

from pathlib import Path

import typer

from parknss.errors import ParknssError


def add_commands(results_app: typer.Typer, store_opt, config_opt) -> None:
    @results_app.command("canary", short_help="Run the canary fits; print their digest.")
    def canary_cmd(
        store: str | None = store_opt,
        config: Path | None = config_opt,
        record: bool = typer.Option(False, "--record", help="Record the digest for this "
                                    "code version and machine in <store>/lineage/."),
    ) -> None:
        """Run the canary (tiny fits down every training code path) and print its digest."""
        from parknss.experiments.canary import run_canary
        from parknss.experiments.lineage import (
            VersionRecord,
            add_canary,
            canary_record,
            read_lineage,
            write_record,
        )
        from parknss.experiments.store import Machine, code_version, results_root

        root = results_root(store, config)
        res = run_canary()
        can = canary_record(res, Machine.here())
        version = code_version()
        for name, d in res.cases.items():
            typer.echo(f"  {name:40s} {d}")
        typer.echo(f"canary digest {res.digest} (spec {res.spec}) of code version {version} "
                   f"on {can.cpu}: {res.seconds:.1f} s")
        records = read_lineage(root)
        same = [(v, c) for v, r in records.items() for c in r.canaries
                if c.cpu == can.cpu and c.spec == can.spec]
        for v, c in same:
            verdict = "equal" if c.digest == res.digest else "differs"
            typer.echo(f"  recorded for {v}{' (this version)' if v == version else ''}: "
                       f"{c.digest} {verdict}")
        if record:
            rec = records.get(version) or VersionRecord(version)
            add_canary(rec, can)
            typer.echo(f"recorded in {write_record(root, rec)}")

    @results_app.command("migrate", short_help="Keep older fits when the canary matches.")
    def migrate_cmd(store: str | None = store_opt, config: Path | None = config_opt) -> None:
        """Run the canary under this code; where it equals an older version's on this CPU
        model, record this version equivalent to it (the store then keeps its fits)."""
        from parknss.experiments.canary import run_canary
        from parknss.experiments.lineage import canary_record, migrate
        from parknss.experiments.store import Machine, code_version, results_root

        root = results_root(store, config)
        m = migrate(root, code_version(), canary_record(run_canary(), Machine.here()))
        for line in m.lines():
            typer.echo(line)
        if m.differs and not m.equivalent:
            raise ParknssError(f"the canary of code {m.version} differs from every recorded "
                               "one on this CPU: this code changes the numbers, the stored "
                               "fits of other versions stay stale (recorded in lineage/)")

    @results_app.command("seal", short_help="Digest entries stored without one.")
    def seal_cmd(store: str | None = store_opt, config: Path | None = config_opt) -> None:
        """Add a content digest to every entry stored without one (once, for old stores)."""
        from parknss.experiments.store import results_root, seal

        root = results_root(store, config)
        done, already = seal(root)
        typer.echo(f"{done} entries sealed, {already} already had a digest, in {root}")
