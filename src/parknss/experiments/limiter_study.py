"""The inference-limiter study (paper §V-B): the same fold models with and without it.

Each job fits one CV fold (through :func:`~parknss.experiments.folds.fold_job`), then rolls
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
import tempfile
from dataclasses import asdict, dataclass
from typing import Any

from parknss.experiments.config import ExperimentsConfig
from parknss.experiments.noise import NoiseFloor
from parknss.experiments.sweep import Sweep, fold_spec, nanmean, relative_effect

VARIANTS: tuple[str, ...] = ("none", "reconstructed", "residual")


def limiter_job(**fold_kwargs: Any) -> dict[str, Any]:
    """Fit a fold, then score its model under each limiter variant (JSON result).

    Returns ``{"fold": FoldResult JSON, "variants": {variant: OpenLoopErrors JSON}}``.
    """
    from parknss.experiments.folds import fold_job, make_fold
    from parknss.metrics.errors import open_loop_errors
    from parknss.nss.campaigns import load_campaign
    from parknss.nss.checkpoint import load_model
    from parknss.nss.config import LimiterConfig
    from parknss.nss.predict import predict_trials

    with tempfile.TemporaryDirectory(prefix="parknss-limiter-") as tmp:
        fold = fold_job(**fold_kwargs, save_dir=tmp)
        model = load_model(tmp).model
    campaign = load_campaign(fold_kwargs.get("data"))
    f = make_fold(
        campaign,
        fold_kwargs.get("split", "cv"),
        fold_kwargs.get("index", 0),
        fold_kwargs.get("r", 1),
        fold_kwargs.get("split_seed"),
    )
    val = [campaign[i] for i in f.val]
    variants = {}
    for v in VARIANTS:
        lim = None if v == "none" else LimiterConfig(enabled=True, mode=v)
        pred = predict_trials(model, val, limiter=lim)
        variants[v] = open_loop_errors(pred, val, fold["window_length"]).to_json()
    fold["model_dir"] = None
    return {"fold": fold, "variants": variants}


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


def limiter_study(
    cfg: ExperimentsConfig, quick: bool, sweep: Sweep, floor: NoiseFloor
) -> LimiterResult:
    """Every fold of the budget under the three limiter variants."""
    budget = cfg.budget(quick)
    ov = budget.study_overrides()
    fn = "parknss.experiments.limiter_study:limiter_job"
    jobs = [fold_spec(sweep, "cv", k, ov, name=f"limiter fold{k}", fn=fn) for k in budget.folds]
    results = sweep.run(jobs, "limiter")
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
            )
        )
    return LimiterResult(scores, floor, cfg.divergence_factor, list(budget.folds), budget.epochs)
