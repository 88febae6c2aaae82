"""The convergence probe (paper §IV-B, Fig. 4): held-out losses over epochs on one fold.

One fit of the configured CV fold at the deployment cap records, every ``val_every``
epochs, the held-out moving-region state loss (raw and smoothed by the trailing moving
average the best-checkpoint tracking uses) and the output loss (scaled units, the training
criterion). The optimum is the epoch of the smallest smoothed state loss (paper: 3130 of a
3200-epoch cap).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from parknss.executor import Job
from parknss.experiments.config import ExperimentsConfig
from parknss.experiments.sweep import FoldScore, Sweep, fold_spec


@dataclass
class ConvergenceResult:
    """Loss histories (one value per validated epoch) and the optimum."""

    split: str
    index: int
    epochs: list[int]
    raw: list[float]
    smooth: list[float]
    output: list[float]
    best_epoch: int | None
    epoch_cap: int
    score: FoldScore

    def late_variation(self, tail: float = 0.1) -> float:
        """Relative spread (max-min)/mean of the smoothed loss over the last ``tail`` epochs."""
        n = max(1, int(len(self.smooth) * tail))
        tail_vals = self.smooth[-n:]
        m = sum(tail_vals) / len(tail_vals)
        return (max(tail_vals) - min(tail_vals)) / m if m else float("nan")

    def to_json(self) -> dict:
        d = asdict(self)
        d["score"] = asdict(self.score)
        return d


def convergence_jobs(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> list[Job]:
    """The one fit of the probe: the configured fold at the deployment protocol (the same
    fit as that fold's Table II NSS fit when the fold is a CV one)."""
    ref = cfg.convergence_split
    ov = cfg.budget(quick).deployment_overrides()
    return [fold_spec(sweep, ref.split, ref.index, ov, r=ref.r)]


def convergence(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> ConvergenceResult:
    """Fit the convergence fold at the budget's ``convergence_epochs``."""
    ref = cfg.convergence_split
    (res,) = sweep.run(convergence_jobs(cfg, quick, sweep), "convergence")
    h = res["history"]
    return ConvergenceResult(
        ref.split,
        ref.index,
        list(h["epochs"]),
        list(h["raw"]),
        list(h["smooth"]),
        list(h["output"]),
        res.get("best_epoch"),
        cfg.budget(quick).convergence_epochs,
        FoldScore.from_json(res),
    )
