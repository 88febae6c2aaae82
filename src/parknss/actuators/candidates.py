"""The one table from an architecture name to its implementation, and the factory.

:data:`parknss.actuators.spec.ALL_ARCHS` is the vocabulary (what a candidate may be
called, validated when a spec is parsed); :data:`CANDIDATES` maps every one of those names
to the class that implements it. The class carries everything else an architecture needs:
its NumPy real-time twin (``stepper_cls``) and its fitting budget (``fit_family``), so
there is no second lookup table anywhere (tests/actuators/test_models.py checks that the
vocabulary and this table agree).
"""

from __future__ import annotations

import torch

from parknss.actuators.config import ArchConfig
from parknss.actuators.lags import Hammerstein, Lag1, Lag2, Static
from parknss.actuators.models import ActuatorModel, Scaling
from parknss.actuators.monotone import MonoLag
from parknss.actuators.neural import NARX, GRUModel, LSTMModel
from parknss.actuators.spec import CandidateSpec

CANDIDATES: dict[str, type[ActuatorModel]] = {
    "lag1": Lag1,
    "lag2": Lag2,
    "hammerstein": Hammerstein,
    "static": Static,
    "narx": NARX,
    "narx1s": NARX,  # the 1 s window (cfg.narx_long_lags)
    "gru": GRUModel,
    "lstm": LSTMModel,
    "monolag": MonoLag,  # opt-in: the monotone structured brake
}


def build_candidate(spec: CandidateSpec, scaling: Scaling, cfg: ArchConfig) -> ActuatorModel:
    """A fresh (float64) candidate of ``spec``; deterministic under the caller's torch seed."""
    return CANDIDATES[spec.arch](spec, scaling, cfg).to(torch.float64)
