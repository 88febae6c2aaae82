"""Time to accuracy of the training recipes: held-out error against CPU time, per CV fold.

For each fold of the budget's ``tta_folds``, fits of the NSS on the same split: the paper
recipe (the Table II fold job itself, so the result store shares the fit) and each
challenger recipe of the budget's ``tta_recipes`` (``fast``, ``coarse``:
:mod:`parknss.nss.recipes`; ``coarse+native``: that recipe with the fused engine's
``native`` kernels, :mod:`parknss.nss.fused_native`). Each fit's history gives the
held-out criterion (moving-region state loss of whole-trial open-loop rollouts, the value
the best checkpoint is chosen on; raw and smoothed) at the fit's CPU time.

* target: the paper fit's best smoothed criterion (the error its final model was chosen
  at);
* reach: the CPU time at which a challenger's smoothed criterion first falls to the target
  (None if it never does);
* speed-ups: the paper fit's CPU time to its own best (the first point at its best smoothed
  criterion, not its total: a fit that peaks early is charged only what its best cost) /
  the challenger's CPU time to reach, and paper / challenger total CPU time;
* the Table II scores of the final models (vx, ω_z moving-region MSE) beside them.

The goal (``tta_speedup``) is met when one challenger recipe reaches the target within
1/``tta_speedup`` of the paper fit's CPU time to it on every fold.

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

    def to_json(self) -> dict:
        """The curve with its best smoothed criterion and the CPU time it was first at."""
        return asdict(self) | {"best": self.best, "best_cpu_s": self.best_cpu_s}

    def reach(self, target: float) -> float | None:
        """CPU time (s) of the first point whose smoothed criterion is <= target."""
        return next((c for c, s in zip(self.cpu_s, self.smooth, strict=True) if s <= target), None)


@dataclass
class Challenger:
    """One of this toolkit's recipes on a fold: its curve and the Table II scores of its
    final model."""

    recipe: str
    curve: Curve
    score: FoldScore


@dataclass
class FoldTTA:
    """The paper recipe and each challenger recipe on one fold."""

    index: int
    paper: Curve
    paper_score: FoldScore
    challengers: list[Challenger]

    @property
    def target(self) -> float:
        return self.paper.best

    def of(self, recipe: str) -> Challenger:
        """The challenger fitted with ``recipe``."""
        for c in self.challengers:
            if c.recipe == recipe:
                return c
        raise KeyError(recipe)

    def reach_cpu_s(self, recipe: str) -> float | None:
        """CPU s at which ``recipe``'s fit first reaches the target (None: never)."""
        return self.of(recipe).curve.reach(self.target)

    def speedup_reach(self, recipe: str) -> float:
        """The paper fit's CPU time to its own best / ``recipe``'s CPU time to reach it."""
        r = self.reach_cpu_s(recipe)
        return self.paper.best_cpu_s / r if r else math.nan

    def speedup_total(self, recipe: str) -> float:
        return self.paper.total_cpu_s / self.of(recipe).curve.total_cpu_s

    def to_json(self) -> dict:
        out = {"index": self.index, "paper": self.paper.to_json(),
               "paper_score": asdict(self.paper_score), "target": self.target,
               "challengers": {}}
        for c in self.challengers:
            out["challengers"][c.recipe] = {
                "curve": c.curve.to_json(),
                "score": asdict(c.score),
                "reach_cpu_s": self.reach_cpu_s(c.recipe),
                "speedup_reach": self.speedup_reach(c.recipe),
                "speedup_total": self.speedup_total(c.recipe),
            }
        return out


@dataclass
class TTAResult:
    folds: list[FoldTTA]
    required_speedup: float

    @property
    def recipes(self) -> list[str]:
        return [c.recipe for c in self.folds[0].challengers] if self.folds else []

    def rows(self) -> list[list]:
        out = []
        for f in self.folds:
            for c in f.challengers:
                r = f.reach_cpu_s(c.recipe)
                out.append(
                    [
                        f"fold {f.index}",
                        c.recipe,
                        f.paper.total_cpu_s,
                        f.paper.best_cpu_s,
                        f.target,
                        f.paper_score.vx,
                        f.paper_score.yaw,
                        c.curve.total_cpu_s,
                        c.curve.best,
                        c.score.vx,
                        c.score.yaw,
                        *(
                            (r, f.speedup_reach(c.recipe))
                            if r is not None
                            else (f"not reached (best {c.curve.best / f.target - 1:+.0%})", "-")
                        ),
                        f.speedup_total(c.recipe),
                    ]
                )
        return out

    def met_by(self, recipe: str) -> bool:
        """``recipe`` reached the paper's error on every fold within 1/required of the paper
        fit's CPU time to that error."""
        return bool(self.folds) and all(
            f.reach_cpu_s(recipe) is not None and f.speedup_reach(recipe) >= self.required_speedup
            for f in self.folds
        )

    def met(self) -> bool:
        """Some challenger recipe meets the goal on every fold."""
        return any(self.met_by(r) for r in self.recipes)

    def to_json(self) -> dict:
        return {
            "folds": [f.to_json() for f in self.folds],
            "required_speedup": self.required_speedup,
            "met": self.met(),
            "met_by": [r for r in self.recipes if self.met_by(r)],
        }


COLUMNS = [
    "",
    "recipe",
    "paper CPU [s]",
    "paper CPU to best [s]",
    "paper criterion",
    "paper vx",
    "paper ω_z",
    "CPU [s]",
    "criterion",
    "vx",
    "ω_z",
    "reaches the paper's best at [s]",
    "speed-up (reach)",
    "speed-up (total)",
]


def tta_jobs(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> list[Job]:
    """Per fold of the budget's ``tta_folds``: the paper recipe's fit (that fold's Table
    II NSS fit) and one fit of each challenger of the budget's ``tta_recipes`` (a recipe,
    or ``recipe+kernels``: :func:`challenger_overrides`)."""
    b = cfg.budget(quick)
    paper_ov = b.deployment_overrides()
    jobs = []
    for i in b.tta_folds:
        jobs.append(fold_spec(sweep, "cv", i, paper_ov, name=f"paper recipe fold {i}"))
        for name in b.tta_recipes:
            ov = merge_overrides(paper_ov, challenger_overrides(name))
            jobs.append(fold_spec(sweep, "cv", i, ov, name=f"{name} recipe fold {i}"))
    return jobs


def challenger_overrides(name: str) -> dict:
    """The NSS overrides of a challenger named ``recipe`` or ``recipe+kernels`` (the fused
    kernels it trains with, ``model.fused_kernels``; without: the config's)."""
    recipe, _, kernels = name.partition("+")
    over: dict = {"train": {"recipe": recipe}}
    if kernels:
        over["model"] = {"fused_kernels": kernels}
    return over


def time_to_accuracy(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> TTAResult:
    """Fit every recipe on every fold of the budget's ``tta_folds`` (CV split)."""
    b = cfg.budget(quick)
    res = sweep.run(tta_jobs(cfg, quick, sweep), "time to accuracy")
    per = 1 + len(b.tta_recipes)
    folds = []
    for j, i in enumerate(b.tta_folds):
        p, *others = res[j * per : (j + 1) * per]
        folds.append(FoldTTA(
            i, Curve.from_result(p), FoldScore.from_json(p),
            [Challenger(r, Curve.from_result(o), FoldScore.from_json(o))
             for r, o in zip(b.tta_recipes, others, strict=True)],
        ))
    return TTAResult(folds, cfg.tta_speedup)
