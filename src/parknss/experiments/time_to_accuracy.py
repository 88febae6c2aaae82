"""Time to accuracy of the training recipes: held-out error against CPU time, per CV fold.

For each fold of the budget's ``tta_folds``, two fits of the NSS on the same split: the
paper recipe (the Table II fold job itself, so the result store shares the fit) and the
fast recipe (``train.recipe: fast``, :mod:`parknss.nss.recipes`). Each fit's history gives
the held-out criterion (moving-region state loss of whole-trial open-loop rollouts, the
value the best checkpoint is chosen on; raw and smoothed) at the fit's CPU time.

* target: the paper fit's best smoothed criterion (the error its final model was chosen
  at);
* reach: the CPU time at which the fast fit's smoothed criterion first falls to the target
  (None if it never does);
* speed-ups: the paper fit's CPU time to its own best (the first point at its best smoothed
  criterion, not its total: a fit that peaks early is charged only what its best cost) /
  fast CPU time to reach, and paper / fast total CPU time;
* the Table II scores of both final models (vx, ω_z moving-region MSE) beside them.

CPU time is the fit process's (``time.process_time``, one torch thread), so it does not
depend on what else the machine runs; ratios are taken within one machine.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from parknss.errors import DataError
from parknss.executor import Job
from parknss.experiments.config import ExperimentsConfig, merge_overrides
from parknss.experiments.sweep import FoldScore, Sweep, fold_spec

FAST = {"train": {"recipe": "fast"}}


@dataclass
class Curve:
    """A fit's held-out criterion (scaled MAE) at its CPU time (s), one point per
    validation."""

    cpu_s: list[float]
    raw: list[float]
    smooth: list[float]
    total_cpu_s: float

    @property
    def best(self) -> float:
        """The lowest smoothed criterion (the one the fit's final model was chosen at)."""
        return min(self.smooth)

    @classmethod
    def from_result(cls, res: dict) -> Curve:
        h = res["history"]
        cpu = h.get("cpu_s") or []
        if len(cpu) != len(h["raw"]) or any(c is None for c in cpu) or res.get("cpu_s") is None:
            raise DataError(
                f"{res.get('model', 'fit')} fold {res.get('index')}: no CPU times in its "
                "history (fitted before they were recorded); refit it (--refit)"
            )
        return cls(list(cpu), list(h["raw"]), list(h["smooth"]), float(res["cpu_s"]))

    @property
    def best_cpu_s(self) -> float:
        """CPU time (s) of the first point at the best smoothed criterion."""
        return self.cpu_s[self.smooth.index(self.best)]

    def reach(self, target: float) -> float | None:
        """CPU time (s) of the first point whose smoothed criterion is <= target."""
        return next((c for c, s in zip(self.cpu_s, self.smooth, strict=True) if s <= target), None)


@dataclass
class FoldTTA:
    """Both recipes on one fold."""

    index: int
    paper: Curve
    fast: Curve
    paper_score: FoldScore
    fast_score: FoldScore

    @property
    def target(self) -> float:
        return self.paper.best

    @property
    def reach_cpu_s(self) -> float | None:
        return self.fast.reach(self.target)

    @property
    def speedup_reach(self) -> float:
        """The paper fit's CPU time to its own best / the fast fit's CPU time to reach it."""
        r = self.reach_cpu_s
        return self.paper.best_cpu_s / r if r else math.nan

    @property
    def speedup_total(self) -> float:
        return self.paper.total_cpu_s / self.fast.total_cpu_s

    def to_json(self) -> dict:
        d = asdict(self)
        d["paper"]["best"], d["fast"]["best"] = self.paper.best, self.fast.best
        d["paper"]["best_cpu_s"], d["fast"]["best_cpu_s"] = (
            self.paper.best_cpu_s, self.fast.best_cpu_s)
        d.update(
            target=self.target,
            reach_cpu_s=self.reach_cpu_s,
            speedup_reach=self.speedup_reach,
            speedup_total=self.speedup_total,
        )
        return d


@dataclass
class TTAResult:
    folds: list[FoldTTA]
    required_speedup: float

    def rows(self) -> list[list]:
        out = []
        for f in self.folds:
            out.append(
                [
                    f"fold {f.index}",
                    f.paper.total_cpu_s,
                    f.paper.best_cpu_s,
                    f.target,
                    f.paper_score.vx,
                    f.paper_score.yaw,
                    f.fast.total_cpu_s,
                    f.fast.best,
                    f.fast_score.vx,
                    f.fast_score.yaw,
                    *(
                        (f.reach_cpu_s, f.speedup_reach)
                        if f.reach_cpu_s is not None
                        else (f"not reached (best {f.fast.best / f.target - 1:+.0%})", "-")
                    ),
                    f.speedup_total,
                ]
            )
        return out

    def met(self) -> bool:
        """The fast recipe reached the paper's error on every fold within 1/required of the
        paper fit's CPU time to that error."""
        return bool(self.folds) and all(
            f.reach_cpu_s is not None and f.speedup_reach >= self.required_speedup
            for f in self.folds
        )

    def to_json(self) -> dict:
        return {
            "folds": [f.to_json() for f in self.folds],
            "required_speedup": self.required_speedup,
            "met": self.met(),
        }


COLUMNS = [
    "",
    "paper CPU [s]",
    "paper CPU to best [s]",
    "paper criterion",
    "paper vx",
    "paper ω_z",
    "fast CPU [s]",
    "fast criterion",
    "fast vx",
    "fast ω_z",
    "fast reaches at [s]",
    "speed-up (reach)",
    "speed-up (total)",
]


def tta_jobs(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> list[Job]:
    """Paper and fast recipe fits of every fold of the budget's ``tta_folds``, in pairs
    (the paper one is that fold's Table II NSS fit)."""
    b = cfg.budget(quick)
    paper_ov = b.deployment_overrides()
    jobs = []
    for i in b.tta_folds:
        jobs.append(fold_spec(sweep, "cv", i, paper_ov, name=f"paper recipe fold {i}"))
        jobs.append(
            fold_spec(sweep, "cv", i, merge_overrides(paper_ov, FAST), name=f"fast recipe fold {i}")
        )
    return jobs


def time_to_accuracy(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> TTAResult:
    """Fit both recipes on every fold of the budget's ``tta_folds`` (CV split)."""
    b = cfg.budget(quick)
    res = sweep.run(tta_jobs(cfg, quick, sweep), "time to accuracy")
    folds = [
        FoldTTA(
            i,
            Curve.from_result(p),
            Curve.from_result(f),
            FoldScore.from_json(p),
            FoldScore.from_json(f),
        )
        for i, p, f in zip(b.tta_folds, res[0::2], res[1::2], strict=True)
    ]
    return TTAResult(folds, cfg.tta_speedup)
