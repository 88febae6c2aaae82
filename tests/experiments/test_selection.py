"""Inner-validation selection (``train.selection: inner``): the checkpoint is chosen on one
training trial per class held out of the fit, never on a scored trial; the paper's
protocol stays the default and keeps its store keys."""

from __future__ import annotations

import math

import pytest

from parknss.errors import ConfigError
from parknss.experiments.ablations import _metric
from parknss.experiments.folds import fold_job, inner_split
from parknss.experiments.store import key_kwargs
from parknss.nss.campaigns import load_campaign

TINY = {"model": {"state_layers": 1, "state_units": 4, "output_layers": 1, "output_units": 4},
        "train": {"epochs": 4, "val_every": 2, "smooth_window": 1}}


def test_inner_split_holds_out_the_last_trial_of_each_class(tiny_study):
    data, _ = tiny_study
    trials = list(load_campaign(str(data)))
    fit_on, select_on = inner_split(trials)
    classes = {t.maneuver for t in trials}
    assert {t.maneuver for t in select_on} == classes and len(select_on) == len(classes)
    assert not {t.id for t in fit_on} & {t.id for t in select_on}
    assert len(fit_on) + len(select_on) == len(trials)
    for t in select_on:  # the last of its class in the given order
        assert [u for u in trials if u.maneuver == t.maneuver][-1] is t
    with pytest.raises(ConfigError, match="two training trials"):
        inner_split(select_on)  # one trial per class: nothing to hold out


def test_an_inner_fold_fit_never_selects_on_a_scored_trial(tiny_study):
    data, _ = tiny_study
    inner = {**TINY, "train": {**TINY["train"], "selection": "inner"}}
    res = fold_job("cv", 0, data=str(data), overrides=inner)
    assert not set(res["selected_on"]) & set(res["val"])
    assert set(res["selected_on"]) | set(res["fitted_on"]) == set(res["train"])
    paper = fold_job("cv", 0, data=str(data), overrides=TINY)
    assert "selected_on" not in paper and paper["val"] == res["val"]


def test_the_default_protocol_keeps_its_store_key():
    base = {"split": "cv", "index": 0, "overrides": TINY}
    spelled = {**base, "overrides": {**TINY, "train": {**TINY["train"], "selection": "scored"}}}
    inner = {**base, "overrides": {**TINY, "train": {**TINY["train"], "selection": "inner"}}}
    assert key_kwargs(base) == key_kwargs(spelled)
    assert "selection" not in key_kwargs(base)["nss"]["train"]
    assert key_kwargs(inner)["nss"]["train"]["selection"] == "inner"


def test_the_lr_criterion_metric_is_the_best_smoothed_criterion():
    res = {"errors": {"vx_mse_moving_kmh2": 0.2}, "history": {"smooth": [0.5, None, 0.3, 0.4]}}
    assert _metric(res, "criterion") == 0.3 and _metric(res, "vx_mse_moving_kmh2") == 0.2
    assert math.isnan(_metric({"errors": {}}, "criterion"))
