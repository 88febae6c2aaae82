"""``parknss rate`` as one library call: rate a source, write the files and Fig. 7.

:func:`run_rate` rates the source of a :class:`~parknss.chain.rating.RateInputs` (a model,
a chain or the truth replay, :func:`parknss.chain.rating.rate_source`) and writes
``ratings.csv``, ``ratings.json`` and the box plot ``iso_rating.png`` (Fig. 7) to ``out``
(each file atomically). The demo and the ``fig7`` artefact of ``parknss reproduce`` call
it into a folder of their runs; ``parknss rate`` calls :func:`rate_run`, which claims
``out`` as its run folder first (:func:`parknss.outputs.run_folder`).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from parknss.chain.rating import RateInputs, rate_source
from parknss.metrics.rating_report import RatingTable
from parknss.outputs import run_folder, write_text_atomic
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
    return RatingRun(table, write_rating(table, source, out))


def write_rating(table: RatingTable, source: dict, out: Path) -> dict:
    """Write ``ratings.csv``, ``ratings.json`` and Fig. 7 of a rating of ``source`` into
    ``out``; the JSON document (also what ``parknss reproduce`` rebuilds from the store)."""
    out.mkdir(parents=True, exist_ok=True)
    doc = {"source": source, **table.to_json()}
    doc["files"] = {
        "csv": str(table.to_csv(out / "ratings.csv")),
        "json": str(out / "ratings.json"),
        "figure": str(draw_iso_boxplot(table, out / "iso_rating.png")),
    }
    write_text_atomic(out / "ratings.json", json.dumps(doc, indent=2))
    return doc


def rate_run(
    inputs: RateInputs, out: Path, *, overwrite: bool = False,
    progress: Callable[[str], None] = _quiet,
) -> RatingRun:
    """``parknss rate``: :func:`run_rate` into the run folder ``out``, refused if it holds
    anything but a rating of the same source unless ``overwrite``."""
    inputs.check()
    identity = {"data": inputs.data, "model": inputs.model, "chain": inputs.chain,
                "replay_truth": inputs.replay_truth, "config": inputs.config}
    with run_folder(out, command="parknss rate", args=identity, overwrite=overwrite):
        return run_rate(inputs, out, progress)
