"""Fold plans: labelled campaigns keep exactly their stratified folds; unlabelled or
unstratifiable ones fall back to plain k-fold (CV) and to seeded random training subsets
of the same sizes (learning curve), and say so."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml

from helpers.experiments import TINY_CONFIG
from helpers.synth import make_campaign
from parknss.cli import main
from parknss.config import BUNDLED_CAMPAIGN
from parknss.data.io import write_campaign
from parknss.data.splits import (
    DEFAULT_FOLDS,
    cv_plan,
    leave_r_out_plan,
    plain_k_fold,
    stratify_problem,
)
from parknss.data.trial import MANEUVER_CLASSES, UNLABELLED, Campaign, Trial
from parknss.errors import DataError
from parknss.experiments.cv import CVResult
from parknss.experiments.folds import make_fold
from parknss.experiments.learning_curve import grid_note


def _stub(tid: str, cls: str, rep: int) -> Trial:
    return Trial(tid, cls, rep, {"t": np.arange(3) * 0.01})


def default_ids_campaign() -> Campaign:
    """The bundled campaign's ids, classes and repetitions (its campaign.json), no data."""
    path = Path(BUNDLED_CAMPAIGN) / "campaign.json"
    if path.is_file():
        entries = json.loads(path.read_text())["trials"]
        trials = [_stub(e["id"], e["maneuver"], e["repetition"]) for e in entries]
    else:  # the generator's order: class by class, repetitions 1..4
        trials = [_stub(f"{c}_r{r}", c, r) for c in MANEUVER_CLASSES for r in range(1, 5)]
    return Campaign(trials, name="default-ids")


def unlabelled(n: int) -> Campaign:
    """n unlabelled trials, as the reader names them (repetitions 1..n in file order)."""
    return Campaign([_stub(f"log{i:02d}", UNLABELLED, i) for i in range(1, n + 1)])


# Held-out repetitions per fold, as stratified_folds / leave_r_out gave them before the
# fallbacks existed (computed with the previous splits.py on the default campaign ids).
EXPECTED_REPS = {
    ("cv", 1, None): [[1], [2], [3], [4]],
    ("cv", 1, 0): [[3], [1], [2], [4]],
    ("cv", 1, 3): [[4], [3], [2], [1]],
    ("leave", 2, None): [[1, 2], [2, 3], [3, 4], [1, 4]],
    ("leave", 2, 0): [[1, 3], [1, 2], [2, 4], [3, 4]],
    ("leave", 2, 3): [[3, 4], [2, 3], [1, 2], [1, 4]],
    ("leave", 3, None): [[1, 2, 3], [2, 3, 4], [1, 3, 4], [1, 2, 4]],
    ("leave", 3, 0): [[1, 2, 3], [1, 2, 4], [2, 3, 4], [1, 3, 4]],
    ("leave", 3, 3): [[2, 3, 4], [1, 2, 3], [1, 2, 4], [1, 3, 4]],
}


@pytest.mark.parametrize(("split", "r", "seed"), list(EXPECTED_REPS))
def test_labelled_campaign_keeps_exactly_its_folds(split, r, seed):
    camp = default_ids_campaign()
    plan = cv_plan(camp, seed=seed) if split == "cv" else leave_r_out_plan(camp, r, seed=seed)
    assert plan.stratified and "stratified" in plan.note and "not" not in plan.note
    for i, (fold, reps) in enumerate(zip(plan.folds, EXPECTED_REPS[split, r, seed], strict=True)):
        val = tuple(tr.id for tr in camp if tr.repetition in reps)
        assert fold.index == i and fold.val == val
        assert fold.train == tuple(tr.id for tr in camp if tr.id not in val)
        assert fold.name == (f"fold{i}" if split == "cv" else f"leave{r}out_fold{i}")
        assert make_fold(camp, split, i, r, seed) == fold  # what every fold job builds


@pytest.mark.parametrize(
    ("camp", "why"),
    [
        (unlabelled(10), f"10 of 10 trials are {UNLABELLED}"),
        (make_campaign(20, reps=3), "class 'park_in_left' has 3 trials, fewer than the 4 folds"),
        (Campaign(make_campaign(20, reps=5).trials[:-1]), "classes differ in size"),
    ],
)
def test_unstratifiable_campaigns_fall_back_to_plain_k_fold(camp, why):
    assert why in stratify_problem(camp)
    plan = cv_plan(camp)
    assert not plan.stratified and plan.note.startswith(f"not stratifiable ({why}")
    assert "plain 4-fold" in plan.note and "\n" not in plan.note
    assert len(plan.folds) == DEFAULT_FOLDS
    held = Counter(i for f in plan.folds for i in f.val)
    assert held == Counter({i: 1 for i in camp.ids})  # every trial held out exactly once
    sizes = [len(f.val) for f in plan.folds]
    assert max(sizes) - min(sizes) <= 1
    for f in plan.folds:
        assert set(f.train) | set(f.val) == set(camp.ids) and not set(f.train) & set(f.val)
        assert list(f.train) == [i for i in camp.ids if i in f.train]  # campaign order


def test_plain_k_fold_interleaves_and_is_deterministic_under_the_seed():
    camp = unlabelled(10)
    folds = plain_k_fold(camp, 4)
    assert [f.val for f in folds][:2] == [("log01", "log05", "log09"), ("log02", "log06", "log10")]
    assert plain_k_fold(camp, 4, seed=5) == plain_k_fold(camp, 4, seed=5)
    assert cv_plan(camp, seed=5).folds == tuple(plain_k_fold(camp, 4, seed=5))
    vals = {tuple(f.val for f in plain_k_fold(camp, 4, seed=s)) for s in range(6)}
    assert len(vals) > 1  # the seed matters
    with pytest.raises(DataError, match="at least 4 trials"):
        plain_k_fold(unlabelled(3), 4)


def test_learning_curve_fallback_subsets_have_the_stratified_sizes():
    camp = unlabelled(16)
    base = plain_k_fold(camp, 4)
    by_r = {r: leave_r_out_plan(camp, r) for r in (1, 2, 3)}
    for r, n_train in ((1, 12), (2, 8), (3, 4)):  # as leave-r-out of 4 classes x 4 trials
        plan = by_r[r]
        assert not plan.stratified and "seeded random subset" in plan.note
        for f, b in zip(plan.folds, base, strict=True):
            assert len(f.train) == n_train and f.val == b.val  # same held-out trials
            assert set(f.train) <= set(b.train)
            assert list(f.train) == [i for i in camp.ids if i in f.train]
    for i in range(4):  # nested: a smaller training set is inside the larger one
        assert set(by_r[3].folds[i].train) <= set(by_r[2].folds[i].train)
        assert set(by_r[2].folds[i].train) <= set(by_r[1].folds[i].train)
    assert leave_r_out_plan(camp, 2, seed=4) == leave_r_out_plan(camp, 2, seed=4)
    draws = {leave_r_out_plan(camp, 2, seed=s).folds[0].train for s in range(6)}
    assert len(draws) > 1
    with pytest.raises(DataError):
        leave_r_out_plan(camp, 4)
    ok, note = grid_note(camp, [1, 2, 3])
    assert not ok and note.startswith(f"not stratifiable (16 of 16 trials are {UNLABELLED})")
    assert grid_note(default_ids_campaign(), [1, 2, 3])[0]


def test_cv_result_carries_the_note():
    res = CVResult({"linear": []}, stratified=False, note="not stratifiable (x): plain")
    assert res.to_json()["stratified"] is False and res.to_json()["note"].startswith("not")
    table = res.table()
    assert "plain 4-fold CV" in table.splitlines()[0] and table.splitlines()[1].startswith("not")


def test_cv_command_on_unlabelled_campaign_prints_the_note(tmp_path, capsys):
    src = make_campaign(400, reps=2)
    trials = [
        Trial(f"log{i:02d}", UNLABELLED, i, tr.channels) for i, tr in enumerate(src.trials, 1)
    ]
    data = write_campaign(Campaign(trials, name="unlabelled"), tmp_path / "camp")
    args = ["cv", "--data", str(data), "--variants", "linear", "--workers", "1"]
    out = tmp_path / "cv"
    assert main([*args, "--out", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["stratified"] is False
    assert doc["note"].startswith(f"not stratifiable (8 of 8 trials are {UNLABELLED})")
    assert [len(f["val"]) for f in doc["folds"]["linear"]] == [2, 2, 2, 2]
    assert sorted(i for f in doc["folds"]["linear"] for i in f["val"]) == [tr.id for tr in trials]
    assert main([*args, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "plain 4-fold CV" in text and doc["note"] in text


def test_learning_curve_study_on_unlabelled_campaign_says_so(tmp_path, capsys):
    src = make_campaign(400, reps=4)
    trials = [
        Trial(f"log{i:02d}", UNLABELLED, i, tr.channels) for i, tr in enumerate(src.trials, 1)
    ]
    data = write_campaign(Campaign(trials, name="unlabelled"), tmp_path / "camp")
    cfg = tmp_path / "experiments.yaml"
    cfg.write_text(yaml.safe_dump(TINY_CONFIG))
    args = ["study", "learning-curve", "--quick", "--data", str(data), "--config", str(cfg)]
    assert main([*args, "--workers", "1", "--out", str(tmp_path / "lc"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    res = doc["result"]
    assert doc["stratified"] is False and res["stratified"] is False
    assert res["note"] == doc["note"] and "seeded random subsets" in res["note"]
    assert [p["n_train"] for p in res["points"]] == [4, 8, 12]  # the stratified sizes
    for p in res["points"]:
        (score,) = p["scores"]
        assert score["n_train"] == p["n_train"]
