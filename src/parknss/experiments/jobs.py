"""The study job functions by import path (what the executor resolves and the store files
results under), the ones that keep resumable training state, and the jobs whose result a
stored result of another job answers."""

from __future__ import annotations

FOLD_JOB = "parknss.experiments.folds:fold_job"
LIMITER_JOB = "parknss.experiments.folds:limiter_job"

STATEFUL_JOBS: tuple[str, ...] = (FOLD_JOB, LIMITER_JOB)
"""Jobs that take a ``state_dir`` (they fit through :func:`~parknss.experiments.folds.fold_job`)."""

ALIASES: dict[str, tuple[str, str]] = {FOLD_JOB: (LIMITER_JOB, "fold")}
"""Jobs a stored entry of another job answers: job function -> (answering function, the
part of its result that is this job's result). A limiter job runs the fold job of the same
arguments (only saving its model to a temporary folder) and returns that result as its
``"fold"``, so a stored limiter fit is also the fold fit of its fold: the limiter study's
folds are the deployed-configuration folds of Table III, the learning curve at r = 1 and
the seed-noise fold's seed 0 (:meth:`parknss.experiments.store.ResultStore.get`)."""
