"""The learning curve (paper §IV-B "Data Splits", §V-A, the learning-curve figure).

Leave-r-repeats-out with r = 1, 2, 3 (four folds each) on 16 trials gives training sets of
12, 8 and 4 trials, all fitted at one matched epoch budget. Per size: the fold errors (the
boxes) and their mean; a power law e(n) = a·n^(-b) fitted to the fold means by least squares
in log-log space is extrapolated to the all-trials deployment model (n = 16), whose
held-out error cannot be measured because no trial is left out.

On a campaign that is not stratifiable (unlabelled trials, a class with fewer trials than
folds, classes of different sizes) the grid falls back to seeded random subsets of each
plain k-fold fold's training trials of the same sizes, scored on that fold's held-out
trials (:func:`~parknss.data.splits.leave_r_out_plan`); the result says so in
``stratified`` and ``note``.
"""

from __future__ import annotations

import contextlib
import itertools
import math
from dataclasses import asdict, dataclass

import numpy as np

from parknss.data.splits import DEFAULT_FOLDS, stratify_problem
from parknss.errors import DataError
from parknss.executor import Job
from parknss.experiments.config import ExperimentsConfig
from parknss.experiments.folds import fold_plan, make_fold
from parknss.experiments.sweep import FoldScore, Sweep, fold_spec, nanmean


@dataclass
class PowerLaw:
    """e(n) = a · n^(-b) (b > 0: error falls with data)."""

    a: float
    b: float

    def __call__(self, n):
        return self.a * np.asarray(n, dtype=float) ** (-self.b)


def fit_power_law(n, e) -> PowerLaw:
    """Least-squares fit of log e = log a - b log n; needs >= 2 distinct n, e > 0."""
    n = np.asarray(n, dtype=float)
    e = np.asarray(e, dtype=float)
    ok = np.isfinite(e) & (e > 0) & (n > 0)
    if len(np.unique(n[ok])) < 2:
        raise DataError("a power-law fit needs positive errors at two or more sizes")
    slope, intercept = np.polyfit(np.log(n[ok]), np.log(e[ok]), 1)
    return PowerLaw(a=float(math.exp(intercept)), b=float(-slope))


@dataclass
class CurvePoint:
    """One training-set size: its r, the fold scores and their means."""

    r: int
    n_train: int
    folds: list[int]
    scores: list[FoldScore]

    def values(self, channel: str) -> list[float]:
        return [getattr(s, channel) for s in self.scores]

    def mean(self, channel: str) -> float:
        return nanmean(self.values(channel))


@dataclass
class LearningCurveResult:
    """Points by increasing training-set size and the fits per channel; ``stratified``
    False and ``note`` saying why when the grid fell back to random training subsets."""

    points: list[CurvePoint]
    fits: dict[str, PowerLaw]
    extrapolate_to: int
    epochs: int
    stratified: bool = True
    note: str = ""

    def sizes(self) -> list[int]:
        return [p.n_train for p in self.points]

    def means(self, channel: str) -> list[float]:
        return [p.mean(channel) for p in self.points]

    def extrapolated(self, channel: str) -> float:
        f = self.fits.get(channel)
        return float(f(self.extrapolate_to)) if f else math.nan

    def descending(self, channel: str) -> bool:
        """Fold means fall strictly from each size to the next larger one."""
        m = self.means(channel)
        return all(b < a for a, b in itertools.pairwise(m))

    def to_json(self) -> dict:
        return {
            "epochs": self.epochs,
            "extrapolate_to": self.extrapolate_to,
            "points": [
                {
                    "r": p.r,
                    "n_train": p.n_train,
                    "folds": p.folds,
                    "scores": [asdict(s) for s in p.scores],
                }
                for p in self.points
            ],
            "fits": {k: asdict(v) for k, v in self.fits.items()},
            "extrapolated": {k: self.extrapolated(k) for k in self.fits},
            "stratified": self.stratified,
            "note": self.note,
        }


def grid_note(
    campaign, rs: list[int] | tuple[int, ...], k: int = DEFAULT_FOLDS
) -> tuple[bool, str]:
    """(stratified, one-line note) of the learning-curve grid on ``campaign``."""
    problem = stratify_problem(campaign, k)
    r_list = ", ".join(map(str, rs))
    if problem is None:
        return True, f"stratified leave-r-repeats-out, r = {r_list}, in every maneuver class"
    return False, (
        f"not stratifiable ({problem}): leave-r-repeats-out (r = {r_list}) replaced by "
        f"seeded random subsets of the same sizes of each plain {k}-fold fold's training "
        "trials, scored on that fold's held-out trials"
    )


def curve_jobs(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> list[tuple[int, Job]]:
    """(r, job) for every (r, fold) of the grid, at the budget's study overrides. A
    leave-r-out fold that is the CV fold of its index (the same training and held-out
    trials: r = 1 on a stratified campaign) is spelled as that CV fold, so its fit is the
    one Table III's deployed option, the limiter study and the seed-noise study make."""
    budget = cfg.budget(quick)
    ov = budget.study_overrides()
    campaign = sweep.campaign()
    cv = fold_plan(campaign, "cv").folds
    jobs = []
    for r in cfg.learning_curve_rs:
        for k in budget.folds:
            leave = make_fold(campaign, "leave", k, r)
            same = k < len(cv) and (leave.train, leave.val) == (cv[k].train, cv[k].val)
            split, rr = ("cv", 1) if same else ("leave", r)
            jobs.append((r, fold_spec(sweep, split, k, ov, r=rr, name=f"leave{r} fold{k}")))
    return jobs


def learning_curve(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> LearningCurveResult:
    """Fit every (r, fold) of the grid at the budget's epochs; fit and extrapolate."""
    budget = cfg.budget(quick)
    stratified, note = grid_note(sweep.campaign(), cfg.learning_curve_rs)
    grid = curve_jobs(cfg, quick, sweep)
    results = sweep.run([j for _, j in grid], "learning curve")
    points = []
    for r in cfg.learning_curve_rs:
        scores = [
            FoldScore.from_json(res) for (rr, _), res in zip(grid, results, strict=True) if rr == r
        ]
        points.append(CurvePoint(r, scores[0].n_train, list(budget.folds), scores))
    points.sort(key=lambda p: p.n_train)
    fits = {}
    for ch in ("vx", "yaw"):
        with contextlib.suppress(DataError):
            fits[ch] = fit_power_law([p.n_train for p in points], [p.mean(ch) for p in points])
    return LearningCurveResult(
        points, fits, cfg.extrapolate_to, budget.epochs, stratified=stratified, note=note
    )
