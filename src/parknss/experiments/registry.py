"""The paper's reproducible artefacts (tables and figures) and how each is made.

An :class:`Artefact` has a name (``table2``, ``fig5``, ``learning_curve``, ...), the paper
section it reproduces, and a function that takes a :class:`RunContext` and returns an
:class:`ArtefactResult` of tables, figure files and findings. ``parknss reproduce`` runs
them and writes the HTML report.
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from parknss.config import REPO_ROOT
from parknss.errors import ConfigError


@dataclass
class Table:
    """A table for the report: column names and rows of cells (numbers or text)."""

    title: str
    columns: list[str]
    rows: list[list[Any]]


@dataclass
class Finding:
    """One of the paper's findings beside what this toolkit measured.

    ``agrees`` is True/False, or None where the comparison is not decidable; then
    ``undecided`` says why ("within noise", "not measured", ...).
    """

    claim: str
    measured: str
    agrees: bool | None
    undecided: str = "within noise"

    @property
    def verdict(self) -> str:
        """ "agrees", "differs" or the reason it is undecided."""
        if self.agrees is None:
            return self.undecided
        return "agrees" if self.agrees else "differs"


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
    between artefacts of one run (the config, the measured noise floor).
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
        )


@dataclass(frozen=True)
class Artefact:
    name: str
    title: str
    paper_ref: str
    make: Callable[[RunContext], ArtefactResult]


_REGISTRY: dict[str, Artefact] = {}


def register(name: str, title: str, paper_ref: str):
    """Decorator adding an artefact function to the registry under ``name``."""

    def deco(fn: Callable[[RunContext], ArtefactResult]):
        _REGISTRY[name] = Artefact(name, title, paper_ref, fn)
        return fn

    return deco


def artefacts() -> dict[str, Artefact]:
    """All registered artefacts, in registration order (imports the study modules)."""
    import parknss.experiments.artefacts  # noqa: F401  (registers them)

    return dict(_REGISTRY)


def get(name: str) -> Artefact:
    arts = artefacts()
    if name not in arts:
        raise ConfigError(f"unknown artefact {name!r}; choose from {', '.join(arts)}")
    return arts[name]


def git_revision() -> str:
    """The repository's HEAD commit (with '+dirty' if the tree has changes), or 'unknown'."""
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
        ).stdout.strip()
        return rev + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
