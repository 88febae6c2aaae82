"""Data splits of paper §IV-B: stratified 4-fold CV and the leave-r-repeats-out grid.

Stratified k-fold: every fold holds out one trial per maneuver class. Within each class
the trials are ordered by repetition; fold k holds out the class's (k+1)-th trial (with
``seed`` given, a seeded permutation of each class's trials is used instead of the
repetition order, the same permutation for every fold). With 4 classes x 4 repetitions
this is 12 training and 4 validation trials per fold, and every trial is held out once.

Leave-r-repeats-out (r = 1, 2, 3; four folds each): fold k holds out, in every class, the
trials at positions k, k+1, ..., k+r-1 (cyclic), so r = 1 is the stratified 4-fold, r = 3
trains on one trial per class (4 trials) and the grid spans 4 to 12 training trials.
All splits are deterministic functions of the campaign's class and repetition labels.

Fallbacks (:func:`cv_plan`, :func:`leave_r_out_plan`): a campaign is *not stratifiable*
for k folds when some trial is unlabelled (class :data:`~parknss.data.trial.UNLABELLED`),
a class has fewer than k trials, or the classes differ in size. Then

* the k-fold CV is plain k-fold over the trials (:func:`plain_k_fold`): the trials in
  campaign order (a seeded permutation of it when ``seed`` is given), fold j holds out
  positions j, j+k, j+2k, ... (interleaved, so a campaign recorded class by class or
  session by session spreads each over the folds);
* the leave-r-repeats-out grid keeps each plain fold's held-out trials and trains on a
  seeded random subset of its training trials of round(n_train · (k - r) / (k - 1))
  trials, the sizes the stratified grid would have (12, 8, 4 of 16 trials at k = 4);
  the subsets of one fold are nested (one permutation per fold, its first n trials).

A :class:`FoldPlan` says which happened: ``stratified`` and a one-line ``note``. A
stratifiable campaign gives exactly the folds of :func:`stratified_folds` and
:func:`leave_r_out`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parknss.data.trial import UNLABELLED, Campaign
from parknss.errors import DataError

DEFAULT_FOLDS = 4  # the paper's k: 4 classes x 4 repetitions, one repetition per fold


@dataclass(frozen=True)
class Fold:
    """One split: trial ids for training and for validation (campaign order)."""

    index: int
    train: tuple[str, ...]
    val: tuple[str, ...]
    name: str = ""

    def to_json(self) -> dict:
        return {
            "index": self.index,
            "name": self.name,
            "train": list(self.train),
            "val": list(self.val),
        }


def _ordered_classes(campaign: Campaign, seed: int | None) -> dict[str, list[str]]:
    by_class = campaign.by_class()
    sizes = {len(v) for v in by_class.values()}
    if len(sizes) != 1:
        counts = ", ".join(f"{c}: {len(v)}" for c, v in by_class.items())
        raise DataError(f"stratified splits need equally many trials per class ({counts})")
    out = {c: [tr.id for tr in trs] for c, trs in by_class.items()}
    if seed is not None:
        rng = np.random.default_rng(seed)
        k = sizes.pop()
        perm = rng.permutation(k)
        out = {c: [ids[i] for i in perm] for c, ids in out.items()}
    return out


def _fold(campaign: Campaign, index: int, held: set[str], name: str) -> Fold:
    train = tuple(tr.id for tr in campaign if tr.id not in held)
    val = tuple(tr.id for tr in campaign if tr.id in held)
    return Fold(index, train, val, name)


def leave_r_out(campaign: Campaign, r: int, seed: int | None = None) -> list[Fold]:
    """The k folds (k = trials per class) holding out r cyclic positions per class."""
    classes = _ordered_classes(campaign, seed)
    k = len(next(iter(classes.values())))
    if not 1 <= r < k:
        raise DataError(f"leave-{r}-out needs 1 <= r < {k} (trials per class)")
    folds = []
    for i in range(k):
        pos = [(i + j) % k for j in range(r)]
        held = {ids[p] for ids in classes.values() for p in pos}
        folds.append(_fold(campaign, i, held, f"leave{r}out_fold{i}"))
    return folds


def stratified_folds(campaign: Campaign, seed: int | None = None) -> list[Fold]:
    """Stratified k-fold: fold k holds out the (k+1)-th trial of every class."""
    folds = leave_r_out(campaign, 1, seed)
    return [Fold(f.index, f.train, f.val, f"fold{f.index}") for f in folds]


def all_trials(campaign: Campaign) -> Fold:
    """The deployment 'split': every trial trains, none validates."""
    return Fold(0, tuple(campaign.ids), (), "all")


# ------------------------------------------------------------------ plans and fallbacks


@dataclass(frozen=True)
class FoldPlan:
    """The folds of one split and how they were made.

    Attributes:
        folds: the folds, index order.
        stratified: True when the folds are the stratified ones of :func:`stratified_folds`
            / :func:`leave_r_out`, False for the plain k-fold fallback.
        note: one line saying which, and why not stratified.
    """

    folds: tuple[Fold, ...]
    stratified: bool
    note: str

    def to_json(self) -> dict:
        return {
            "stratified": self.stratified,
            "note": self.note,
            "folds": [f.to_json() for f in self.folds],
        }


def stratify_problem(campaign: Campaign, k: int = DEFAULT_FOLDS) -> str | None:
    """Why ``campaign`` cannot be split stratified into ``k`` folds, or None if it can."""
    unlabelled = sum(tr.maneuver == UNLABELLED for tr in campaign)
    if unlabelled:
        return f"{unlabelled} of {len(campaign)} trials are {UNLABELLED}"
    sizes = {c: len(v) for c, v in campaign.by_class().items()}
    small = [c for c, n in sizes.items() if n < k]
    if small:
        return f"class {small[0]!r} has {sizes[small[0]]} trials, fewer than the {k} folds"
    if len(set(sizes.values())) > 1:
        return "classes differ in size (" + ", ".join(f"{c}: {n}" for c, n in sizes.items()) + ")"
    return None


def plain_k_fold(campaign: Campaign, k: int = DEFAULT_FOLDS, seed: int | None = None) -> list[Fold]:
    """Plain k-fold over the trials: fold j holds out positions j, j+k, ... of the campaign
    order (of a ``seed``-ed permutation of it when given). Every trial is held out once."""
    n = len(campaign)
    if k < 2:
        raise DataError(f"k-fold CV needs k >= 2 folds, got {k}")
    if n < k:
        raise DataError(f"{k}-fold CV needs at least {k} trials; the campaign has {n}")
    ids = campaign.ids
    order = (
        list(range(n))
        if seed is None
        else [int(i) for i in np.random.default_rng(seed).permutation(n)]
    )
    return [_fold(campaign, j, {ids[i] for i in order[j::k]}, f"fold{j}") for j in range(k)]


def _fallback_note(problem: str, what: str) -> str:
    return f"not stratifiable ({problem}): {what}"


def cv_plan(campaign: Campaign, k: int = DEFAULT_FOLDS, seed: int | None = None) -> FoldPlan:
    """The CV folds: :func:`stratified_folds` when stratifiable, else :func:`plain_k_fold`."""
    problem = stratify_problem(campaign, k)
    if problem is None:
        folds = stratified_folds(campaign, seed)
        n_cls = len(campaign.classes())
        note = (
            f"stratified {len(folds)}-fold CV: each fold holds out one trial of each of the "
            f"{n_cls} maneuver classes"
        )
        return FoldPlan(tuple(folds), True, note)
    order = "campaign order" if seed is None else f"order permuted with seed {seed}"
    what = (
        f"plain {k}-fold CV over the {len(campaign)} trials instead (fold j holds out every "
        f"{k}-th trial from position j, {order})"
    )
    return FoldPlan(tuple(plain_k_fold(campaign, k, seed)), False, _fallback_note(problem, what))


def subset_size(n_train: int, r: int, k: int) -> int:
    """Training trials kept for ``r`` of the fallback grid: round(n_train (k-r)/(k-1)), >= 1."""
    return max(1, round(n_train * (k - r) / (k - 1)))


def random_subset_folds(
    campaign: Campaign, r: int, k: int = DEFAULT_FOLDS, seed: int | None = None
) -> list[Fold]:
    """The leave-r-out fallback: each plain k-fold fold, its training trials cut to a seeded
    random subset of :func:`subset_size` trials (nested over r: one permutation per fold,
    drawn from ``default_rng([seed or 0, fold index])``)."""
    if not 1 <= r < k:
        raise DataError(f"leave-{r}-out needs 1 <= r < {k} (folds)")
    out = []
    for f in plain_k_fold(campaign, k, seed):
        rng = np.random.default_rng([0 if seed is None else seed, f.index])
        perm = rng.permutation(len(f.train))
        keep = {f.train[i] for i in perm[: subset_size(len(f.train), r, k)]}
        train = tuple(i for i in f.train if i in keep)
        out.append(Fold(f.index, train, f.val, f"leave{r}out_fold{f.index}"))
    return out


def leave_r_out_plan(
    campaign: Campaign, r: int, k: int = DEFAULT_FOLDS, seed: int | None = None
) -> FoldPlan:
    """The leave-r-repeats-out folds: :func:`leave_r_out` when stratifiable, else
    :func:`random_subset_folds`."""
    problem = stratify_problem(campaign, k)
    if problem is None:
        folds = leave_r_out(campaign, r, seed)
        note = (
            f"stratified leave-{r}-repeats-out: each fold holds out {r} trial(s) of each of "
            f"the {len(campaign.classes())} maneuver classes"
        )
        return FoldPlan(tuple(folds), True, note)
    folds = random_subset_folds(campaign, r, k, seed)
    sizes = sorted({len(f.train) for f in folds})
    what = (
        f"instead of leaving {r} repeat(s) per class out, each plain {k}-fold fold trains on "
        f"a seeded random subset of {'/'.join(map(str, sizes))} of its training trials and "
        "scores its held-out trials"
    )
    return FoldPlan(tuple(folds), False, _fallback_note(problem, what))
