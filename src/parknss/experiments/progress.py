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

CPU time left: a paper-recipe step (one full-batch epoch) costs the same throughout, so a
fit at step k of K after c CPU s has about c·(K − k)/k left; a fast-recipe fit's two
phases cost differently per step (an update ~1/6 of an epoch), so it gets none
(``parknss study estimate`` prices a whole fit).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
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
    the folder has no state file yet (the fit has not started); ``uniform``: every step
    costs the same (the paper recipe), so :attr:`cpu_left_s` extrapolates."""

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
    uniform: bool = False
    queued: bool = False

    @property
    def done(self) -> bool:
        return self.steps is not None and self.step >= self.steps

    @property
    def cpu_left_s(self) -> float | None:
        """CPU s to the last step at the mean cost per step so far (module doc); None
        when the plan does not know the fit, its steps cost unequally or none ran."""
        if (self.error or not self.uniform or self.steps is None or self.cpu_s is None
                or self.step <= 0):
            return None
        return self.cpu_s * max(self.steps - self.step, 0) / self.step

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
        best = "-" if self.best is None else f"{self.best:.4g} @ {self.best_step}"
        return f"{self.name:<40} {of:>18} {cpu:>9} {left:>10} {best:>18}  {self.updated_utc}"


HEADER = (f"{'fit':<40} {'step':>18} {'CPU s':>9} {'CPU s left':>10} {'best criterion':>18}"
          "  written (UTC)")


class PlannedFit(NamedTuple):
    """A fit of the plan: its job's name, its total steps, whether every step costs the
    same (the paper recipe)."""

    name: str
    steps: int | None
    uniform: bool = False


def read_state(folder: Path, plan: PlannedFit) -> FitProgress:
    """The progress in one state folder (see the module doc)."""
    path = folder / META
    row = FitProgress(folder.name, plan.name, steps=plan.steps, uniform=plan.uniform)
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
                                      shape.recipe == "paper")
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
    return rows
