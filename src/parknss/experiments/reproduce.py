"""``parknss reproduce`` as one library call: run artefacts, write the HTML report.

:func:`reproduce` runs the chosen artefacts of :mod:`parknss.experiments.artefacts` (all,
or one by name) with one :class:`~parknss.experiments.results.RunContext` (budget,
executor settings, campaign, config, result cache in ``<out>/cache``), writes the
self-contained ``report.html`` with each paper finding beside what was measured, and
the run summary it returns into the run folder's manifest ``run.json``. The run folder is
claimed through :func:`parknss.outputs.run_folder`: the same artefacts, budget, campaign
and config resume it (the cache is reused), anything else is refused unless
``overwrite``.

A ``quick`` run (a few epochs of a tiny net) is a smoke test: its report says so at the
top and every finding's verdict is "smoke test", never agrees / differs / within noise.

Fits are looked up in the run folder's cache, then in the result store
(:mod:`parknss.experiments.store`; ``store``: a folder or ``off``, default the checkout's
``results/``), and only the missing ones are fitted and recorded in both, so a study runs
across several sittings and a report is rebuilt from the store without refitting.
``refit`` ignores the store's results (and still records the new fits); a quick run reads
the store but does not write it. The summary's ``sources`` says, per artefact, how many
fits came from the run cache, from the store and were fitted.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from parknss.errors import MissingResultsError
from parknss.executor import Tally
from parknss.experiments.folds import fold_config
from parknss.experiments.registry import artefacts, get
from parknss.experiments.results import NOT_MEASURED, ArtefactResult, Finding, RunContext
from parknss.experiments.store import open_store
from parknss.nss.config import NSSConfig
from parknss.outputs import git_revision, keep_on_interrupt, run_folder
from parknss.report.html import write_report


@dataclass(frozen=True, kw_only=True)
class ReproduceInputs:
    """Artefact ``name`` (or "all"), the ``quick`` budget, the executor settings, the
    campaign ``data`` (None: default), the run folder ``out`` (None:
    ``runs/reproduce-<UTC stamp>``), the studies' YAML ``config`` (None: shipped),
    whether an ``out`` holding something else may be replaced (``overwrite``), the result
    ``store`` (a folder or "off"; None: $PARKNSS_RESULTS, else the config's ``store.dir``)
    and whether to ``refit`` what the store holds."""

    name: str = "all"
    quick: bool = False
    executor: str = "local"
    workers: int | None = None
    address: str | None = None
    data: Path | None = None
    out: Path | None = None
    config: Path | None = None
    overwrite: bool = False
    store: str | None = None
    stored_only: bool = False
    refit: bool = False


def artefact_list() -> str:
    """One line per artefact: name, title, paper reference."""
    return "\n".join(f"{a.name:16s} {a.title} ({a.paper_ref})" for a in artefacts().values())


def _quiet(msg: str) -> None:
    pass


def not_measured(title: str, exc: MissingResultsError) -> ArtefactResult:
    """An artefact a ``--stored-only`` run cannot build: no tables, one finding row
    "not measured" saying how many of its fits the store lacks."""
    what = f"{len(exc.missing)} of {exc.total} fits of '{exc.desc}' are not in the store"
    return ArtefactResult(notes=f"Not measured: {what}.",
                          findings=[Finding(title, what, None, NOT_MEASURED)])


def reproduce(inputs: ReproduceInputs, log: Callable[[str], None] = _quiet) -> dict:
    """Run the artefacts and write the report; the run summary (also ``run.json``)."""
    arts = artefacts()
    chosen = list(arts.values()) if inputs.name == "all" else [get(inputs.name)]
    stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S")
    quick = inputs.quick
    out = inputs.out or Path("runs") / f"reproduce-{stamp}{'-quick' if quick else ''}"
    ctx = RunContext(
        out_dir=out,
        quick=quick,
        executor=inputs.executor,
        workers=inputs.workers,
        address=inputs.address,
        data=inputs.data,
        cache_dir=out / "cache",
        config=inputs.config,
        log=log,
    )
    ctx.store = open_store(inputs.store, ctx.experiments_config(), quick, inputs.refit,
                           stored_only=inputs.stored_only)
    identity = {
        "artefacts": [a.name for a in chosen],
        "quick": quick,
        "data": inputs.data,
        "config": inputs.config,
        "experiments_config": ctx.experiments_config().digest(),
        "nss_config": fold_config(None, None).digest(),
    }
    with run_folder(out, command="parknss reproduce", args=identity,
                    overwrite=inputs.overwrite) as run:
        summary = _run(ctx, chosen, stamp, inputs, log)
        run.manifest.update(summary)  # run.json: the manifest and the run summary
    return summary


def partial_line(art_name: str, done: int, total: int, t: Tally, stored: bool) -> str:
    """What an interrupted run kept, in one line: the artefacts finished, the jobs of
    the interrupted one that finished (each kept in the run cache and, with a store,
    the result store)."""
    where = "the run cache and the result store" if stored else "the run cache"
    return (f"interrupted during {art_name}: {done} of {total} artefacts finished; "
            f"{t.total} of {t.planned} of its jobs (fits, cells) finished and kept in {where}")


def _run(ctx: RunContext, chosen, stamp: str, inputs: ReproduceInputs, log) -> dict:
    out = ctx.out_dir
    sections: list = []
    sources: dict[str, dict[str, int]] = {}
    for art in chosen:
        log(f"[reproduce] {art.name}: {art.title}")
        t0 = time.perf_counter()
        ctx.tally = Tally()
        def line(name: str = art.name) -> str:
            return partial_line(name, len(sections), len(chosen), ctx.tally,
                                ctx.store is not None and ctx.store.write)

        try:
            with keep_on_interrupt(lambda: f"{line()}; partial report {out / 'report.html'}; "
                                   "run the same command again to resume"):
                res = art.make(ctx)
        except MissingResultsError as exc:  # --stored-only: say what is missing, fit nothing
            res = not_measured(art.title, exc)
            log(f"[reproduce] {art.name}: not measured ({exc})")
        except KeyboardInterrupt:  # SIGINT/SIGTERM: a partial report, then stop (exit 130/143)
            _write(ctx, sections, sources, stamp, inputs, partial=line())
            raise
        res.wall_s = time.perf_counter() - t0
        t = ctx.tally
        sources[art.name] = {"run_cache": t.cache, "store": t.store, "fitted": t.computed}
        if t.total:
            log(f"[reproduce] {art.name}: {t.total} fits: {t.cache} from the run cache, "
                f"{t.store} from the store, {t.computed} fitted")
        if ctx.quick:  # a smoke test supports no verdict (module doc)
            res.findings = [f.smoke_test() for f in res.findings]
        sections.append((art, res))
    return _write(ctx, sections, sources, stamp, inputs)


def _write(ctx: RunContext, sections: list, sources: dict, stamp: str,
           inputs: ReproduceInputs, partial: str | None = None) -> dict:
    """Write ``report.html`` of the finished ``sections`` (``partial``: the line saying
    where an interrupted run stopped, shown at the top); the run summary."""
    out, quick = ctx.out_dir, ctx.quick
    meta = {
        "artefacts": [a.name for a, _ in sections],
        "quick": quick,
        "executor": inputs.executor,
        "workers": inputs.workers,
        "data": str(inputs.data or "bundled"),
        "git_revision": git_revision(),
        "created_utc": stamp,
        "store": str(ctx.store.root) if ctx.store else None,
        "store_writes": bool(ctx.store and ctx.store.write),
        "refit": inputs.refit,
        "sources": sources,
        "partial": partial,
        "config": {
            "experiments": ctx.experiments_config().model_dump(mode="json"),
            "budget": "quick" if quick else "full",
            "nss_base": NSSConfig().model_dump(mode="json"),
        },
    }
    report = write_report(out / "report.html", "parknss reproduction report", sections, meta)
    return {
        "report": str(report),
        **meta,
        "wall_s": {a.name: round(r.wall_s, 2) for a, r in sections},
        "verdicts": {f.claim: f.verdict for _, r in sections for f in r.findings},
        "files": sorted(
            str(p.relative_to(out))
            for p in out.rglob("*")
            if p.is_file() and "cache" not in p.parts
        ),
    }
