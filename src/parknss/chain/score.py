"""Closed-loop value of a chain configuration: vx MSE against the logged trials (paper units).

:func:`chain_score` rolls a :class:`~parknss.chain.Chain` (any channels measured) over
whole trials from their logged commands and scores the velocity (and yaw rate) with
:func:`parknss.metrics.errors.open_loop_errors`: full trajectory and moving region
(|vx| >= 0.5 km/h), (km/h)². The all-measured chain is the reference of Phase B and
Table IV.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import torch

from parknss.actuators.envelopes import Envelope
from parknss.actuators.models import ActuatorModel
from parknss.chain.model import Chain, NSSProvenance
from parknss.chain.trials import chain_predictions
from parknss.data.trial import Trial
from parknss.metrics.errors import open_loop_errors
from parknss.nss.model import NSSModel


@dataclass
class ChainScore:
    """vx MSE full / moving, (km/h)²; yaw-rate MSE moving, (°/s)²."""

    vx_full: float
    vx_moving: float
    yaw_moving: float

    @property
    def criterion(self) -> float:
        """Phase B selection criterion: full-trajectory plus moving-region vx MSE."""
        return self.vx_full + self.vx_moving

    def to_json(self) -> dict:
        return asdict(self)


def make_chain(
    nss: NSSModel,
    models: dict[str, ActuatorModel | None],
    env: Envelope,
    provenance: NSSProvenance | None = None,
) -> Chain:
    """A float64 chain (channels absent from ``models`` are measured)."""
    return Chain(nss, dict(models), env, provenance).double()


def chain_score(chain: Chain, trials: Sequence[Trial]) -> ChainScore:
    """Score ``chain`` on whole trials rolled out from their logged commands."""
    with torch.no_grad():
        pred = chain_predictions(chain, trials)
    e = open_loop_errors(pred, trials)
    return ChainScore(e.vx_mse_full_kmh2, e.vx_mse_moving_kmh2, e.yaw_mse_moving_degs2)
