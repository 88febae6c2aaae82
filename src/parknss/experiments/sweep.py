"""What every NSS study shares: how its fold jobs are built, run and read back.

A study is a list of :func:`parknss.experiments.folds.fold_job` jobs run through the
executor (local pool, in-process or Ray; cached under the job hash, so an interrupted study
resumes; and looked up in the result store, :mod:`parknss.experiments.store`, when one is
given). :class:`Sweep` carries the executor settings, the campaign, the store and the
tally of where the results came from; :class:`FoldScore`
is the slice of a fold's JSON result the studies tabulate (moving-region MSEs in the
paper's units against the logged channels, and against the noise-free truth when the
campaign is synthetic).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from parknss.config import override
from parknss.executor import Job, Store, Tally, run_jobs
from parknss.experiments.config import Overrides
from parknss.experiments.jobs import FOLD_JOB, STATEFUL_JOBS
from parknss.nss.config import NSSConfig


@dataclass
class Sweep:
    """Executor settings, the campaign folder (None: the default campaign), the result
    store (None: none), the tally that counts results from the cache, the store and
    fitted, and where fold fits keep their resumable training state (``state_root``; None:
    nowhere, a killed fit starts over)."""

    executor: str = "local"
    workers: int | None = None
    address: str | None = None
    cache_dir: Path | None = None
    data: str | None = None
    progress: bool = True
    store: Store | None = None
    tally: Tally | None = None
    state_root: Path | None = None

    def run(self, jobs: list[Job], desc: str) -> list[Any]:
        """Results of ``jobs`` in order (cached jobs are read, not recomputed; identical
        jobs, e.g. the deployed option shared by several ablation axes, run once)."""
        unique: dict[str, Job] = {}
        for job in jobs:
            unique.setdefault(job.key(), job)
        results = run_jobs(
            list(unique.values()),
            executor=self.executor,
            workers=self.workers,
            cache_dir=self.cache_dir,
            address=self.address,
            progress=self.progress,
            desc=desc,
            store=self.store,
            tally=self.tally,
        )
        by_key = dict(zip(unique, results, strict=True))
        return [by_key[job.key()] for job in jobs]

    def campaign(self):
        from parknss.nss.campaigns import load_campaign

        return load_campaign(self.data)


def canonical_overrides(overrides: Overrides) -> Overrides:
    """The overrides as the minimal difference from the NSS defaults.

    Two spellings of one configuration (e.g. ``{"model": {"residual_yaw": True}}`` and
    ``{}``) give the same job, so the executor's cache computes it once.
    """
    default = NSSConfig().model_dump(mode="json")
    doc = override(NSSConfig(), overrides).model_dump(mode="json")
    out: Overrides = {}
    for sec, vals in doc.items():
        diff = {k: v for k, v in vals.items() if v != default[sec][k]}
        if diff:
            out[sec] = diff
    return out


def fold_spec(
    sweep: Sweep,
    split: str,
    index: int,
    overrides: Overrides,
    r: int = 1,
    name: str = "",
    fn: str = FOLD_JOB,
    **extra: Any,
) -> Job:
    """A fold job (or a job of ``fn`` with the same arguments plus ``extra``); the overrides
    are canonicalised (:func:`canonical_overrides`). A fold job of a sweep with a
    ``state_root`` checkpoints its fit under ``state_root/<fit key>`` and resumes from
    there (a long study across sittings; :func:`~parknss.experiments.store.fit_key`)."""
    kwargs: dict[str, Any] = {
        "split": split,
        "index": index,
        "r": r,
        "model": "nss",
        "data": sweep.data,
        "overrides": canonical_overrides(overrides),
        **extra,
    }
    if sweep.state_root is not None and fn in STATEFUL_JOBS:
        from parknss.experiments.store import fit_key

        kwargs["state_dir"] = str(Path(sweep.state_root) / fit_key(fn, kwargs))
    return Job(fn, kwargs, name or f"{split} r{r} fold{index}")


def _num(v: Any) -> float:
    return math.nan if v is None else float(v)


@dataclass
class FoldScore:
    """Moving-region errors of one fold: vx (km/h)², yaw (°/s)²; wall and CPU time of the
    fit, s (CPU NaN when the result lacks it); the full-trajectory errors (every sample,
    against the logged and the truth channels) and the moving errors within / beyond the
    training-window horizon (NaN where the result lacks them)."""

    vx: float
    vx_reverse: float
    yaw: float
    vx_truth: float
    yaw_truth: float
    wall_s: float
    best_epoch: int | None
    n_train: int
    epochs: int | None = None
    cpu_s: float = math.nan
    vx_full: float = math.nan
    yaw_full: float = math.nan
    vx_truth_full: float = math.nan
    yaw_truth_full: float = math.nan
    vx_within: float = math.nan
    vx_beyond: float = math.nan
    yaw_within: float = math.nan
    yaw_beyond: float = math.nan

    @property
    def wall_per_epoch(self) -> float:
        """Wall clock per epoch, s (validation included); NaN without an epoch count."""
        return self.wall_s / self.epochs if self.epochs else math.nan

    @property
    def cpu_per_epoch(self) -> float:
        """CPU time per epoch (per step of a fast fit), s; NaN without either."""
        return self.cpu_s / self.epochs if self.epochs else math.nan

    @classmethod
    def from_json(cls, res: dict) -> FoldScore:
        e, t = res["errors"], res.get("truth_errors") or {}
        return cls(
            vx=_num(e["vx_mse_moving_kmh2"]),
            vx_reverse=_num(e["vx_mse_reverse_kmh2"]),
            yaw=_num(e["yaw_mse_moving_degs2"]),
            vx_truth=_num(t.get("vx_mse_moving_kmh2")),
            yaw_truth=_num(t.get("yaw_mse_moving_degs2")),
            wall_s=float(res["wall_s"]),
            best_epoch=res.get("best_epoch"),
            n_train=len(res["train"]),
            epochs=res.get("epochs"),
            cpu_s=_num(res.get("cpu_s")),
            vx_full=_num(e.get("vx_mse_full_kmh2")),
            yaw_full=_num(e.get("yaw_mse_full_degs2")),
            vx_truth_full=_num(t.get("vx_mse_full_kmh2")),
            yaw_truth_full=_num(t.get("yaw_mse_full_degs2")),
            vx_within=_num(e.get("vx_mse_within_kmh2")),
            vx_beyond=_num(e.get("vx_mse_beyond_kmh2")),
            yaw_within=_num(e.get("yaw_mse_within_degs2")),
            yaw_beyond=_num(e.get("yaw_mse_beyond_degs2")),
        )


def nanmean(values: list[float]) -> float:
    """Mean ignoring NaN (NaN when nothing is finite)."""
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else math.nan


def relative_effect(value: float, baseline: float) -> float:
    """(value - baseline) / baseline; NaN when undefined."""
    if not (math.isfinite(value) and math.isfinite(baseline)) or baseline == 0.0:
        return math.nan
    return (value - baseline) / baseline
