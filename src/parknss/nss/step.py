"""One training step's objective and gradient (paper eq. 8 through BPTT), in one process.

:func:`epoch_loss` rolls out every sequence of a batch and evaluates eq. 8 (plus the
opt-in priors of :mod:`parknss.nss.losses`); :func:`local_step` backpropagates it into the
model's ``.grad`` and returns the terms as floats. The data-parallel step of
:mod:`parknss.nss.parallel` calls the same two on each shard of the batch, with the
shard's :class:`~parknss.nss.losses.Share`.
"""

from __future__ import annotations

import torch

from parknss.errors import ParknssError
from parknss.nss.batch import Batch
from parknss.nss.config import NSSConfig
from parknss.nss.losses import (
    LossTerms,
    Share,
    decoupling_loss,
    nss_loss,
    torque_gain_loss,
)
from parknss.nss.model import NSSModel


def epoch_loss(
    model: NSSModel,
    batch: Batch,
    cfg: NSSConfig,
    engine: str | None = None,
    share: Share | None = None,
) -> LossTerms:
    """Roll out every sequence of the batch and evaluate eq. 8; with ``share``, the batch is
    one shard of a larger one and the terms are its part of that batch's (losses module)."""
    r = model.rollout(batch.x0, batch.u, engine=engine, stride=batch.stride)
    terms = nss_loss(r, batch.targets, cfg.loss, model.vx_zero_s(), model.st_sc[0], share)
    if cfg.loss.lambda_torque > 0.0:  # the torque-gain prior (opt-in; nss/losses.py)
        lt = torque_gain_loss(model, r, batch.u, batch.targets, cfg.loss, cfg.train.seed,
                              share)
        terms.total = terms.total + cfg.loss.lambda_torque * lt
        terms.torque_gain = lt
    if cfg.loss.lambda_decouple > 0.0 and (share is None or share.first):  # opt-in prior
        lc = decoupling_loss(model, cfg.loss, cfg.train.seed)
        terms.total = terms.total + cfg.loss.lambda_decouple * lc
        terms.decouple = lc
    return terms


def local_step(
    model: NSSModel, batch: Batch, cfg: NSSConfig, step: int, share: Share | None = None
) -> dict[str, float]:
    """Forward and backward of ``batch`` (gradients accumulate into ``model``'s ``.grad``);
    the loss terms as floats. A non-finite loss is refused before the backward, naming the
    step (1-based)."""
    terms = epoch_loss(model, batch, cfg, share=share)
    if not torch.isfinite(terms.total):
        raise ParknssError(f"training diverged at step {step} (loss {float(terms.total)})")
    terms.total.backward()
    return terms.as_floats()
