"""Whole-trial chain predictions from the logged commands.

:func:`chain_predictions` gives ``{trial_id: {"vx", "yaw_rate", "ax", "ay", "torque",
"brake_pressure", "steer"}}`` (float64 arrays (T,), schema units), the format of
:func:`parknss.nss.predict.predict_trials` plus the actuals, for ``parknss evaluate
--chain``, ``parknss rate --chain``, Phase B and Table IV. A float64 chain with state-aware
submodels is evaluated by the NumPy real-time twin (:func:`realtime_predictions`, equal to
the torch rollout to rounding and faster than its per-sample loop), any other chain by the
batched torch rollout (:func:`rollout_trials`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from parknss.chain.model import ACTUALS, Chain, ChainRollout
from parknss.chain.realtime import RealtimeChain
from parknss.data.trial import Trial
from parknss.errors import DataError
from parknss.signals import COMMAND_CHANNELS

Predictions = dict[str, dict[str, np.ndarray]]


@dataclass
class TrialBatch:
    """Whole trials padded to the longest (last sample repeated): commands (B, T, 4),
    measured actuals (B, T, 3), x0 (B, 2), y0 (B, 3), lengths."""

    cmds: np.ndarray
    actuals: np.ndarray
    x0: np.ndarray
    y0: np.ndarray
    lengths: list[int]
    ids: list[str]


def _pad(x: np.ndarray, L: int) -> np.ndarray:
    return np.concatenate([x, np.repeat(x[-1:], L - len(x), axis=0)]) if len(x) < L else x


def trial_batch(trials: Sequence[Trial]) -> TrialBatch:
    """Batch whole trials for :meth:`Chain.rollout` (logged commands and actuals)."""
    trials = list(trials)
    if not trials:
        raise DataError("no trials to roll out")
    L = max(tr.n for tr in trials)
    cmds = np.stack([_pad(tr.array(COMMAND_CHANNELS), L) for tr in trials])
    acts = np.stack([_pad(tr.array(ACTUALS), L) for tr in trials])
    x0 = np.stack([[tr["vx"][0], tr["yaw_rate"][0]] for tr in trials])
    return TrialBatch(cmds, acts, x0, acts[:, 0].copy(), [tr.n for tr in trials],
                      [tr.id for tr in trials])


def rollout_trials(
    chain: Chain, trials: Sequence[Trial], gear_rule: bool = False
) -> ChainRollout:
    """No-grad chain rollout of whole trials (padded); see :func:`trial_batch`. A replay:
    the logged gear is engaged as given unless ``gear_rule`` (:meth:`Chain.rollout`)."""
    b = trial_batch(trials)
    with torch.no_grad():
        return chain.rollout(b.cmds, torch.as_tensor(b.x0), torch.as_tensor(b.y0),
                             torch.as_tensor(b.actuals), gear_rule=gear_rule)


def realtime_predictions(chain: Chain, trials: Iterable[Trial]) -> Predictions:
    """The same predictions by the NumPy real-time twin, trial by trial (faster than the
    torch loop when state-aware submodels force an interleaved rollout). A replay: the
    logged gear is the engaged one, no gear rule (:mod:`parknss.chain.model`)."""
    rt = RealtimeChain(chain.nss, chain.models(), chain.envelope, gear_rule=False)
    out: Predictions = {}
    names = ("vx", "yaw_rate", "ax", "ay", *ACTUALS)
    for tr in trials:
        cm, ac = tr.array(COMMAND_CHANNELS), tr.array(ACTUALS)
        rt.start([tr["vx"][0], tr["yaw_rate"][0]], ac[0], cm[0])
        rows = np.empty((tr.n, 7))
        for k in range(tr.n):
            act, st = rt.step(*cm[k], measured=ac[k])
            rows[k, :4] = st
            rows[k, 4:] = act
        out[tr.id] = {n: rows[:, i].copy() for i, n in enumerate(names)}
    return out


def chain_predictions(chain: Chain, trials: Iterable[Trial]) -> Predictions:
    """{trial_id: {"vx", "yaw_rate", "ax", "ay", "torque", "brake_pressure", "steer"}}.

    A chain with state-aware submodels in float64 is evaluated by the real-time twin
    (equal to the torch rollout to rounding, tests/chain/test_chain.py), else by the batched
    torch rollout."""
    trials = list(trials)
    if chain.state_aware and chain.nss.dtype == torch.float64:
        return realtime_predictions(chain, trials)
    r = rollout_trials(chain, trials)
    ch = {k: v.detach().to(torch.float64).numpy() for k, v in r.nss.channels().items()}
    for i, name in enumerate(ACTUALS):
        ch[name] = r.actuals[..., i].detach().to(torch.float64).numpy()
    return {tr.id: {k: v[j, : tr.n].copy() for k, v in ch.items()} for j, tr in enumerate(trials)}
