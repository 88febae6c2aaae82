"""Small kinematic trials for the NSS, data, actuator and experiment tests (fast,
deterministic), tiny NSS configs and models, and campaigns with channels taken away.

``make_trial`` drives a car through a gear pattern: in each gear segment vx rises from and
returns to standstill (sin² profile, signed by the gear), torque follows the acceleration
and speed, the brake the deceleration and the stops; yaw rate is the kinematic-bicycle
value plus a small speed-proportional slip term, ax = dvx/dt, ay = vx·ω. No noise, no
blind-zone artefacts: the point of these trials is speed and exact properties, not realism.
"""

from __future__ import annotations

import numpy as np

from parknss.data.trial import MANEUVER_CLASSES, Campaign, Trial
from parknss.signals import DT, REQUIRED_CHANNELS
from parknss.vehicle import VehicleGeometry, yaw_rate_ref


def make_trial(
    n: int = 300,
    seed: int = 0,
    maneuver: str = "park_in_left",
    repetition: int = 1,
    gears: tuple[int, ...] = (1, -1, 1),
) -> Trial:
    """A trial of n samples with the gear pattern ``gears`` (segments of equal length)."""
    rng = np.random.default_rng(seed)
    geom = VehicleGeometry()
    t = np.arange(n) * DT
    seg = np.minimum((np.arange(n) * len(gears)) // n, len(gears) - 1)
    gear = np.asarray(gears, dtype=float)[seg]
    phase = (np.arange(n) - (seg * n) // len(gears)) / max(n // len(gears), 1)
    move = np.clip((phase - 0.1) / 0.8, 0.0, 1.0)
    vpk = 0.6 + 0.2 * rng.random()
    vx = gear * vpk * np.sin(np.pi * move) ** 2
    acc = np.gradient(np.abs(vx), DT)
    torque = 20.0 + 150.0 * np.clip(acc, 0.0, None) + 30.0 * np.abs(vx)
    brake = 40.0 * np.clip(-acc, 0.0, None) + 8.0 * (np.abs(vx) < 1e-6)
    steer = 300.0 * np.sin(2 * np.pi * (t / t[-1] + rng.random()))
    yaw = yaw_rate_ref(vx, steer, geom) * (1.0 - 0.02 * np.abs(vx))
    ax = np.gradient(vx, DT)
    ay = vx * yaw
    ch = {
        "t": t,
        "gear": gear,
        "torque_cmd": torque,
        "torque": torque,
        "decel_cmd": -0.1 * brake,
        "brake_pressure": brake,
        "steer_cmd": steer,
        "steer": steer,
        "vx": vx,
        "yaw_rate": yaw,
        "ax": ax,
        "ay": ay,
    }
    return Trial(f"{maneuver}_r{repetition}", maneuver, repetition, ch)


def make_campaign(n: int = 200, reps: int = 4, lengths: dict | None = None) -> Campaign:
    """4 classes x reps short trials; ``lengths`` maps trial id -> n to vary lengths."""
    trials = []
    for ci, m in enumerate(MANEUVER_CLASSES):
        for r in range(1, reps + 1):
            tid = f"{m}_r{r}"
            nn = (lengths or {}).get(tid, n + 17 * r + 5 * ci)
            gears = (1, -1, 1) if m.startswith("park_in") else (-1, 1)
            trials.append(make_trial(nn, seed=10 * ci + r, maneuver=m, repetition=r, gears=gears))
    return Campaign(trials, name="synthetic")


TINY = {"state_units": 8, "state_layers": 2, "output_units": 8, "output_layers": 1}


def tiny_config(dtype: str = "float64", **sections):
    """An NSSConfig with tiny networks (sections override as in ``with_overrides``)."""
    from parknss.nss.config import NSSConfig, with_overrides

    model = {**TINY, **sections.pop("model", {})}
    train = {"dtype": dtype, **sections.pop("train", {})}
    return with_overrides(NSSConfig(), model=model, train=train, **sections)


def tiny_model(campaign: Campaign | None = None, seed: int = 0, dtype: str = "float64", **sec):
    """A freshly initialised tiny NSSModel with a normalizer fitted on ``campaign``."""
    from parknss.data.normalize import Normalizer
    from parknss.nss.model import NORMALIZED
    from parknss.nss.train import build_model

    campaign = campaign or make_campaign(150, reps=1)
    sec.setdefault("train", {})["seed"] = seed
    cfg = tiny_config(dtype, **sec)
    norm = Normalizer.fit(
        list(campaign), NORMALIZED, cfg.data.normalizer, cfg.data.clip_percentiles
    )
    return build_model(cfg, norm, VehicleGeometry()), cfg


def keep(trial: Trial, names) -> Trial:
    """The trial with only ``t`` and ``names`` (plus its truth channels)."""
    ch = {k: v for k, v in trial.channels.items() if k == "t" or k in names}
    return Trial(trial.id, trial.maneuver, trial.repetition, ch)


def drop(campaign: Campaign, names, name: str = "partial") -> Campaign:
    """The campaign with ``names`` removed from every trial."""
    rest = [c for c in REQUIRED_CHANNELS if c not in names]
    return Campaign([keep(tr, rest) for tr in campaign], name=name)
