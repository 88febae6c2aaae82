"""The command-to-vehicle chain (paper Fig. 2) and everything that needs one (layer L7).

Composition, rollouts and the artefact:

* :mod:`~parknss.chain.model`: :class:`Chain`, the batched differentiable rollout;
* :mod:`~parknss.chain.realtime`: its NumPy float64 real-time twin (the reference
  implementation of one 10 ms step);
* :mod:`~parknss.chain.ccode`, :mod:`~parknss.chain.native`: that step as generated C from
  the weights, compiled and called through ctypes (the FMU's core, ``engine="native"``);
* :mod:`~parknss.chain.trials`: whole-trial predictions from the logged commands;
* :mod:`~parknss.chain.artefact`, :mod:`~parknss.chain.deployed`: the artefact folder and
  :class:`DeployedChain`, a :class:`~parknss.plant.Plant`.

What is built on a chain (below it, :mod:`parknss.actuators` holds the candidates, the
envelopes and the fitting of one candidate):

* :mod:`~parknss.chain.score`: the closed-loop value of a chain configuration;
* :mod:`~parknss.chain.selection`: Phase B and the whole two-phase selection;
* :mod:`~parknss.chain.cotune`: consequence-level co-tuning of one submodel;
* :mod:`~parknss.chain.study`: the selection study's co-tuning and Fig. 6 numbers;
* :mod:`~parknss.chain.ladder`: Table IV and the deployed chain;
* :mod:`~parknss.chain.build`: ``parknss actuators build|ladder`` as one call;
* :mod:`~parknss.chain.stress`: the envelope stress study;
* :mod:`~parknss.chain.rating`: what ``parknss rate`` rates (model, chain or truth).
"""

from parknss.chain.deployed import DeployedChain, load_chain, predict_chain_campaign, save_chain
from parknss.chain.model import ACTUALS, Chain, ChainRollout, NSSProvenance
from parknss.chain.trials import (
    Predictions,
    TrialBatch,
    chain_predictions,
    realtime_predictions,
    rollout_trials,
    trial_batch,
)

__all__ = [
    "ACTUALS",
    "Chain",
    "ChainRollout",
    "DeployedChain",
    "NSSProvenance",
    "Predictions",
    "TrialBatch",
    "chain_predictions",
    "load_chain",
    "predict_chain_campaign",
    "realtime_predictions",
    "rollout_trials",
    "save_chain",
    "trial_batch",
]
