"""The inference-time gear-conditioned kinematic state limiter of paper §V-B (off by default).

Applied to every new state of a rollout (after each integration step, with the gear of
that step):

* velocity by gear: drive vx >= 0, reverse vx <= 0, neutral/park vx = 0;
* yaw envelope: |ω̂_z| <= |vx| · κ_max · (1 + margin) + tol, where κ_max = 1 / R_min is
  the largest path curvature of the vehicle (steering lock, nonlinear rack), so no yaw
  rate beyond what the geometry permits at the current speed survives.

``mode="reconstructed"`` (the correct one) clamps the reconstructed yaw rate
ω̂_z = ω_ref + ω_res and writes back the residual that gives the clamped value.
``mode="residual"`` clamps the internal residual channel with the same envelope as if it
were the yaw rate, the variant the paper warns about: at low speed the envelope shrinks
to ``tol`` and the residual is pinned to zero, i.e. the yaw to the kinematic manifold.
For the direct-yaw model both modes clamp the yaw state.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from parknss.nss.config import LimiterConfig
from parknss.nss.model import I_GEAR, I_STEER, NSSModel, StateLimiter


class KinematicLimiter:
    """Callable (next scaled state (B, 2), scaled input of the step (B, 4)) -> state."""

    def __init__(self, model: NSSModel, cfg: LimiterConfig) -> None:
        self.model = model
        self.cfg = cfg
        self.kappa_max = 1.0 / model.geometry.min_turning_radius()
        self.tol = math.radians(cfg.yaw_tol_degs)

    def envelope(self, vx: Tensor) -> Tensor:
        """Largest admissible |yaw rate| in rad/s at speed vx (m/s)."""
        return vx.abs() * self.kappa_max * (1.0 + self.cfg.yaw_margin) + self.tol

    def clamp_vx(self, vx: Tensor, gear: Tensor) -> Tensor:
        """vx (m/s) limited by the gear: >= 0 in drive, <= 0 in reverse, 0 otherwise."""
        drive = torch.where(gear > 0.5, vx.clamp(min=0.0), vx.clamp(max=0.0))
        return torch.where(gear.abs() <= 0.5, torch.zeros_like(vx), drive)

    def __call__(self, x_s: Tensor, u_s: Tensor) -> Tensor:
        m = self.model
        gear = u_s[:, I_GEAR] * m.in_sc[I_GEAR] + m.in_off[I_GEAR]
        vx = self.clamp_vx(m.vx_phys(x_s[:, 0]), gear)
        vx_s = (vx - m.st_off[0]) / m.st_sc[0]
        env = self.envelope(vx)
        sc = m.st_sc[1]
        if not m.cfg.residual_yaw:
            yaw = m.yaw_phys(x_s[:, 1])
            yaw = torch.maximum(torch.minimum(yaw, env), -env)
            return torch.stack([vx_s, m.yaw_scaled(yaw)], dim=-1)
        if self.cfg.mode == "residual":
            res = x_s[:, 1] * sc
            res = torch.maximum(torch.minimum(res, env), -env)
            return torch.stack([vx_s, res / sc], dim=-1)
        ref = m.yaw_ref(vx_s, u_s[:, I_STEER])
        yaw = ref + x_s[:, 1] * sc
        yaw = torch.maximum(torch.minimum(yaw, env), -env)
        return torch.stack([vx_s, (yaw - ref) / sc], dim=-1)


def make_limiter(model: NSSModel, cfg: LimiterConfig) -> StateLimiter | None:
    """The limiter the config asks for, or None when it is disabled."""
    return KinematicLimiter(model, cfg) if cfg.enabled else None
