"""Consequence-level co-tuning: it lowers the chained velocity loss on a tiny case and
changes the tuned submodel's weights only."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from helpers.actuators import tiny_config, tiny_nss
from parknss.actuators.envelopes import identify_envelope
from parknss.actuators.fit import fit_candidate
from parknss.actuators.spec import CandidateSpec
from parknss.chain.cotune import cotune
from parknss.chain.score import chain_score, make_chain

torch.set_num_threads(1)


def _snapshot(module) -> dict:
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


@pytest.mark.parametrize("drive", ["drive/lag1/cmd", "drive/lag1/uniform"])
def test_cotune_lowers_the_velocity_loss_and_touches_only_the_target(drive, actuator_campaign):
    camp = actuator_campaign
    trials = list(camp)[:4]
    nss, _ = tiny_nss(camp, seed=3)
    cfg = tiny_config(cotune={"iters": 12, "lr": 0.01, "window": 1000, "burn_in": 0,
                              "batch": 4})
    env = identify_envelope(trials, cfg.envelope)

    def fit(name):
        return fit_candidate(CandidateSpec.parse(name), trials, cfg, env)[0]

    models = {"drive": fit(drive), "brake": fit("brake/narx1s/cmd"),
              "steering": fit("steering/lag1/cmd")}
    chain = make_chain(nss, models, env)
    before_nss = _snapshot(chain.nss)
    before = {c: _snapshot(m) for c, m in models.items()}
    score0 = chain_score(chain, trials)
    rep = cotune(chain, "brake", trials, cfg.cotune)
    score1 = chain_score(chain, trials)
    assert len(rep.history) == 12
    assert score1.vx_moving < score0.vx_moving  # the masked velocity loss went down
    for c in ("drive", "steering"):
        for k, v in _snapshot(models[c]).items():
            assert torch.equal(v, before[c][k]), (c, k)
    for k, v in _snapshot(chain.nss).items():
        assert torch.equal(v, before_nss[k]), k
    changed = [k for k, v in _snapshot(models["brake"]).items()
               if not torch.equal(v, before["brake"][k])]
    assert changed
    assert all(not p.requires_grad for p in chain.parameters())
    assert np.isfinite(rep.history).all()


def test_cotune_keeps_the_best_all_window_weights_even_when_the_run_diverges(actuator_campaign):
    camp = actuator_campaign
    trials = list(camp)[:4]
    nss, _ = tiny_nss(camp, seed=3)
    # an absurd learning rate: the minibatch run is pushed far off its start
    cfg = tiny_config(cotune={"iters": 6, "lr": 5.0, "window": 1000, "burn_in": 0,
                              "batch": 2, "eval_every": 2})
    env = identify_envelope(trials, cfg.envelope)

    def fit(name):
        return fit_candidate(CandidateSpec.parse(name), trials, cfg, env)[0]

    models = {"drive": fit("drive/lag1/cmd"), "brake": fit("brake/narx1s/cmd"),
              "steering": fit("steering/lag1/cmd")}
    chain = make_chain(nss, models, env)
    rep = cotune(chain, "brake", trials, cfg.cotune)
    steps = [s for s, _ in rep.evals]
    assert steps == [0, 2, 4, 6]
    values = dict(rep.evals)
    assert rep.best_step in values
    assert values[rep.best_step] == min(values.values())
    assert values[rep.best_step] <= values[0]  # never worse than the start
    assert max(values.values()) > values[0]  # the run did go astray: keeping the best mattered
