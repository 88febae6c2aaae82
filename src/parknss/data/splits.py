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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parknss.data.trial import Campaign
from parknss.errors import DataError


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
