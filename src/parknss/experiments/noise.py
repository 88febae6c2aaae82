"""The seed-noise floor (paper §IV-B "Evaluation Discipline", §V-A).

Repeated fits of one split under several seeds; the coefficient of variation (sample std
with ddof = 1 over the mean) of the held-out moving-region vx and ω_z errors is the floor
every other study compares its effects against (paper: about 2 % and 3-4 %). An effect
counts as beyond the floor when its relative size exceeds ``floor_z`` times the CV of its
channel (:meth:`NoiseFloor.exceeds`).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from parknss.experiments.config import Budget, ExperimentsConfig, merge_overrides
from parknss.experiments.sweep import FoldScore, Sweep, fold_spec

CHANNELS = ("vx", "yaw")


def coefficient_of_variation(values) -> float:
    """std (ddof = 1) / |mean| of a 1-D sample; 0 for a constant sample, NaN if undefined."""
    a = np.asarray(values, dtype=float)
    if a.size < 2 or not np.all(np.isfinite(a)):
        return math.nan
    m = float(a.mean())
    if m == 0.0:
        return math.nan
    if np.all(a == a[0]):
        return 0.0  # exactly, not the rounding residue of the mean
    return float(a.std(ddof=1) / abs(m))


@dataclass
class NoiseFloor:
    """Relative seed-induced spread of the vx and yaw errors (fractions, not %)."""

    vx: float
    yaw: float
    n_seeds: int
    source: str  # "measured" or "paper"
    z: float = 2.0
    max_threshold: float = 0.1  # a wider threshold cannot confirm "no effect"

    def threshold(self, channel: str) -> float:
        """The relative effect an option must exceed to count (z·CV of the channel)."""
        return self.z * getattr(self, channel)

    def exceeds(self, rel_effect: float, channel: str) -> bool | None:
        """True/False whether |rel_effect| > z·CV; None when either is undefined."""
        thr = self.threshold(channel)
        if not (math.isfinite(rel_effect) and math.isfinite(thr)):
            return None
        return abs(rel_effect) > thr

    def confirms_null(self, rel_effect: float, channel: str) -> bool | None:
        """For a claim of *no* effect: True if |rel_effect| <= z·CV and the floor is narrow
        enough to be informative (z·CV <= max_threshold), False if the effect exceeds the
        floor, None otherwise (undefined, or a floor too wide to confirm anything)."""
        beyond = self.exceeds(rel_effect, channel)
        if beyond is None:
            return None
        if beyond:
            return False
        return True if self.threshold(channel) <= self.max_threshold else None

    def describe(self) -> str:
        return (
            f"seed-noise CV vx {100 * self.vx:.1f} %, yaw {100 * self.yaw:.1f} % "
            f"({self.source}, {self.n_seeds} seeds; threshold {self.z:g}·CV)"
        )

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, doc: dict) -> NoiseFloor:
        keys = ("vx", "yaw", "n_seeds", "source", "z", "max_threshold")
        return cls(**{k: doc[k] for k in keys if k in doc})

    @classmethod
    def paper(cls, cfg: ExperimentsConfig) -> NoiseFloor:
        """The paper's floor, labelled as such (for a study run without a measured floor)."""
        return cls(
            cfg.paper_floor["vx"], cfg.paper_floor["yaw"], 0, "paper", cfg.floor_z, cfg.max_floor
        )

    @classmethod
    def load(cls, path: str | Path) -> NoiseFloor:
        """From a seed-noise result JSON (``parknss study seed-noise --out``) or a floor JSON."""
        doc = json.loads(Path(path).read_text())
        doc = doc.get("result", doc)
        return cls.from_json(doc.get("floor", doc))


@dataclass
class SeedNoiseResult:
    """Per-seed scores of one split and the floor they give."""

    split: str
    index: int
    seeds: list[int]
    scores: list[FoldScore]
    floor: NoiseFloor
    epochs: int

    def mean(self, channel: str) -> float:
        return float(np.mean([getattr(s, channel) for s in self.scores]))

    def to_json(self) -> dict:
        return {
            "split": self.split,
            "index": self.index,
            "seeds": self.seeds,
            "epochs": self.epochs,
            "scores": [asdict(s) for s in self.scores],
            "floor": self.floor.to_json(),
        }


def seed_jobs(cfg: ExperimentsConfig, budget: Budget, sweep: Sweep):
    ref = cfg.seed_noise_split
    return [
        fold_spec(
            sweep,
            ref.split,
            ref.index,
            merge_overrides(budget.study_overrides(), {"train": {"seed": s}}),
            r=ref.r,
            name=f"seed {s}",
        )
        for s in budget.seeds
    ]


def seed_noise(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> SeedNoiseResult:
    """Fit the configured split once per seed of the budget; CVs of the held-out errors."""
    budget = cfg.budget(quick)
    results = sweep.run(seed_jobs(cfg, budget, sweep), "seed noise")
    scores = [FoldScore.from_json(r) for r in results]
    floor = NoiseFloor(
        vx=coefficient_of_variation([s.vx for s in scores]),
        yaw=coefficient_of_variation([s.yaw for s in scores]),
        n_seeds=len(scores),
        source="measured",
        z=cfg.floor_z,
        max_threshold=cfg.max_floor,
    )
    ref = cfg.seed_noise_split
    return SeedNoiseResult(ref.split, ref.index, list(budget.seeds), scores, floor, budget.epochs)
