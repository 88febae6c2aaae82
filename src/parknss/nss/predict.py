"""Open-loop predictions of whole trials: the one entry point evaluation and rating use.

``predict_campaign(model_path, campaign)`` loads a model artefact and rolls it out open
loop from every trial's measured initial state [vx(0), ω_z(0)] with the measured actual
inputs [gear, torque, brake_pressure, steer], over the trial's complete length, and
returns ``{trial_id: {"vx", "yaw_rate", "ax", "ay": float64 arrays (T,)}}`` in schema
units. ``parknss rate`` imports exactly this.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch

from parknss.data.trial import Campaign, Trial
from parknss.data.windows import whole_trials
from parknss.nss.checkpoint import load_model
from parknss.nss.config import LimiterConfig
from parknss.nss.limiter import make_limiter
from parknss.nss.model import NSSModel
from parknss.nss.train import check_trials

Predictions = dict[str, dict[str, np.ndarray]]


def predict_trials(
    model: NSSModel, trials: Iterable[Trial], limiter: LimiterConfig | None = None
) -> Predictions:
    """Roll ``model`` out over every trial (batched, padded), cut back to each length."""
    trials = list(trials)
    if not trials:
        return {}
    check_trials(trials, model.dt, "prediction")
    w = whole_trials(trials)
    lim = make_limiter(model, limiter) if limiter is not None else None
    with torch.no_grad():
        x0 = torch.as_tensor(w.states[:, 0], dtype=model.dtype)
        r = model.rollout(x0, torch.as_tensor(w.inputs, dtype=model.dtype), limiter=lim)
    ch = {k: v.detach().to(torch.float64).numpy() for k, v in r.channels().items()}
    return {tr.id: {k: v[i, : tr.n].copy() for k, v in ch.items()} for i, tr in enumerate(trials)}


def predict_campaign(
    model_path: str | Path, campaign: Campaign, limiter: LimiterConfig | None = None
) -> Predictions:
    """Open-loop predictions of every trial of ``campaign`` by the model at ``model_path``."""
    return predict_trials(load_model(model_path).model, campaign, limiter)
