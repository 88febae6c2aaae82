"""Exponential moving average of the weights (``fast.ema``; off at 0, the default).

After each Adam step k the average moves toward the new weights:
ā ← d·ā + (1 - d)·θ_{k+1}, started at the initial weights θ_1 (so it carries no bias
toward zero). Validation and the best-checkpoint snapshot then see ā instead of θ: the
minibatch phase's noise is averaged out of the model that is kept, while training
continues on θ. Its state (one tensor per parameter) is part of the resumable training
state, so a resumed fit is bit-identical to an uninterrupted one.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch


class WeightAverage:
    """EMA with decay ``d`` in (0, 1) of the named parameters of ``model``."""

    def __init__(self, model: torch.nn.Module, decay: float) -> None:
        if not 0.0 < decay < 1.0:
            raise ValueError(f"EMA decay must be in (0, 1), got {decay}")
        self.decay = decay
        self.avg = {k: p.detach().clone() for k, p in model.named_parameters()}

    @torch.no_grad()
    def update(self, model: torch.nn.Module) -> None:
        """ā ← d·ā + (1 - d)·θ for the model's current weights θ."""
        for k, p in model.named_parameters():
            self.avg[k].lerp_(p.detach(), 1.0 - self.decay)

    @contextmanager
    def swapped_in(self, model: torch.nn.Module) -> Iterator[None]:
        """The model carries ā inside the block and its own weights again after it."""
        own = {k: p.detach().clone() for k, p in model.named_parameters()}
        with torch.no_grad():
            for k, p in model.named_parameters():
                p.copy_(self.avg[k])
        try:
            yield
        finally:
            with torch.no_grad():
                for k, p in model.named_parameters():
                    p.copy_(own[k])

    def load(self, tensors: dict[str, torch.Tensor]) -> None:
        """Restore ā from a saved state (the names of :attr:`avg`)."""
        missing = set(self.avg) - set(tensors)
        if missing:
            raise KeyError(f"weight average lacks {sorted(missing)[:3]}")
        self.avg = {k: tensors[k].to(self.avg[k].dtype).clone() for k in self.avg}
