"""The inference-limiter study (paper §V-B): the same fold models with and without it.

Each job (:func:`~parknss.experiments.folds.limiter_job`) fits one CV fold, then rolls
the *same* model out over the held-out trials three ways: without a limiter, with the
gear-conditioned kinematic limiter clamping the reconstructed yaw rate (the correct
form), and with the limiter clamping the residual channel instead (the form the paper
warns pins the yaw to the kinematic manifold, so the rollout diverges). Effects are
relative to the unlimited rollout and judged against the seed-noise floor; a variant
"diverges" when its vx error exceeds ``divergence_factor`` times the unlimited one or is
not finite.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

from parknss.executor import Job
from parknss.experiments.config import ExperimentsConfig
from parknss.experiments.folds import VARIANTS
from parknss.experiments.jobs import LIMITER_JOB
from parknss.experiments.noise import NoiseFloor
from parknss.experiments.sweep import Sweep, fold_spec, nanmean, relative_effect


def _get(errors: dict, key: str) -> float:
    v = errors.get(key)
    return math.nan if v is None else float(v)


@dataclass
class VariantScore:
    """Fold-mean moving-region errors of one limiter variant, (km/h)² and (°/s)²."""

    variant: str
    vx: float
    vx_reverse: float
    yaw: float
    per_fold_vx: list[float]
    per_fold_errors: list[dict] = field(default_factory=list)  # OpenLoopErrors JSON per fold


@dataclass
class LimiterResult:
    variants: list[VariantScore]
    floor: NoiseFloor
    divergence_factor: float
    folds: list[int]
    epochs: int

    def get(self, variant: str) -> VariantScore:
        return next(v for v in self.variants if v.variant == variant)

    def effect(self, variant: str, channel: str) -> float:
        return relative_effect(
            getattr(self.get(variant), channel), getattr(self.get("none"), channel)
        )

    def diverges(self, variant: str) -> bool:
        v, base = self.get(variant).vx, self.get("none").vx
        return not math.isfinite(v) or v > self.divergence_factor * base

    def to_json(self) -> dict:
        return {
            "folds": self.folds,
            "epochs": self.epochs,
            "floor": self.floor.to_json(),
            "divergence_factor": self.divergence_factor,
            "variants": [asdict(v) for v in self.variants],
        }


def limiter_jobs(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> list[Job]:
    """One limiter job per fold of the budget (each fits once, rolls out three ways)."""
    budget = cfg.budget(quick)
    ov = budget.study_overrides()
    return [
        fold_spec(sweep, "cv", k, ov, name=f"limiter fold{k}", fn=LIMITER_JOB)
        for k in budget.folds
    ]


def limiter_study(
    cfg: ExperimentsConfig, quick: bool, sweep: Sweep,
    floor: NoiseFloor | Callable[[], NoiseFloor],
) -> LimiterResult:
    """Every fold of the budget under the three limiter variants; ``floor`` or a function
    that gives it once the limiter fits are done (which then answer the seed-noise
    study's fit of its fold: :data:`~parknss.experiments.store.ALIASES`)."""
    budget = cfg.budget(quick)
    results = sweep.run(limiter_jobs(cfg, quick, sweep), "limiter")
    if callable(floor):
        floor = floor()
    scores = []
    for v in VARIANTS:
        errs = [r["variants"][v] for r in results]
        scores.append(
            VariantScore(
                v,
                vx=nanmean([_get(e, "vx_mse_moving_kmh2") for e in errs]),
                vx_reverse=nanmean([_get(e, "vx_mse_reverse_kmh2") for e in errs]),
                yaw=nanmean([_get(e, "yaw_mse_moving_degs2") for e in errs]),
                per_fold_vx=[_get(e, "vx_mse_moving_kmh2") for e in errs],
                per_fold_errors=errs,
            )
        )
    return LimiterResult(scores, floor, cfg.divergence_factor, list(budget.folds), budget.epochs)
