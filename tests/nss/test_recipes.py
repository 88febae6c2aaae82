"""Training recipes: the paper's schedule, the fast recipe's minibatches and phases."""

from __future__ import annotations

import itertools
import math

import pytest
import torch

from helpers.synth import make_campaign, tiny_config, tiny_model
from parknss.data.decimate import decimate, grid_length
from parknss.data.windows import make_windows
from parknss.errors import ConfigError
from parknss.nss import train_state
from parknss.nss.config import with_overrides
from parknss.nss.recipes import (
    HELD_INPUTS,
    CoarseRecipe,
    FastRecipe,
    PaperRecipe,
    cosine,
    make_recipe,
)
from parknss.nss.train import fit, learning_rate

CAMP = make_campaign(130, reps=2)
TRAIN = [tr for tr in CAMP if tr.repetition == 1]
VAL = [tr for tr in CAMP if tr.repetition == 2][:2]
FAST = {"window": 40, "batch": 3, "updates": 7, "val_every": 2, "finish_epochs": 5}


def _fast_cfg(**fast):
    cfg = tiny_config(train={"recipe": "fast", "val_every": 2, "lr_min": 1e-5})
    return with_overrides(cfg, fast={**FAST, **fast})


def _recipe(cfg):
    model, _ = tiny_model(CAMP)
    L = min(tr.n for tr in TRAIN)
    return make_recipe(cfg, model, TRAIN, L), L


def test_paper_recipe_is_the_paper_schedule():
    cfg = tiny_config(train={"epochs": 11, "val_every": 5, "lr_min": 1e-5})
    r, L = _recipe(cfg)
    assert isinstance(r, PaperRecipe) and r.steps == 11
    assert r.full.n == len(make_windows(TRAIN, L).trial_ids) and r.full.steps == L
    steps = [r.step(k) for k in range(1, 12)]
    assert all(s.batch is r.full and s.full for s in steps)  # every step: all windows
    assert [s.lr for s in steps] == [learning_rate(cfg, k) for k in range(1, 12)]
    assert [k for k, s in enumerate(steps, 1) if s.validate] == [1, 6, 11]


def test_fast_minibatches_cover_every_window_once_per_pass():
    r, _ = _recipe(_fast_cfg(updates=40))
    assert isinstance(r, FastRecipe) and r.short.steps == 40
    n, b = r.short.n, r.size
    assert r.per_pass == n // b >= 2
    for p in range(3):  # each pass: disjoint minibatches of `batch` windows
        idx = torch.cat([r.permutation(p)[j * b : (j + 1) * b] for j in range(r.per_pass)])
        assert len(set(idx.tolist())) == r.per_pass * b
    first = r.minibatch(1)
    assert first.n == b and torch.equal(first.u, r.short.u[r.permutation(0)[:b]])
    assert torch.equal(first.targets.vx_s, r.short.targets.vx_s[r.permutation(0)[:b]])
    assert not torch.equal(r.permutation(0), r.permutation(1))
    again, _ = _recipe(_fast_cfg(updates=40))  # a function of (seed, pass) only
    assert torch.equal(again.permutation(2), r.permutation(2))


def test_fast_phases_lr_and_validation():
    cfg = _fast_cfg()
    r, _ = _recipe(cfg)
    steps = [r.step(k) for k in range(1, r.steps + 1)]
    assert r.steps == 12 and [s.phase for s in steps] == ["short"] * 7 + ["full"] * 5
    assert [s.full for s in steps] == [False] * 7 + [True] * 5
    assert all(s.batch is r.full for s in steps[7:])
    assert steps[0].lr == cfg.fast.lr and steps[6].lr == pytest.approx(1e-5)
    assert steps[7].lr == cfg.fast.finish_lr and steps[-1].lr == pytest.approx(1e-5)
    assert all(a.lr >= b.lr for a, b in itertools.pairwise(steps[:7]))
    assert [k for k, s in enumerate(steps, 1) if s.validate] == [1, 3, 5, 7, 8, 10, 12]
    assert cosine(3, 5, 1.0, 0.0) == pytest.approx(0.5) and cosine(1, 1, 2.0, 0.0) == 2.0
    assert cosine(2, 3, 1.0, 0.0) == pytest.approx(0.5 * (1 + math.cos(math.pi / 2)))


def test_fast_fit_learns_and_reports_its_recipe():
    res = fit(TRAIN, VAL, _fast_cfg(updates=30, finish_epochs=6), progress=False)
    rows = res.history.rows
    assert res.recipe == "fast" and res.epochs_run == 36 and len(rows) == 36
    assert [r["phase"] for r in rows] == ["short"] * 30 + ["full"] * 6
    raw = res.history.crit_raw
    assert min(raw) < raw[0]  # the held-out criterion improved
    assert res.training_meta()["recipe"] == "fast" and res.cpu_s > 0.0


def test_fast_fit_without_validation_selects_on_full_batch_steps():
    res = fit(TRAIN, (), _fast_cfg(finish_epochs=4), progress=False)
    assert res.history.crit_epochs == [8, 9, 10, 11]  # phase-2 steps only
    assert res.best_epoch in (8, 9, 10, 11)


def test_fingerprint_of_a_paper_fit_ignores_the_fast_section():
    paper = tiny_config()
    fp = train_state.fingerprint(paper, "d", ["a"], ["b"], 10)
    assert train_state.fingerprint(with_overrides(paper, fast={"batch": 7}), "d", ["a"], ["b"],
                                   10) == fp  # fmt: skip
    fast = _fast_cfg()
    fpf = train_state.fingerprint(fast, "d", ["a"], ["b"], 10)
    assert fpf != fp
    assert train_state.fingerprint(with_overrides(fast, fast={"batch": 7}), "d", ["a"], ["b"],
                                   10) != fpf  # fmt: skip


def test_fast_config_refusals():
    with pytest.raises(ConfigError, match="updates"):
        _fast_cfg(updates=0, finish_epochs=0)
    with pytest.raises(ConfigError):
        _fast_cfg(window=1)


def test_fast_fit_identity_leaves_out_what_the_fast_recipe_does_not_read():
    from parknss.nss.config import fit_identity

    fast = _fast_cfg()
    ident = fit_identity(fast)
    for k, v in (("epochs", 77), ("lr", 1e-4), ("schedule", "constant")):
        assert fit_identity(with_overrides(fast, train={k: v})) == ident
    assert fit_identity(with_overrides(fast, train={"lr_min": 1e-6})) != ident  # read
    paper = tiny_config()
    assert fit_identity(with_overrides(paper, train={"epochs": 77})) != fit_identity(paper)


def test_fit_identity_has_the_fused_kernels_only_when_not_the_reference():
    """The default kernels keep the keys fits had before the option existed; the fast
    ones (other rounding) make another fit."""
    from parknss.nss.config import fit_identity

    cfg = tiny_config()
    ident = fit_identity(cfg)
    assert "fused_kernels" not in ident["model"]
    fast = fit_identity(with_overrides(cfg, model={"fused_kernels": "fast"}))
    assert fast["model"]["fused_kernels"] == "fast"
    assert {k: v for k, v in fast["model"].items() if k != "fused_kernels"} == ident["model"]


COARSE = {"factor": 4, "epochs": 9, "lr": 3e-3, "val_every": 4, "finish_epochs": 5,
          "finish_lr": 1e-3}


def _coarse_cfg(**coarse):
    cfg = tiny_config(train={"recipe": "coarse", "val_every": 2, "lr_min": 1e-5})
    return with_overrides(cfg, coarse={**COARSE, **coarse})


def test_coarse_phases_batches_lr_and_validation():
    """Phase 1: the paper's windows of the decimated trials (same count, L on the grid of
    every m-th sample, stride m, the held inputs averaged); phase 2: the full-rate ones."""
    cfg = _coarse_cfg()
    r, L = _recipe(cfg)
    assert isinstance(r, CoarseRecipe) and r.steps == 14
    c, full = r.coarse, r.full
    assert (c.stride, full.stride) == (4, 1) and c.n == full.n
    assert c.steps == grid_length(L, 4) and full.steps == L
    w = make_windows([decimate(t, 4, HELD_INPUTS) for t in TRAIN], grid_length(L, 4))
    assert torch.equal(c.u, torch.as_tensor(w.inputs)) and c.lengths == list(w.lengths)
    assert torch.equal(c.x0, torch.as_tensor(w.states[:, 0]))
    steps = [r.step(k) for k in range(1, 15)]
    assert [s.phase for s in steps] == ["coarse"] * 9 + ["full"] * 5
    assert all(s.batch is c and not s.full for s in steps[:9])
    assert all(s.batch is full and s.full for s in steps[9:])
    assert steps[0].lr == 3e-3 and steps[8].lr == pytest.approx(1e-5)
    assert steps[9].lr == 1e-3 and steps[-1].lr == pytest.approx(1e-5)
    assert [k for k, s in enumerate(steps, 1) if s.validate] == [1, 5, 9, 10, 12, 14]


def test_coarse_fit_learns_and_reports_its_recipe():
    res = fit(TRAIN, VAL, _coarse_cfg(epochs=40, finish_epochs=4), progress=False)
    rows = res.history.rows
    assert res.recipe == "coarse" and res.epochs_run == 44 and len(rows) == 44
    assert [r["phase"] for r in rows] == ["coarse"] * 40 + ["full"] * 4
    raw = res.history.crit_raw  # held-out, at the full rate, in both phases
    assert res.history.crit_epochs == [*range(1, 41, 4), 41, 43, 44]
    assert min(raw) < 0.9 * raw[0]
    assert res.training_meta()["recipe"] == "coarse"


def test_coarse_config_refusals_and_identity():
    from parknss.nss.config import fit_identity

    with pytest.raises(ConfigError, match="epochs"):
        _coarse_cfg(epochs=0, finish_epochs=0)
    with pytest.raises(ConfigError):
        _coarse_cfg(factor=0)
    coarse = _coarse_cfg()
    ident = fit_identity(coarse)
    assert "coarse" in ident and "fast" not in ident and "epochs" not in ident["train"]
    assert fit_identity(with_overrides(coarse, fast={"batch": 7})) == ident
    assert fit_identity(with_overrides(coarse, coarse={"factor": 8})) != ident
    for other in (tiny_config(), _fast_cfg()):  # the keys stored fits were made with
        assert "coarse" not in fit_identity(other)
        assert fit_identity(with_overrides(other, coarse={"factor": 8})) == fit_identity(other)
