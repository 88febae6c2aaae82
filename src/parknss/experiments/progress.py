"""How far the fits of a run folder have got: ``parknss study progress OUT``.

A study fit of ``parknss reproduce`` or ``parknss study`` keeps its resumable training
state in ``OUT/state/<folder>/`` (``train_state.json`` beside the tensors, written every
``train.checkpoint_every`` steps; :mod:`parknss.nss.train_state`). This module reads the
JSON half of each (never the tensors) and names the fit from the run's plan: a folder is
the fit key (:func:`~parknss.experiments.store.fit_key`) of a study job, or
``<variant>_fold<i>`` for Table II (:func:`parknss.experiments.cv.state_folder`); the plan
(:func:`~parknss.experiments.plan.plan_rows` at the run's budget, config and campaign)
gives the job's name and its total steps (paper recipe: epochs; fast recipe: updates +
finish epochs). A folder the plan does not know keeps its folder name and no total; a
folder with no state file yet (the executor labels a job's folder with ``job.json`` when
it queues the job, :mod:`parknss.experiments.parked`) is listed as queued; a state file
that does not read is listed as unreadable, with why.

CPU time left, per phase of the fit's recipe (:mod:`parknss.nss.recipes`; paper recipe:
one phase of epochs, fast recipe: phase-1 updates, then finish epochs): each history row
records the CPU seconds so far, so the mean CPU cost per step of each phase the fit has
run is measured from its own rows, and the steps left in that phase cost that much each. A
phase the fit has not reached yet (a fast fit's finish epochs, ~3.5-6.5x an update) is
priced at the median per-step cost of the same phase on the same engine class in the
other fits of the run folder (``borrowed``), and the fit gets no estimate while none has
run it (``parknss study estimate`` times an engine class and prices a whole fit). A state
written before rows kept CPU times falls back to its mean CPU per step when its recipe has
one phase.
"""

from __future__ import annotations

import json
import math
import statistics
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import NamedTuple

from parknss.errors import ConfigError
from parknss.experiments.config import ExperimentsConfig
from parknss.experiments.parked import JOB_FILE
from parknss.experiments.sweep import Sweep
from parknss.nss.history import History
from parknss.nss.train_state import FORMAT, META


@dataclass
class FitProgress:
    """One fit's training state: ``step`` of ``steps`` (None: the plan does not know the
    fit), CPU and wall seconds so far, the best smoothed criterion and its step, when the
    state was last written (UTC), or ``error`` when the state does not read; ``queued``:
    the folder has no state file yet (the fit has not started); ``phases``: the recipe's
    phases in order, (name, steps); ``rates``: CPU s per step of each phase, measured
    from the fit's own history rows or ``borrowed`` from its siblings (module doc);
    ``engine``: (integrator, engine class) of the fit, for borrowing."""

    folder: str
    name: str
    step: int = 0
    steps: int | None = None
    cpu_s: float | None = None
    wall_s: float | None = None
    best: float | None = None
    best_step: int | None = None
    updated_utc: str = ""
    error: str = ""
    queued: bool = False
    phases: list[tuple[str, int]] = field(default_factory=list)
    rates: dict[str, float] = field(default_factory=dict)
    borrowed: list[str] = field(default_factory=list)
    engine: tuple[str, str] | None = None

    def steps_left(self) -> dict[str, int]:
        """Steps still to run in each phase of :attr:`phases` (0 for one behind)."""
        out, start = {}, 0
        for name, n in self.phases:
            out[name] = max(0, start + n - max(start, self.step))
            start += n
        return out

    @property
    def done(self) -> bool:
        return self.steps is not None and self.step >= self.steps

    @property
    def cpu_left_s(self) -> float | None:
        """CPU s to the last step: each phase's steps left times its CPU s per step
        (module doc); None when the plan does not know the fit, the state does not read,
        it has not started, or a phase with steps left has no measured cost."""
        if self.error or self.steps is None or self.step <= 0 or not self.phases:
            return None
        left = 0.0
        for name, n in self.steps_left().items():
            if n:
                if name not in self.rates:
                    return None
                left += n * self.rates[name]
        return left

    def to_json(self) -> dict:
        return {**asdict(self), "done": self.done, "cpu_left_s": self.cpu_left_s}

    def line(self) -> str:
        if self.error:
            return f"{self.name:<40} unreadable: {self.error}"
        if self.queued:
            return f"{self.name:<40} {'queued':>18} (not started: no training state yet)"
        of = f"{self.step}/{self.steps} ({100 * self.step / self.steps:.0f} %)" if (
            self.steps) else f"{self.step}/?"
        cpu = "-" if self.cpu_s is None else f"{self.cpu_s:.0f}"
        left = "-" if self.cpu_left_s is None else f"{self.cpu_left_s:.0f}"
        if self.borrowed and self.cpu_left_s is not None:
            left = "~" + left
        best = "-" if self.best is None else f"{self.best:.4g} @ {self.best_step}"
        return f"{self.name:<40} {of:>18} {cpu:>9} {left:>10} {best:>18}  {self.updated_utc}"


HEADER = (f"{'fit':<40} {'step':>18} {'CPU s':>9} {'CPU s left':>10} {'best criterion':>18}"
          "  written (UTC)")


class PlannedFit(NamedTuple):
    """A fit of the plan: its job's name, its total steps, its recipe's phases in order
    as (name, steps), its (integrator, engine class)."""

    name: str
    steps: int | None
    phases: tuple[tuple[str, int], ...] = ()
    engine: tuple[str, str] | None = None


def phase_rates(rows: list[dict]) -> dict[str, float]:
    """Mean CPU s per step of each phase in a fit's history rows (each row's ``cpu_s`` is
    the fit's CPU time so far; a paper-recipe row has no ``phase``: "paper"). Rows without
    a CPU time are skipped with the step before them."""
    spent: dict[str, float] = {}
    count: dict[str, int] = {}
    before: float | None = 0.0
    for row in rows:
        cpu = row.get("cpu_s")
        if not isinstance(cpu, int | float) or not math.isfinite(cpu):
            before = None
            continue
        if before is not None:
            name = row.get("phase", "paper")
            spent[name] = spent.get(name, 0.0) + max(cpu - before, 0.0)
            count[name] = count.get(name, 0) + 1
        before = cpu
    return {k: spent[k] / count[k] for k in spent}


def borrow_rates(rows: list[FitProgress]) -> None:
    """Give each fit the median CPU s per step of a phase it has not run yet from the
    fits of the same engine class that have (module doc); marks it ``borrowed``."""
    seen: dict[tuple, list[float]] = {}
    for r in rows:
        if r.engine is not None:
            for name, rate in r.rates.items():
                seen.setdefault((r.engine, name), []).append(rate)
    for r in rows:
        for name, n in r.steps_left().items():
            if n and name not in r.rates and (r.engine, name) in seen:
                r.rates[name] = statistics.median(seen[r.engine, name])
                r.borrowed.append(name)


def read_state(folder: Path, plan: PlannedFit) -> FitProgress:
    """The progress in one state folder (see the module doc)."""
    path = folder / META
    row = FitProgress(folder.name, plan.name, steps=plan.steps, phases=list(plan.phases),
                      engine=plan.engine)
    if not path.exists() and (folder / JOB_FILE).is_file():
        row.queued = True
        return row
    try:
        meta = json.loads(path.read_text())
        if meta.get("format") != FORMAT:
            raise ValueError("not a parknss training state")
        hist = History.from_json(meta["history"])
        row.step = int(meta["epoch"])
        row.wall_s = float(meta["wall_s"])
        row.cpu_s = None if meta.get("cpu_s") is None else float(meta["cpu_s"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        row.error = f"{exc.__class__.__name__}: {exc}"
        return row
    row.rates = phase_rates(hist.rows)
    if not row.rates and len(row.phases) == 1 and row.cpu_s and row.step > 0:
        row.rates = {row.phases[0][0]: row.cpu_s / row.step}
    best_step, best = hist.best()
    if math.isfinite(best):
        row.best, row.best_step = best, best_step
    stamp = datetime.fromtimestamp(path.stat().st_mtime, UTC)
    row.updated_utc = stamp.strftime("%Y-%m-%d %H:%M")
    return row


def planned_fits(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> dict[str, PlannedFit]:
    """State folder name -> :class:`PlannedFit` of every fit the studies plan."""
    from parknss.experiments.cv import MODEL_VARIANTS, cv_jobs, state_folder
    from parknss.experiments.plan import fit_shape, plan_rows
    from parknss.experiments.store import fit_key

    campaign = sweep.campaign()
    out: dict[str, PlannedFit] = {}
    for jobs in plan_rows(cfg, quick, sweep).values():
        for job in jobs:
            key = fit_key(job.fn, job.kwargs)
            if key not in out and job.kwargs.get("model", "nss") == "nss":
                shape = fit_shape(job, campaign)
                out[key] = PlannedFit(job.name or key, shape.epochs + shape.updates,
                                      shape.phases, shape.engine)
    ov = cfg.budget(quick).deployment_overrides()
    for var, job in cv_jobs(sweep.data, None, ov, list(MODEL_VARIANTS)):
        if job.kwargs["model"] == "nss":
            out[state_folder(var, job.kwargs["index"])] = out[fit_key(job.fn, job.kwargs)]
    return out


def run_progress(out_dir: Path, cfg: ExperimentsConfig, quick: bool,
                 data: str | None) -> list[FitProgress]:
    """Every fit with a training state under ``out_dir/state``, named by the plan."""
    root = Path(out_dir) / "state"
    if not root.is_dir():
        raise ConfigError(f"{root} does not exist: no fit of this run has written a "
                          "training state (is it a parknss reproduce or study run folder?)")
    names = planned_fits(cfg, quick, Sweep(data=data, progress=False))
    rows = []
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        rows.append(read_state(folder, names.get(folder.name, PlannedFit(folder.name, None))))
    borrow_rates(rows)
    return rows
