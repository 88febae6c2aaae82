"""The weight average of ``fast.ema``: its arithmetic, its swap, and a fit that keeps it."""

from __future__ import annotations

import pytest
import torch

from helpers.synth import make_campaign, tiny_config
from parknss.data.windows import whole_trials
from parknss.nss.averaging import WeightAverage
from parknss.nss.batch import make_batch
from parknss.nss.config import fit_identity, with_overrides
from parknss.nss.train import fit, validation_losses

CAMP = make_campaign(130, reps=2)
TRAIN = [tr for tr in CAMP if tr.repetition == 1]
VAL = [tr for tr in CAMP if tr.repetition == 2][:2]
FAST = {"window": 40, "batch": 3, "updates": 12, "val_every": 2, "finish_epochs": 4}


def _cfg(**fast):
    cfg = tiny_config(train={"recipe": "fast", "val_every": 2, "lr_min": 1e-5,
                             "smooth_window": 1, "dtype": "float64"})
    return with_overrides(cfg, fast={**FAST, **fast})


def test_average_moves_toward_the_weights_and_swaps_back_exactly():
    net = torch.nn.Linear(3, 2).double()
    start = {k: p.detach().clone() for k, p in net.named_parameters()}
    avg = WeightAverage(net, 0.75)
    with torch.no_grad():
        for p in net.parameters():
            p.add_(1.0)
    avg.update(net)
    for k in start:  # 0.75·θ_1 + 0.25·(θ_1 + 1)
        assert torch.allclose(avg.avg[k], start[k] + 0.25, rtol=0, atol=1e-15)
    own = {k: p.detach().clone() for k, p in net.named_parameters()}
    with avg.swapped_in(net):
        assert all(torch.equal(p, avg.avg[k]) for k, p in net.named_parameters())
    assert all(torch.equal(p, own[k]) for k, p in net.named_parameters())
    with pytest.raises(ValueError, match="decay"):
        WeightAverage(net, 1.0)


def test_ema_off_is_the_fit_it_was_and_keeps_its_store_key():
    plain = with_overrides(tiny_config(train={"recipe": "fast"}), fast=FAST)
    assert fit_identity(_cfg(ema=0.0)) == fit_identity(_cfg())  # left out at its default
    assert "ema" not in fit_identity(plain)["fast"]
    assert fit_identity(_cfg(ema=0.9))["fast"]["ema"] == 0.9
    a, b = fit(TRAIN, VAL, _cfg(), progress=False), fit(TRAIN, VAL, _cfg(ema=0.0), progress=False)
    assert all(torch.equal(x, y) for x, y in zip(a.model.state_dict().values(),
                                                 b.model.state_dict().values(), strict=True))


def test_an_ema_fit_validates_and_keeps_the_average():
    cfg = _cfg(ema=0.9)
    res = fit(TRAIN, VAL, cfg, progress=False)
    plain = fit(TRAIN, VAL, _cfg(), progress=False)
    assert res.history.crit_raw != plain.history.crit_raw  # validated another model
    assert res.history.crit_raw[0] == plain.history.crit_raw[0]  # step 1: ā = θ_1
    # the kept model is the average the best criterion was measured on
    vb = make_batch(res.model, whole_trials(VAL), cfg.loss.blind_zone_kmh)
    vs, _ = validation_losses(res.model, vb, cfg)
    best = res.history.crit_raw[res.history.crit_epochs.index(res.best_epoch)]
    assert vs == pytest.approx(best, rel=1e-12)
    with pytest.raises(Exception, match="ema"):
        _cfg(ema=1.0)
