"""Data splits of paper §IV-B: stratified 4-fold CV, leave-r-repeats-out, determinism."""

from __future__ import annotations

from collections import Counter

import pytest

from helpers.synth import make_campaign
from parknss.data.splits import all_trials, leave_r_out, stratified_folds
from parknss.data.trial import Campaign
from parknss.errors import DataError

CAMP = make_campaign(30, reps=4)
CLASS = {tr.id: tr.maneuver for tr in CAMP}
REP = {tr.id: tr.repetition for tr in CAMP}


def _check_partition(f):
    assert not set(f.train) & set(f.val)
    assert set(f.train) | set(f.val) == set(CAMP.ids)
    # campaign order kept
    assert list(f.train) == [i for i in CAMP.ids if i in f.train]


@pytest.mark.parametrize("seed", [None, 0, 7])
def test_stratified_four_fold(seed):
    folds = stratified_folds(CAMP, seed)
    assert len(folds) == 4 and [f.index for f in folds] == [0, 1, 2, 3]
    held = Counter()
    for f in folds:
        _check_partition(f)
        assert len(f.train) == 12 and len(f.val) == 4
        assert sorted(CLASS[i] for i in f.val) == sorted(set(CLASS.values()))  # one per class
        held.update(f.val)
    assert held == Counter({i: 1 for i in CAMP.ids})  # every trial held out exactly once
    if seed is None:  # repetition order: fold k holds out repetition k + 1
        assert all({REP[i] for i in f.val} == {f.index + 1} for f in folds)


@pytest.mark.parametrize(("r", "n_train"), [(1, 12), (2, 8), (3, 4)])
def test_leave_r_out_sizes(r, n_train):
    folds = leave_r_out(CAMP, r)
    assert len(folds) == 4
    held = Counter()
    for f in folds:
        _check_partition(f)
        assert len(f.train) == n_train and len(f.val) == 16 - n_train
        assert Counter(CLASS[i] for i in f.train) == Counter(
            {c: 4 - r for c in set(CLASS.values())}
        )
        held.update(f.val)
    assert held == Counter({i: r for i in CAMP.ids})  # cyclic: each trial held out r times
    assert [f.train for f in leave_r_out(CAMP, 1)] == [f.train for f in stratified_folds(CAMP)]


def test_determinism_under_seed():
    a, b = stratified_folds(CAMP, seed=3), stratified_folds(CAMP, seed=3)
    assert a == b
    assert leave_r_out(CAMP, 2, seed=5) == leave_r_out(CAMP, 2, seed=5)
    base = [f.val for f in stratified_folds(CAMP)]
    assert any([f.val for f in stratified_folds(CAMP, seed=s)] != base for s in range(5))
    # the permutation is shared by the classes: a fold holds out one repetition index
    for f in stratified_folds(CAMP, seed=3):
        assert len({REP[i] for i in f.val}) == 1


def test_refusals_and_deployment_split():
    with pytest.raises(DataError, match="equally many"):
        stratified_folds(Campaign(list(CAMP)[:-1]))
    for r in (0, 4):
        with pytest.raises(DataError):
            leave_r_out(CAMP, r)
    f = all_trials(CAMP)
    assert f.train == tuple(CAMP.ids) and f.val == ()
    assert f.to_json()["train"] == CAMP.ids
