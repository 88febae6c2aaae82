"""What a reproduced artefact is: its report tables, figures and findings, and its inputs.

An :class:`Artefact` has a name (``table2``, ``fig7``, ``learning_curve``, ...), the paper
section it reproduces, and a function that takes a :class:`RunContext` and returns an
:class:`ArtefactResult` of :class:`Table` s, figure files and :class:`Finding` s. The
functions are :mod:`parknss.experiments.artefacts`; the registry that lists them,
:mod:`parknss.experiments.registry`; ``parknss reproduce`` runs them and writes the HTML
report (:mod:`parknss.experiments.reproduce`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from parknss.executor import Tally


@dataclass
class Table:
    """A table for the report: column names and rows of cells (numbers or text)."""

    title: str
    columns: list[str]
    rows: list[list[Any]]


SMOKE_TEST = "smoke test"
NOT_MEASURED = "not measured"


@dataclass
class Finding:
    """One of the paper's findings beside what this toolkit measured.

    ``agrees`` is True/False, or None where the comparison is not decidable; then
    ``undecided`` says why ("cannot tell at this budget (...)", "not measured", ...).
    ``beside``: the verdict on a second metric, where the report shows one.
    """

    claim: str
    measured: str
    agrees: bool | None
    undecided: str = "cannot tell at this budget"
    beside: str = ""

    @property
    def verdict(self) -> str:
        """ "agrees", "differs" or the reason it is undecided."""
        if self.agrees is None:
            return self.undecided
        return "agrees" if self.agrees else "differs"

    def smoke_test(self) -> Finding:
        """The same row without a verdict: a ``--quick`` budget (a few epochs of a tiny
        net) shows that the pipeline runs, not how the paper's claim fares."""
        return Finding(self.claim, self.measured, None, SMOKE_TEST)


@dataclass
class ArtefactResult:
    tables: list[Table] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    findings: list[Finding] = field(default_factory=list)
    notes: str = ""
    wall_s: float = 0.0


@dataclass
class RunContext:
    """What every artefact function receives.

    quick: tiny budgets for smoke tests; executor/workers/address: how sweeps run;
    out_dir: where figures go; data: campaign folder or None for the default campaign;
    config: the studies' YAML (None: configs/experiments.yaml); memo: results shared
    between artefacts of one run (the config, the measured noise floor); store: the result
    store (:class:`~parknss.experiments.store.ResultStore`, None: none); tally: where the
    fits came from (run cache, store, fitted); log: where an artefact's steps report
    progress (one line each; ``parknss reproduce`` prints them on stderr).
    """

    out_dir: Path
    quick: bool = False
    executor: str = "local"
    workers: int | None = None
    address: str | None = None
    data: Path | None = None
    seed: int = 0
    cache_dir: Path | None = None
    progress: bool = True
    config: Path | None = None
    memo: dict[str, Any] = field(default_factory=dict)
    store: Any = None
    tally: Tally = field(default_factory=Tally)
    log: Callable[[str], None] = field(default=lambda msg: None)
    _campaign: Any = None

    def campaign(self):
        """The campaign under study (loaded once; the default campaign when data is None)."""
        if self._campaign is None:
            from parknss.nss.campaigns import load_campaign

            self._campaign = load_campaign(self.data)
        return self._campaign

    def experiments_config(self):
        """The studies' :class:`~parknss.experiments.config.ExperimentsConfig` (loaded once)."""
        if "config" not in self.memo:
            from parknss.experiments.config import load_experiments_config

            self.memo["config"] = load_experiments_config(self.config)
        return self.memo["config"]

    def sweep(self):
        """The executor settings of this run as a :class:`~parknss.experiments.sweep.Sweep`."""
        from parknss.experiments.sweep import Sweep

        return Sweep(
            executor=self.executor,
            workers=self.workers,
            address=self.address,
            cache_dir=self.cache_dir,
            data=str(self.data) if self.data is not None else None,
            progress=self.progress,
            store=self.store,
            tally=self.tally,
            state_root=self.out_dir / "state",
        )


@dataclass(frozen=True)
class Artefact:
    name: str
    title: str
    paper_ref: str
    make: Callable[[RunContext], ArtefactResult]

