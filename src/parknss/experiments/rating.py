"""``parknss rate`` as one library call: rate a source, write the files and Fig. 7.

:func:`run_rate` rates the source of a :class:`~parknss.chain.rating.RateInputs` (a model,
a chain or the truth replay, :func:`parknss.chain.rating.rate_source`) and writes
``ratings.csv``, ``ratings.json`` and the box plot ``iso_rating.png`` (Fig. 7) to ``out``.
The demo and the ``fig7`` artefact of ``parknss reproduce`` call it too.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from parknss.chain.rating import RateInputs, rate_source
from parknss.metrics.rating_report import RatingTable
from parknss.report.iso_figure import draw_iso_boxplot


def _quiet(msg: str) -> None:
    pass


@dataclass
class RatingRun:
    """A finished rating: the rating ``table`` and the JSON document written to
    ``ratings.json`` (source, config, rows, summary, files)."""

    table: RatingTable
    doc: dict


def run_rate(
    inputs: RateInputs, out: Path, progress: Callable[[str], None] = _quiet
) -> RatingRun:
    """Rate, write the CSV, JSON and figure to ``out``; the table and the document."""
    table, source = rate_source(inputs, progress)
    out.mkdir(parents=True, exist_ok=True)
    doc = {"source": source, **table.to_json()}
    doc["files"] = {
        "csv": str(table.to_csv(out / "ratings.csv")),
        "json": str(out / "ratings.json"),
        "figure": str(draw_iso_boxplot(table, out / "iso_rating.png")),
    }
    (out / "ratings.json").write_text(json.dumps(doc, indent=2))
    return RatingRun(table, doc)
