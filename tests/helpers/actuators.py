"""Tiny fixtures for the actuator and chain tests: short trials with real actuator lag, a
small random NSS, a tiny actuator config (seconds, not minutes)."""

from __future__ import annotations

import numpy as np
import torch

from helpers.synth import make_trial
from parknss.actuators.config import ActuatorConfig
from parknss.data.normalize import Normalizer
from parknss.data.trial import MANEUVER_CLASSES, Campaign, Trial
from parknss.nss.config import NSSConfig, with_overrides
from parknss.nss.model import NORMALIZED
from parknss.nss.train import build_model
from parknss.signals import DT


def lag(u: np.ndarray, tau: float, y0: float = 0.0) -> np.ndarray:
    """Exact first-order lag y[k+1] = a·y[k] + (1 - a)·u[k], a = exp(-dt/τ)."""
    a = np.exp(-DT / tau)
    y = np.empty_like(u)
    y[0] = y0
    for k in range(len(u) - 1):
        y[k + 1] = a * y[k] + (1 - a) * u[k]
    return y


def lagged_trial(n: int = 300, seed: int = 0, maneuver: str = "park_in_left", rep: int = 1,
                 taus=(0.15, 0.1, 0.08)) -> Trial:
    """A kinematic trial whose actuals are first-order lags of piecewise commands."""
    gears = (1, -1, 1) if maneuver.startswith("park_in") else (-1, 1)
    tr = make_trial(n, seed=seed, maneuver=maneuver, repetition=rep, gears=gears)
    rng = np.random.default_rng(seed)
    steps = np.repeat(rng.uniform(0, 1, n // 50 + 1), 50)[:n]
    ch = dict(tr.channels)
    ch["torque_cmd"] = 60 * steps
    ch["decel_cmd"] = -0.6 * (steps < 0.3) * steps / 0.3
    ch["steer_cmd"] = 400 * (2 * np.repeat(rng.uniform(0, 1, n // 80 + 1), 80)[:n] - 1) * 0.8
    ch["torque"] = lag(ch["torque_cmd"], taus[0], ch["torque_cmd"][0])
    ch["brake_pressure"] = lag(-20 * ch["decel_cmd"], taus[1])
    ch["steer"] = lag(ch["steer_cmd"], taus[2], ch["steer_cmd"][0])
    return Trial(tr.id, tr.maneuver, tr.repetition, ch)


def tiny_campaign(n: int = 240, reps: int = 2) -> Campaign:
    trials = [lagged_trial(n + 13 * r + 7 * i, seed=10 * i + r, maneuver=m, rep=r)
              for i, m in enumerate(MANEUVER_CLASSES) for r in range(1, reps + 1)]
    return Campaign(trials, name="tiny")


def tiny_nss(campaign: Campaign, seed: int = 0, dtype=torch.float32, state_units: int = 16,
             output_units: int = 8):
    """A small random NSS fitted to nothing (the chain's arithmetic is what is tested)."""
    cfg = with_overrides(NSSConfig(), model={"state_units": state_units, "state_layers": 2,
                                             "output_units": output_units,
                                             "output_layers": 1},
                         train={"seed": seed})
    norm = Normalizer.fit(list(campaign), NORMALIZED, cfg.data.normalizer,
                          cfg.data.clip_percentiles)
    model = build_model(cfg, norm, None).to(dtype)
    model.eval()
    model.requires_grad_(False)
    return model, cfg


def tiny_config(**over) -> ActuatorConfig:
    doc = {
        "fit": {"window": 60, "burn_in": 20, "max_windows": 8, "iters_linear": 3,
                "iters_neural": 3},
        "select": {"archs": ["lag1", "narx"], "long_archs": ["narx1s"],
                   "variants": ["cmd", "uniform"], "shortlist": 1, "assembly_top": 1,
                   "nss_state_finetune_iters": 0, "step_hold_s": 1.0},
        "cotune": {"iters": 3, "window": 80, "burn_in": 10, "batch": 4},
        "ladder": {"monolithic_epochs": 1},
        "stress": {"seconds": 1.5},
        "arch": {"narx_long_lags": 20},
    }
    for k, v in over.items():
        doc[k] = {**doc.get(k, {}), **v}
    return ActuatorConfig.model_validate(doc)
