"""Tensors for training and open-loop evaluation: inputs, initial states, scaled targets.

A :class:`Batch` is built from :class:`~parknss.data.windows.Windows` (physical units) and
the model that will be trained on it: the targets are scaled by the model's normalizer
(the same clip as its inputs), the masks follow the paper (padding, blind zone).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch
from torch import Tensor

from parknss.data.windows import Windows
from parknss.nss.losses import Targets
from parknss.nss.model import NSSModel
from parknss.signals import kmh_to_ms


@dataclass
class Batch:
    """x0 (N, 2) physical initial state, u (N, T, 4) physical inputs, scaled targets.

    ``stride``: model steps Δt per sample of the batch (a batch of trials decimated by m,
    :mod:`parknss.data.decimate`, is rolled out with an Euler step of m·Δt)."""

    x0: Tensor
    u: Tensor
    targets: Targets
    lengths: list[int]
    stride: int = 1

    @property
    def n(self) -> int:
        return self.x0.shape[0]

    @property
    def steps(self) -> int:
        return self.u.shape[1]

    def select(self, idx: Tensor) -> Batch:
        """The sequences ``idx`` (1-D index tensor) of this batch, in that order."""
        t = self.targets
        targets = Targets(**{f.name: getattr(t, f.name)[idx] for f in fields(Targets)})
        return Batch(self.x0[idx], self.u[idx], targets, [self.lengths[i] for i in idx.tolist()],
                     self.stride)


def make_batch(model: NSSModel, w: Windows, blind_zone_kmh: float, stride: int = 1) -> Batch:
    """Batch of windows for ``model``; |vx| < blind_zone_kmh is masked out of ``moving``;
    ``stride``: the windows' samples are ``stride`` model steps apart (:class:`Batch`)."""
    dt = model.dtype
    st = torch.as_tensor(w.states, dtype=dt)
    out = torch.as_tensor(w.outputs, dtype=dt)
    with torch.no_grad():
        st_s = model.scale_states(st)
        out_s = model.scale_outputs(out)
    valid = torch.as_tensor(w.valid, dtype=dt)
    moving_np = w.valid & (np.abs(w.states[..., 0]) >= kmh_to_ms(blind_zone_kmh))
    targets = Targets(
        vx_s=st_s[..., 0],
        yaw_s=st_s[..., 1],
        ax_s=out_s[..., 0],
        ay_s=out_s[..., 1],
        gear=torch.as_tensor(w.inputs[..., 0], dtype=dt),
        valid=valid,
        moving=torch.as_tensor(moving_np, dtype=dt),
    )
    return Batch(st[:, 0].clone(), torch.as_tensor(w.inputs, dtype=dt), targets, list(w.lengths),
                 stride)
