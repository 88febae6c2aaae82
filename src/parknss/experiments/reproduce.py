"""``parknss reproduce`` as one library call: run artefacts, write the HTML report.

:func:`reproduce` runs the chosen artefacts of :mod:`parknss.experiments.artefacts` (all,
or one by name) with one :class:`~parknss.experiments.results.RunContext` (budget,
executor settings, campaign, config, result cache in ``<out>/cache``), writes the
self-contained ``report.html`` with each paper finding beside what was measured, and
``run.json``, the run summary it returns.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from parknss.experiments.registry import artefacts, get, git_revision
from parknss.experiments.results import RunContext
from parknss.nss.config import NSSConfig
from parknss.report.html import write_report


@dataclass(frozen=True, kw_only=True)
class ReproduceInputs:
    """Artefact ``name`` (or "all"), the ``quick`` budget, the executor settings, the
    campaign ``data`` (None: default), the run folder ``out`` (None:
    ``runs/reproduce-<UTC stamp>``) and the studies' YAML ``config`` (None: shipped)."""

    name: str = "all"
    quick: bool = False
    executor: str = "local"
    workers: int | None = None
    address: str | None = None
    data: Path | None = None
    out: Path | None = None
    config: Path | None = None


def artefact_list() -> str:
    """One line per artefact: name, title, paper reference."""
    return "\n".join(f"{a.name:16s} {a.title} ({a.paper_ref})" for a in artefacts().values())


def _quiet(msg: str) -> None:
    pass


def reproduce(inputs: ReproduceInputs, log: Callable[[str], None] = _quiet) -> dict:
    """Run the artefacts and write the report; the run summary (also ``run.json``)."""
    arts = artefacts()
    chosen = list(arts.values()) if inputs.name == "all" else [get(inputs.name)]
    stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S")
    quick = inputs.quick
    out = inputs.out or Path("runs") / f"reproduce-{stamp}{'-quick' if quick else ''}"
    out.mkdir(parents=True, exist_ok=True)
    ctx = RunContext(
        out_dir=out,
        quick=quick,
        executor=inputs.executor,
        workers=inputs.workers,
        address=inputs.address,
        data=inputs.data,
        cache_dir=out / "cache",
        config=inputs.config,
    )
    sections = []
    for art in chosen:
        log(f"[reproduce] {art.name}: {art.title}")
        t0 = time.perf_counter()
        res = art.make(ctx)
        res.wall_s = time.perf_counter() - t0
        sections.append((art, res))
    meta = {
        "artefacts": [a.name for a, _ in sections],
        "quick": quick,
        "executor": inputs.executor,
        "workers": inputs.workers,
        "data": str(inputs.data or "bundled"),
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
    return summary
