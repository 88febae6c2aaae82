"""The training objective of paper eq. 8, all terms in the scaled space.

    L = L_x^masked + L_y + λ_vx · L_vx + λ_ω · L_ω

* L_x^masked: data loss on the states [vx, ω̂_z] (ω̂_z the reconstructed yaw rate); the vx
  component is masked where the measured |vx| < 0.5 km/h (wheel-speed blind zone). The
  mean runs over the unmasked elements of both components together.
* L_y: data loss on the outputs [ax, ay] over all valid samples.
* L_vx (eq. 6): the gear-conditioned three-branch loss, drive: max(0, -v), reverse:
  max(0, v), neutral/park: |v|, with v the predicted velocity in scaled units measured
  from the scaled image of vx = 0 (v = s(v̂x) - s(0) = v̂x / scale). Measuring from s(0)
  keeps the physical meaning of the branches under any normalizer whose range is not
  symmetric about zero (there s(0) != 0 and a literal max(0, -s(v̂x)) would penalise
  correct drive velocities).
* L_ω (eq. 7): |ω̂_z - ω_ref(v̂x, δ_sw)| in scaled yaw units; for the residual readout this
  is |ω_res|.

The data-loss shape is MAE (the paper's), MSE or log-cosh; the physics terms are defined
with max and |.| by eqs. 6-7 and keep that form. "valid" masks padding (windows shorter
than the batch length); every mean is over valid samples only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from parknss.nss.config import LossConfig
from parknss.nss.model import Rollout

LN2 = math.log(2.0)


def pointwise(e: Tensor, kind: str) -> Tensor:
    """Elementwise data-loss shape of an error e: |e|, e², or log(cosh(e)) (stable)."""
    if kind == "mae":
        return e.abs()
    if kind == "mse":
        return e * e
    if kind == "logcosh":
        a = e.abs()
        return a + torch.nn.functional.softplus(-2.0 * a) - LN2
    raise ValueError(f"unknown loss kind {kind!r}")


def masked_mean(v: Tensor, mask: Tensor) -> Tensor:
    """Σ v·mask / Σ mask (0 when the mask is empty)."""
    return (v * mask).sum() / mask.sum().clamp(min=1.0)


@dataclass
class Targets:
    """Scaled targets and masks of a batch, each (B, T).

    vx_s, yaw_s, ax_s, ay_s: measured channels, scaled (clipped) by the model's normalizer;
    gear: physical gear {-1, 0, 1}; valid: 1 on real samples, 0 on padding; moving: valid
    and measured |vx| >= blind zone.
    """

    vx_s: Tensor
    yaw_s: Tensor
    ax_s: Tensor
    ay_s: Tensor
    gear: Tensor
    valid: Tensor
    moving: Tensor


@dataclass
class LossTerms:
    """The objective and its parts (0-d tensors)."""

    total: Tensor
    state: Tensor
    output: Tensor
    vx_dir: Tensor
    yaw_prior: Tensor

    def as_floats(self) -> dict[str, float]:
        return {k: float(getattr(self, k).detach()) for k in self.__dataclass_fields__}


def state_loss(r: Rollout, t: Targets, kind: str, moving_yaw: bool = False) -> Tensor:
    """Masked state loss: vx on the moving region, ω̂_z on all valid (or moving) samples."""
    ev = pointwise(r.vx_s - t.vx_s, kind)
    ew = pointwise(r.yaw_s - t.yaw_s, kind)
    mw = t.moving if moving_yaw else t.valid
    return ((ev * t.moving).sum() + (ew * mw).sum()) / (t.moving.sum() + mw.sum()).clamp(min=1.0)


def output_loss(r: Rollout, t: Targets, kind: str) -> Tensor:
    """Output loss: mean over valid samples and both channels [ax, ay]."""
    e = pointwise(r.ax_s - t.ax_s, kind) + pointwise(r.ay_s - t.ay_s, kind)
    return 0.5 * masked_mean(e, t.valid)


def velocity_direction_loss(vx_s: Tensor, gear: Tensor, vx_zero_s, valid: Tensor) -> Tensor:
    """Eq. 6: drive max(0,-v), reverse max(0,v), neutral/park |v|; v = vx_s - s(0)."""
    v = vx_s - vx_zero_s
    drive = (gear > 0.5).to(v.dtype)
    rev = (gear < -0.5).to(v.dtype)
    idle = (gear.abs() <= 0.5).to(v.dtype)
    pen = drive * torch.relu(-v) + rev * torch.relu(v) + idle * v.abs()
    return masked_mean(pen, valid)


def yaw_prior_loss(r: Rollout, valid: Tensor) -> Tensor:
    """Eq. 7: mean |ω̂_z - ω_ref| in scaled yaw units."""
    return masked_mean((r.yaw_s - r.yaw_ref_s).abs(), valid)


def nss_loss(r: Rollout, t: Targets, cfg: LossConfig, vx_zero_s) -> LossTerms:
    """The full objective (eq. 8) of a rollout against its targets."""
    ls = state_loss(r, t, cfg.kind)
    ly = output_loss(r, t, cfg.kind)
    lv = velocity_direction_loss(r.vx_s, t.gear, vx_zero_s, t.valid)
    lw = yaw_prior_loss(r, t.valid)
    total = ls + ly + cfg.lambda_vx * lv + cfg.lambda_yaw * lw
    return LossTerms(total, ls, ly, lv, lw)
