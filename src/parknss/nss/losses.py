"""The training objective of paper eq. 8, all terms in the scaled space.

    L = L_x^masked + L_y + λ_vx · L_vx + λ_ω · L_ω

* L_x^masked: data loss on the states [vx, ω̂_z] (ω̂_z the reconstructed yaw rate); the vx
  component is masked where the measured |vx| < 0.5 km/h (wheel-speed blind zone). The
  mean runs over the unmasked elements of both components together.
  ``loss.blind_zone: observe`` (not the paper's; default ``mask``) puts the blind-zone
  samples back through the sensor's observation model: there the wheel-speed sensor reads
  0, so the predicted *reading* h(v̂x) = v̂x · σ((|v̂x| − b) / w) (b the zone, w
  ``blind_zone_width_kmh``; ≈ 0 inside the zone, ≈ v̂x outside) is compared with 0. A
  prediction inside the zone costs ~nothing, one creeping above it costs its speed. The
  moving samples keep the plain error on v̂x; the mean runs over every valid vx sample.
* L_y: data loss on the outputs [ax, ay] over all valid samples.
* L_vx (eq. 6): the gear-conditioned three-branch loss, drive: max(0, -v), reverse:
  max(0, v), neutral/park: |v|, with v the predicted velocity in scaled units measured
  from the scaled image of vx = 0 (v = s(v̂x) - s(0) = v̂x / scale). Measuring from s(0)
  keeps the physical meaning of the branches under any normalizer whose range is not
  symmetric about zero (there s(0) != 0 and a literal max(0, -s(v̂x)) would penalise
  correct drive velocities).
* L_ω (eq. 7): |ω̂_z - ω_ref(v̂x, δ_sw)| in scaled yaw units; for the residual readout this
  is |ω_res|.
* L_τ (``loss.lambda_torque`` > 0; not the paper's, default off): the torque-gain prior.
  At every moving sample in gear the state net's acceleration is evaluated again with the
  drive torque raised by Δτ (``torque_step_nm``), at the rollout's state (detached):
  Δa = a(x̂, τ + Δτ) − a(x̂, τ) in m/s². Physics says gear·Δa ≈ Δτ·i/(r·m) > 0; the
  penalty is max(0, g_min·Δτ − gear·Δa) / (ax scale) (g_min ``torque_gain_min``,
  (m/s²)/(N·m); 0: monotone only), averaged over those samples. A campaign driven by a
  speed-controlling driver anti-correlates torque and speed, and an NSS fitted to it can
  learn that more torque slows the car (docs/closed_loop.md, "the stop offset").
  ``torque_prior_states`` says where the prior is evaluated: ``logged`` (the above),
  ``envelope`` (a seeded draw of ``torque_prior_samples`` states and inputs over the
  normalizer's range with the brake released, :func:`envelope_points`: the steady torque
  far above what a speed needs, which such a driver never logs and where the trap was
  found) or ``both`` (the mean of the two).
* L_c (``loss.lambda_decouple`` > 0; not the paper's, default off): the yaw-state
  decoupling prior. The second state (ω_res, or ω_z for direct yaw) is the model's only
  other memory, and a fit can use it as a hidden speed regulator: a residual of 0.01
  scaled units (0.1 °/s) that cancels 1 m/s² of drive acceleration holds the speed at the
  campaign's cruise whatever the torque (the torque trap, docs/closed_loop.md). At the
  envelope's points (:func:`envelope_points`) the second state is moved over the yaw
  range and max(0, |Δ(dvx/dt)| − ``decouple_tolerance_ms2``) / (ax scale) is averaged:
  at parking speeds the car's longitudinal acceleration does not depend on its yaw
  state beyond cornering drag (a few hundredths of m/s²).

The data-loss shape is MAE (the paper's), MSE or log-cosh; the physics terms are defined
with max and |.| by eqs. 6-7 and keep that form. "valid" masks padding (windows shorter
than the batch length); every mean is over valid samples only.

A batch split over processes (data-parallel training, :mod:`parknss.nss.parallel`) gives
each shard a :class:`Share`: the whole batch's sample counts, so that every masked mean of a
shard is its masked *sum* over the whole batch's count, and the data-independent terms
(the envelope priors) are computed by the first shard only. The shards' losses then add
up to the whole batch's loss, and their gradients to its gradient (up to rounding).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from parknss.nss.config import LossConfig
from parknss.nss.model import I_STEER, I_TORQUE, NSSModel, Rollout
from parknss.signals import kmh_to_ms

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


def masked_mean(v: Tensor, mask: Tensor, count: float | None = None) -> Tensor:
    """Σ v·mask / Σ mask (0 when the mask is empty); with ``count``, Σ v·mask / count (a
    shard's part of the mean over a whole batch whose mask sums to ``count``)."""
    if count is None:
        return (v * mask).sum() / mask.sum().clamp(min=1.0)
    return (v * mask).sum() / max(count, 1.0)


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


@dataclass(frozen=True)
class Share:
    """One shard's part of a batch split over processes (module doc).

    valid, moving, moving_in_gear: the whole batch's counts of valid samples, moving
    samples, and moving samples with a drive gear engaged (the masks' sums, exact integers);
    first: this shard also carries the data-independent terms (the envelope priors)."""

    valid: float
    moving: float
    moving_in_gear: float
    first: bool

    @classmethod
    def of(cls, t: Targets, first: bool) -> Share:
        """The counts of the whole batch's targets ``t``."""
        in_gear = (t.gear != 0).to(t.moving.dtype)
        return cls(float(t.valid.sum()), float(t.moving.sum()),
                   float((t.moving * in_gear).sum()), first)


@dataclass
class LossTerms:
    """The objective and its parts (0-d tensors)."""

    total: Tensor
    state: Tensor
    output: Tensor
    vx_dir: Tensor
    yaw_prior: Tensor
    torque_gain: Tensor | None = None  # the torque-gain prior, when on
    decouple: Tensor | None = None  # the yaw-state decoupling prior, when on

    def as_floats(self) -> dict[str, float]:
        """The parts as floats (a part that is off, None, is left out)."""
        vals = {k: getattr(self, k) for k in self.__dataclass_fields__}
        return {k: float(v.detach()) for k, v in vals.items() if v is not None}


def observed_speed(v: Tensor, zone, width) -> Tensor:
    """What the wheel-speed sensor reads of a speed v: v · σ((|v| − zone) / width).

    ≈ 0 inside |v| < zone (the blind zone), ≈ v outside, a smooth, differentiable gate of
    width ``width`` around the edge. Homogeneous: any unit, the same for v, zone and width
    (m/s, km/h, or scaled units measured from s(0))."""
    return v * torch.sigmoid((v.abs() - zone) / width)


@dataclass
class BlindZoneObservation:
    """The sensor's observation model in the scaled space (``loss.blind_zone: observe``).

    zero_s: the scaled image of vx = 0; zone_s, width_s: the blind zone and the gate width
    divided by the vx scale (scaled units per m/s inverted), so that the observed reading
    of a scaled prediction, measured from s(0), is ``observed_speed(vx_s - zero_s, ...)``.
    """

    zero_s: Tensor | float
    zone_s: Tensor | float
    width_s: Tensor | float

    def reading_s(self, vx_s: Tensor) -> Tensor:
        """s(h(v̂x)) − s(0): the predicted reading, scaled, measured from the reading 0."""
        return observed_speed(vx_s - self.zero_s, self.zone_s, self.width_s)


def state_loss(
    r: Rollout,
    t: Targets,
    kind: str,
    moving_yaw: bool = False,
    blind: BlindZoneObservation | None = None,
    share: Share | None = None,
) -> Tensor:
    """Masked state loss: vx on the moving region, ω̂_z on all valid (or moving) samples.

    With ``blind`` the blind-zone samples (valid, not moving) enter the vx part too: the
    predicted reading :meth:`BlindZoneObservation.reading_s` against the sensor's 0.
    With ``share`` (training only, ``moving_yaw`` False) the sum is over the whole batch's
    count (module doc)."""
    ev = pointwise(r.vx_s - t.vx_s, kind)
    ew = pointwise(r.yaw_s - t.yaw_s, kind)
    mw = t.moving if moving_yaw else t.valid
    if share is not None and moving_yaw:
        raise ValueError("a shared state loss counts the yaw part over all valid samples")
    if blind is None:
        num = (ev * t.moving).sum() + (ew * mw).sum()
        if share is not None:
            return num / max(share.moving + share.valid, 1.0)
        return num / (t.moving.sum() + mw.sum()).clamp(min=1.0)
    mb = t.valid - t.moving
    eb = pointwise(blind.reading_s(r.vx_s), kind)
    num = (ev * t.moving).sum() + (eb * mb).sum() + (ew * mw).sum()
    if share is not None:  # moving + blind-zone + valid samples = 2 · valid
        return num / max(2.0 * share.valid, 1.0)
    return num / (t.moving.sum() + mb.sum() + mw.sum()).clamp(min=1.0)


def output_loss(r: Rollout, t: Targets, kind: str, share: Share | None = None) -> Tensor:
    """Output loss: mean over valid samples and both channels [ax, ay]."""
    e = pointwise(r.ax_s - t.ax_s, kind) + pointwise(r.ay_s - t.ay_s, kind)
    return 0.5 * masked_mean(e, t.valid, None if share is None else share.valid)


def velocity_direction_loss(
    vx_s: Tensor, gear: Tensor, vx_zero_s, valid: Tensor, count: float | None = None
) -> Tensor:
    """Eq. 6: drive max(0,-v), reverse max(0,v), neutral/park |v|; v = vx_s - s(0).
    ``count``: the whole batch's valid samples (a shard's part, module doc)."""
    v = vx_s - vx_zero_s
    drive = (gear > 0.5).to(v.dtype)
    rev = (gear < -0.5).to(v.dtype)
    idle = (gear.abs() <= 0.5).to(v.dtype)
    pen = drive * torch.relu(-v) + rev * torch.relu(v) + idle * v.abs()
    return masked_mean(pen, valid, count)


def yaw_prior_loss(r: Rollout, valid: Tensor, count: float | None = None) -> Tensor:
    """Eq. 7: mean |ω̂_z - ω_ref| in scaled yaw units (``count``: as eq. 6's)."""
    return masked_mean((r.yaw_s - r.yaw_ref_s).abs(), valid, count)


def blind_zone_observation(cfg: LossConfig, vx_zero_s, vx_scale) -> BlindZoneObservation:
    """The observation model of ``cfg`` for a model whose scaled vx is (vx − off) / vx_scale
    (vx_scale in m/s per scaled unit)."""
    sc = abs(vx_scale)
    return BlindZoneObservation(
        vx_zero_s, kmh_to_ms(cfg.blind_zone_kmh) / sc, kmh_to_ms(cfg.blind_zone_width_kmh) / sc
    )


def nss_loss(
    r: Rollout, t: Targets, cfg: LossConfig, vx_zero_s, vx_scale=None,
    share: Share | None = None,
) -> LossTerms:
    """The full objective (eq. 8) of a rollout against its targets. ``vx_scale`` (m/s per
    scaled vx unit) is needed by ``blind_zone: observe`` only; ``share``: the targets are
    one shard of a batch (module doc)."""
    blind = None
    if cfg.blind_zone == "observe":
        if vx_scale is None:
            raise ValueError("blind_zone 'observe' needs the model's vx scale")
        blind = blind_zone_observation(cfg, vx_zero_s, vx_scale)
    ls = state_loss(r, t, cfg.kind, blind=blind, share=share)
    ly = output_loss(r, t, cfg.kind, share)
    n = None if share is None else share.valid
    lv = velocity_direction_loss(r.vx_s, t.gear, vx_zero_s, t.valid, n)
    lw = yaw_prior_loss(r, t.valid, n)
    total = ls + ly + cfg.lambda_vx * lv + cfg.lambda_yaw * lw
    return LossTerms(total, ls, ly, lv, lw)


def envelope_points(
    model: NSSModel, cfg: LossConfig, seed: int
) -> tuple[Tensor, Tensor, Tensor]:
    """The envelope draw of the torque-gain prior: ``cfg.torque_prior_samples`` (state,
    input) points, half in drive and half in reverse, seeded by ``seed`` (the same points
    at every step of a fit). Physical ranges are the normalizer's: the scaled interval
    [-1, 1] of each channel (``clipped``: the training data's 0.5-99.5 % percentiles,
    ``minmax``: min-max, ``zscore``: mean ± one deviation). Per point: |vx| uniform from
    the blind-zone edge to the range's end in the gear's direction, drive torque uniform
    over the range's non-negative part, steering uniform over its range, brake released,
    and the yaw state on the kinematic prior (ω_res = 0; the direct-yaw state ω_ref).
    Returns (x_s (N, 2), u_s (N, 4), gear (N,)) in the model's dtype; N is 0 where the
    range holds no speed beyond the edge in either direction."""
    gen = torch.Generator().manual_seed(int(seed))
    dt = model.dtype
    half = cfg.torque_prior_samples // 2
    lo_v = float(model.st_off[0] - model.st_sc[0].abs())
    hi_v = float(model.st_off[0] + model.st_sc[0].abs())
    edge = kmh_to_ms(cfg.blind_zone_kmh)
    t_lo = max(0.0, float(model.in_off[I_TORQUE] - model.in_sc[I_TORQUE].abs()))
    t_hi = max(t_lo, float(model.in_off[I_TORQUE] + model.in_sc[I_TORQUE].abs()))
    d_lo = float(model.in_off[I_STEER] - model.in_sc[I_STEER].abs())
    d_hi = float(model.in_off[I_STEER] + model.in_sc[I_STEER].abs())

    def uniform(a: float, b: float) -> Tensor:
        return a + (b - a) * torch.rand(half, generator=gen, dtype=torch.float64)

    xs, us = [], []
    for gear, (a, b) in ((1.0, (edge, hi_v)), (-1.0, (-edge, lo_v))):
        draws = (uniform(0.0, 1.0), uniform(t_lo, t_hi), uniform(d_lo, d_hi))  # seed order
        if gear * (b - a) <= 0.0:  # no speed beyond the edge this way
            continue
        vx = a + (b - a) * draws[0]
        u = torch.stack(
            [torch.full_like(vx, gear), draws[1], torch.zeros_like(vx), draws[2]], dim=-1
        )
        xs.append(vx)
        us.append(u)
    if not xs:
        empty = torch.zeros(0, dtype=dt)
        return torch.zeros(0, 2, dtype=dt), torch.zeros(0, 4, dtype=dt), empty
    u_s = model.scale_inputs(torch.cat(us).to(dt))
    vx_s = model.scale_states(torch.stack([torch.cat(xs), torch.zeros_like(torch.cat(xs))],
                                          dim=-1).to(dt))[:, 0]
    if model.cfg.residual_yaw:
        yaw_s = torch.zeros_like(vx_s)
    else:
        yaw_s = model.yaw_scaled(model.yaw_ref(vx_s, u_s[:, I_STEER]))
    return torch.stack([vx_s, yaw_s], dim=-1), u_s, torch.cat(us)[:, 0].to(dt)


def _gain_penalty(
    model: NSSModel, x_s: Tensor, u_s: Tensor, gear: Tensor, cfg: LossConfig
) -> Tensor:
    """max(0, g_min·Δτ − gear·Δa) per point, m/s² (module doc), at scaled (x_s, u_s)."""
    step_s = cfg.torque_step_nm / model.in_sc[I_TORQUE]
    u_hi = u_s.clone()
    u_hi[..., I_TORQUE] = u_hi[..., I_TORQUE] + step_s
    a0 = model.derivative(x_s, u_s)[..., 0]
    a1 = model.derivative(x_s, u_hi)[..., 0]
    gain = (a1 - a0) * model.st_sc[0]  # Δ(dvx/dt), m/s² for the torque step
    return torch.relu(cfg.torque_gain_min * cfg.torque_step_nm - gear * gain)


def torque_gain_loss(
    model: NSSModel, r: Rollout, u: Tensor, t: Targets, cfg: LossConfig, seed: int = 0,
    share: Share | None = None,
) -> Tensor:
    """The torque-gain prior L_τ (module doc) of a rollout ``r`` of ``model`` on the
    physical inputs ``u`` (B, T, 4), at the points ``cfg.torque_prior_states`` names (the
    envelope's drawn under ``seed``, :func:`envelope_points`); a 0-d tensor in scaled ax
    units (0 where there is no point: no moving sample in gear, an empty envelope).
    ``share``: ``t`` is one shard of a batch; the envelope part is the first shard's."""
    parts = []
    if cfg.torque_prior_states in ("logged", "both"):
        x_s = r.state_s.detach()
        gear = torch.sign(u[..., 0]).to(x_s.dtype)
        pen = _gain_penalty(model, x_s, model.scale_inputs(u.to(x_s.dtype)), gear, cfg)
        count = None if share is None else share.moving_in_gear
        parts.append(masked_mean(pen, t.moving * (gear != 0).to(pen.dtype), count))
    if cfg.torque_prior_states in ("envelope", "both"):
        x_s, u_s, gear = envelope_points(model, cfg, seed)
        if len(gear) and (share is None or share.first):
            parts.append(_gain_penalty(model, x_s, u_s, gear, cfg).mean())
        else:
            parts.append(torch.zeros((), dtype=model.dtype))
    return sum(parts[1:], parts[0]) / len(parts) / model.out_sc[0].abs()


def decoupling_loss(model: NSSModel, cfg: LossConfig, seed: int = 0) -> Tensor:
    """The yaw-state decoupling prior L_c (module doc) at the envelope's points
    (:func:`envelope_points`, drawn under ``seed``): the second state is moved from the
    kinematic prior to a value drawn uniformly over the scaled yaw range [-1, 1] around it
    (seeded by ``seed`` + 1), and the change of dvx/dt beyond ``decouple_tolerance_ms2`` is
    penalised; a 0-d tensor in scaled ax units (0 for an empty envelope)."""
    x_s, u_s, _gear = envelope_points(model, cfg, seed)
    if not len(x_s):
        return torch.zeros((), dtype=model.dtype)
    gen = torch.Generator().manual_seed(int(seed) + 1)
    shift = 2.0 * torch.rand(len(x_s), generator=gen, dtype=torch.float64) - 1.0
    x_r = x_s.clone()
    x_r[:, 1] = x_r[:, 1] + shift.to(x_s.dtype)
    a_ref = model.derivative(x_s, u_s)[:, 0]
    a_r = model.derivative(x_r, u_s)[:, 0]
    change = (a_r - a_ref).abs() * model.st_sc[0].abs()  # m/s²
    pen = torch.relu(change - cfg.decouple_tolerance_ms2)
    return pen.mean() / model.out_sc[0].abs()
