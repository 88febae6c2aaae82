"""The per-fold seed floor and the judge that reads every finding with it.

The floor fits (:func:`floor_jobs`) are the study configuration (the budget's overrides,
epoch cap and recipe) refitted under several seeds on every CV fold of the budget: the
seed-noise split with the budget's ``seeds``, the other folds with its ``floor_seeds``
(seed 0 is the deployed-configuration fit the ablations and the limiter already hold).
A run that may only read the store uses the floor fits it holds: a fold with fewer than
``verdict.min_seeds`` of them borrows the pooled floor of the measured folds, and says so.

A :class:`Judge` turns study results into :class:`~parknss.experiments.verdict.Effect` s
on one metric (``moving``: the paper's region, measured |vx| >= 0.5 km/h; ``full``: every
sample; ``truth_full``: every sample against the noise-free truth):

* :meth:`Judge.cross`: an option against its baseline, two fits per fold at the same seed:
  the pair's seed spread is sqrt 2 x the fold's seed CV of the metric (independent fits;
  an upper bound when fits of one seed are positively correlated);
* :meth:`Judge.within`: two numbers of one fit (reverse vs all moving samples, beyond vs
  within the horizon, a limiter on vs off): the pair's seed spread is that of the same
  quantity over the fold's floor fits (None where they do not score it: the bootstrap
  alone);
* :meth:`Judge.unpaired`: the folds of two splits (the learning curve's sizes).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from parknss.experiments.config import ExperimentsConfig, VerdictConfig, merge_overrides
from parknss.experiments.noise import NoiseFloor, SeedNoiseResult
from parknss.experiments.sweep import FoldScore, Sweep, fold_spec, relative_effect
from parknss.experiments.verdict import Effect, FoldNoise, estimate, estimate_unpaired

METRICS: dict[str, tuple[str, str]] = {
    "moving": ("vx", "yaw"),
    "full": ("vx_full", "yaw_full"),
    "truth_full": ("vx_truth_full", "yaw_truth_full"),
}
"""Metric name -> the :class:`FoldScore` fields of its vx and yaw errors."""
LABELS = {"moving": "moving region (measured |vx| >= 0.5 km/h)", "full": "full trajectory",
          "truth_full": "full trajectory vs truth"}


def metric_value(score: FoldScore, channel: str, metric: str) -> float:
    """The ``channel`` ("vx" or "yaw") error of ``score`` on ``metric``."""
    return float(getattr(score, METRICS[metric][0 if channel == "vx" else 1]))


@dataclass
class FoldSeeds:
    """The floor fits: fold -> seed -> score."""

    fits: dict[int, dict[int, FoldScore]] = field(default_factory=dict)

    def spread(self, quantity: Callable[[FoldScore], float], min_seeds: int,
               relative: bool) -> FoldNoise:
        """Per fold, the sample sd (ddof = 1) of ``quantity`` over its seeds, over |mean|
        when ``relative`` (the CV); NaN for a fold with fewer than ``min_seeds`` (its
        two-seed estimate kept aside, :class:`FoldNoise`)."""
        sd, seeds, few = {}, {}, {}
        for k, by_seed in self.fits.items():
            vals = np.array([quantity(s) for s in by_seed.values()], dtype=float)
            vals = vals[np.isfinite(vals)]
            seeds[k] = int(vals.size)
            v = math.nan
            if vals.size >= 2:
                v = float(vals.std(ddof=1))
                v = v / abs(float(vals.mean())) if relative else v
            sd[k] = v if vals.size >= min_seeds else math.nan
            if vals.size < min_seeds and math.isfinite(v):
                few[k] = v
        return FoldNoise(sd, seeds, min_seeds, few=few)

    def seeds_of(self, fold: int) -> list[int]:
        return sorted(self.fits.get(fold, {}))


def floor_jobs(cfg: ExperimentsConfig, quick: bool, sweep: Sweep):
    """(fold, seed, job) of every floor fit (module doc): the budget's folds and the
    seed-noise fold."""
    budget = cfg.budget(quick)
    ref = cfg.seed_noise_split
    out = []
    folds = sorted({*budget.folds, *([ref.index] if ref.split == "cv" else [])})
    for k in folds:
        seeds = budget.seeds if ref.split == "cv" and ref.index == k else budget.floor_seeds
        for s in seeds:
            ov = merge_overrides(budget.study_overrides(), {"train": {"seed": s}})
            out.append((k, s, fold_spec(sweep, "cv", k, ov, name=f"floor fold{k} seed {s}")))
    return out


def fold_seeds(cfg: ExperimentsConfig, quick: bool, sweep: Sweep, fit: bool = True,
               known: SeedNoiseResult | None = None) -> FoldSeeds:
    """The floor fits: all of them (fitted where missing) when ``fit`` and the sweep may
    fit; else those the result store holds (none without a store). ``known``: the
    seed-noise study's result, whose fold is then taken from it (not run again)."""
    plan = floor_jobs(cfg, quick, sweep)
    fits: dict[int, dict[int, FoldScore]] = {}
    if known is not None and known.split.startswith("cv"):
        fits[known.index] = dict(zip(known.seeds, known.scores, strict=True))
        plan = [p for p in plan if p[0] != known.index]
    store = sweep.store
    if fit and (store is None or store.fit_missing):
        results = sweep.run([p[-1] for p in plan], "floor") if plan else []
    else:
        got = [store.get(job) if store is not None else (False, None) for *_, job in plan]
        results = [res if hit else None for hit, res in got]
    for (k, s, _), res in zip(plan, results, strict=True):
        if res is not None:
            fits.setdefault(k, {})[s] = FoldScore.from_json(res)
    return FoldSeeds(fits)


@dataclass
class Judge:
    """Effects of study results on ``metric`` with their intervals (module doc);
    ``fallback``: the floor where no fold has enough seed fits (a single-fold or the
    paper's floor, its CV for every fold)."""

    cfg: VerdictConfig
    seeds: FoldSeeds
    metric: str = "moving"
    fallback: NoiseFloor | None = None

    def with_metric(self, metric: str) -> Judge:
        return replace(self, metric=metric)

    def value(self, score: FoldScore, channel: str) -> float:
        return metric_value(score, channel, self.metric)

    def cv(self, channel: str) -> FoldNoise:
        """The relative seed spread of one fit's ``channel`` error per fold."""
        noise = self.seeds.spread(lambda s: self.value(s, channel), self.cfg.min_seeds, True)
        if self.fallback is not None and self.metric == "moving":
            noise.prior = getattr(self.fallback, channel)
            if not any(math.isfinite(v) for v in noise.sd.values()):
                noise.source = f"{self.fallback.source} floor, {self.fallback.n_seeds} seeds"
        return noise

    def cross(self, option: Mapping[int, FoldScore], base: Mapping[int, FoldScore],
              channel: str) -> Effect:
        """Option vs baseline, one fit each per fold (the same seed)."""
        pairs = {k: [relative_effect(self.value(option[k], channel),
                                     self.value(base[k], channel))]
                 for k in option if k in base}
        return estimate(pairs, self.cv(channel), self.cfg, scale=math.sqrt(2.0))

    def within(self, fits: Mapping[int, FoldScore],
               quantity: Callable[[FoldScore], float], noise: bool = True) -> Effect:
        """A relative effect inside each fold's fit (``quantity`` of its score); the seed
        spread of the same quantity over the floor fits unless ``noise`` is False."""
        pairs = {k: [quantity(s)] for k, s in fits.items()}
        fn = self.seeds.spread(quantity, self.cfg.min_seeds, False) if noise else None
        return estimate(pairs, fn, self.cfg)

    def within_values(self, effects: Mapping[int, float]) -> Effect:
        """Per-fold relative effects measured without floor fits (the bootstrap alone)."""
        return estimate({k: [v] for k, v in effects.items()}, None, self.cfg)

    def unpaired(self, a: list[FoldScore], b: list[FoldScore], channel: str) -> Effect:
        """``b`` vs ``a``: the folds of two different splits."""
        return estimate_unpaired([self.value(s, channel) for s in a],
                                 [self.value(s, channel) for s in b],
                                 self.cv(channel).pooled(), self.cfg)

    def describe(self) -> str:
        return (f"{LABELS[self.metric]}; vx {self.cv('vx').describe()}; yaw "
                f"{self.cv('yaw').describe()}; interval {100 * self.cfg.level:g} %, "
                f"{self.cfg.resamples} resamples")


def judge_from_floor(floor: NoiseFloor, cfg: VerdictConfig,
                     seeds: FoldSeeds | None = None) -> Judge:
    """A judge of ``seeds`` (none: no fold measured) falling back on ``floor``."""
    return Judge(cfg, seeds or FoldSeeds(), cfg.metric, floor)
