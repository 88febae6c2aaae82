"""The objective of eq. 8 on hand-computed cases: eq. 6 branches, eq. 7, masks, λ."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from helpers.synth import make_campaign, make_trial, tiny_model
from parknss.data.trial import Campaign
from parknss.data.windows import make_windows
from parknss.nss.batch import make_batch
from parknss.nss.config import LossConfig
from parknss.nss.losses import (
    Targets,
    nss_loss,
    output_loss,
    pointwise,
    state_loss,
    velocity_direction_loss,
    yaw_prior_loss,
)
from parknss.nss.model import Rollout
from parknss.signals import kmh_to_ms

F64 = torch.float64


def T(*v):
    return torch.tensor([list(v)], dtype=F64)


def _rollout(vx_s, yaw_s, yaw_ref_s, ax_s, ay_s) -> Rollout:
    z = torch.zeros_like(vx_s)
    return Rollout(
        vx=z, yaw_rate=z, yaw_res=z, ax=z, ay=z, vx_s=vx_s, yaw_s=yaw_s,
        yaw_ref_s=yaw_ref_s, ax_s=ax_s, ay_s=ay_s, state_s=torch.stack([vx_s, yaw_s], -1),
    )  # fmt: skip


def _targets(vx_s, yaw_s, ax_s, ay_s, gear, valid, moving) -> Targets:
    return Targets(vx_s, yaw_s, ax_s, ay_s, gear, valid, moving)


@pytest.mark.parametrize(
    ("gear", "v", "want"),
    [
        # drive penalises only vx < 0
        (1.0, 0.7, 0.0), (1.0, 0.0, 0.0), (1.0, -0.3, 0.3),
        # reverse penalises only vx > 0
        (-1.0, -0.7, 0.0), (-1.0, 0.0, 0.0), (-1.0, 0.4, 0.4),
        # neutral/park penalises |vx|
        (0.0, 0.25, 0.25), (0.0, -0.6, 0.6), (0.0, 0.0, 0.0),
    ],
)  # fmt: skip
def test_velocity_direction_branches(gear, v, want):
    zero = 0.2  # the scaled image of vx = 0 under some asymmetric normalizer
    got = velocity_direction_loss(T(v + zero), T(gear), zero, T(1.0))
    assert float(got) == pytest.approx(want, abs=1e-15)


def test_velocity_direction_mean_over_valid_samples():
    vx = T(-0.5, 0.3, 0.2, -0.1, 9.0)
    gear = T(1.0, -1.0, 0.0, 1.0, 0.0)
    valid = T(1.0, 1.0, 1.0, 1.0, 0.0)  # the padded last sample is ignored
    # penalties 0.5, 0.3, 0.2, 0.1 -> mean 0.275
    assert float(velocity_direction_loss(vx, gear, 0.0, valid)) == pytest.approx(0.275)


def test_velocity_direction_loss_measured_from_physical_zero():
    """With a clipped normalizer s(0) != 0; correct drive/reverse motion costs nothing."""
    tr = make_trial(300, seed=1, gears=(1, -1))
    tr.channels["vx"] = np.where(tr["vx"] < 0, 0.3 * tr["vx"], tr["vx"])  # slow reverse
    m, _ = tiny_model(Campaign([tr]))
    zero = m.vx_zero_s()
    assert float(zero) < -0.3  # the asymmetric case the design note is about
    vx = torch.tensor([[0.1, -0.1, 0.0, 0.3, -0.1]], dtype=F64)
    assert float(m.normalizer.transform("vx", vx)[0, 0]) < 0  # literal max(0, -s) would bite
    gear = T(1.0, -1.0, 0.0, -1.0, 1.0)
    vx_s = m.normalizer.transform("vx", vx)
    assert torch.equal(vx_s, m.normalizer.transform("vx", vx, clip=False))  # inside the clip
    got = velocity_direction_loss(vx_s, gear, zero, torch.ones_like(vx))
    sc = m.normalizer.scale_of("vx")
    # only the two direction violations, 0.3 and 0.1 m/s, in scaled units
    assert float(got) == pytest.approx((0.3 + 0.1) / sc / 5, rel=1e-12)


def test_yaw_prior_loss():
    yaw = T(0.5, -0.2, 0.1, 3.0)
    ref = T(0.4, 0.1, 0.1, 0.0)
    r = _rollout(T(0, 0, 0, 0), yaw, ref, T(0, 0, 0, 0), T(0, 0, 0, 0))
    valid = T(1.0, 1.0, 1.0, 0.0)
    assert float(yaw_prior_loss(r, valid)) == pytest.approx((0.1 + 0.3 + 0.0) / 3)


def test_pointwise_shapes():
    e = torch.linspace(-40.0, 40.0, 801, dtype=F64)
    torch.testing.assert_close(pointwise(e, "mae"), e.abs())
    torch.testing.assert_close(pointwise(e, "mse"), e * e)
    want = np.log(np.cosh(np.float128(e.numpy()))).astype(np.float64)
    torch.testing.assert_close(
        pointwise(e, "logcosh"), torch.as_tensor(want), rtol=1e-12, atol=1e-14
    )
    assert torch.all(torch.isfinite(pointwise(torch.tensor([1e4], dtype=F64), "logcosh")))
    # small errors: log cosh e ~ e²/2, large ones: |e| - ln 2
    assert float(pointwise(torch.tensor(1e-3, dtype=F64), "logcosh")) == pytest.approx(
        5e-7, rel=1e-6
    )
    assert float(pointwise(torch.tensor(50.0, dtype=F64), "logcosh")) == pytest.approx(
        50.0 - math.log(2.0), rel=1e-15
    )
    with pytest.raises(ValueError):
        pointwise(e, "huber")


def test_state_and_output_loss_hand_computed():
    r = _rollout(T(1.0, 2.0, 3.0), T(0.0, 0.5, -1.0), T(0, 0, 0), T(1.0, 0.0, 0.0), T(0.0, -2, 5))
    t = _targets(
        vx_s=T(0.5, 2.5, 0.0), yaw_s=T(0.0, 0.0, 0.0), ax_s=T(0.0, 0.0, 0.0),
        ay_s=T(0.0, 0.0, 0.0), gear=T(1, 1, 1), valid=T(1.0, 1.0, 0.0), moving=T(0.0, 1.0, 0.0),
    )  # fmt: skip
    # vx on moving only: |2-2.5| = 0.5 (1 element); yaw on valid: 0 + 0.5 (2 elements)
    assert float(state_loss(r, t, "mae")) == pytest.approx((0.5 + 0.5) / 3)
    assert float(state_loss(r, t, "mse")) == pytest.approx((0.25 + 0.25) / 3)
    # moving_yaw (validation criterion): yaw on the moving sample only
    assert float(state_loss(r, t, "mae", moving_yaw=True)) == pytest.approx((0.5 + 0.5) / 2)
    # outputs: mean over valid samples and both channels: (1 + 0) + (0 + 2) over 4
    assert float(output_loss(r, t, "mae")) == pytest.approx(3.0 / 4)


def test_blind_zone_samples_do_not_enter_the_state_loss():
    camp = make_campaign(150, reps=1)
    m, cfg = tiny_model(camp)
    tr = make_trial(300, seed=3)
    vx = tr["vx"]
    bz = kmh_to_ms(cfg.loss.blind_zone_kmh)
    slow = np.abs(vx) < bz
    assert slow.any() and (~slow).any()
    b0 = make_batch(m, make_windows([tr], tr.n), cfg.loss.blind_zone_kmh)
    assert torch.equal(b0.targets.moving[0].bool(), torch.as_tensor(~slow))
    with torch.no_grad():
        r = m.rollout(b0.x0, b0.u)
        base = state_loss(r, b0.targets, cfg.loss.kind)

        # perturb the measured vx inside the blind zone (stays inside it): no change
        tr2 = make_trial(300, seed=3)
        tr2.channels["vx"] = np.where(slow, -0.9 * bz * np.sign(vx + 1e-9), vx)
        b1 = make_batch(m, make_windows([tr2], tr2.n), cfg.loss.blind_zone_kmh)
        assert not torch.equal(b1.targets.vx_s, b0.targets.vx_s)
        assert float(state_loss(r, b1.targets, cfg.loss.kind)) == float(base)

        # perturb the predicted vx on the masked samples: no change either
        r.vx_s = torch.where(torch.as_tensor(slow)[None], r.vx_s + 5.0, r.vx_s)
        assert float(state_loss(r, b0.targets, cfg.loss.kind)) == float(base)

        # a moving sample does count
        k = int(np.flatnonzero(~slow)[0])
        r.vx_s[0, k] += 1.0
        assert float(state_loss(r, b0.targets, cfg.loss.kind)) != float(base)


@pytest.mark.parametrize("kind", ["mae", "mse", "logcosh"])
def test_total_applies_lambdas_as_eq8(kind):
    g = torch.Generator().manual_seed(0)

    def rnd():
        return torch.randn(2, 7, generator=g, dtype=F64)

    r = _rollout(rnd(), rnd(), rnd(), rnd(), rnd())
    gear = torch.tensor([[1, 1, -1, -1, 0, 0, 1], [-1, 0, 1, 1, 1, -1, 0]], dtype=F64)
    valid = torch.ones(2, 7, dtype=F64)
    valid[1, 5:] = 0
    moving = valid * (torch.rand(2, 7, generator=g, dtype=F64) > 0.3)
    t = _targets(rnd(), rnd(), rnd(), rnd(), gear, valid, moving)
    cfg = LossConfig(kind=kind, lambda_vx=0.3, lambda_yaw=0.7)
    terms = nss_loss(r, t, cfg, 0.1)
    ls, ly = state_loss(r, t, kind), output_loss(r, t, kind)
    lv = velocity_direction_loss(r.vx_s, gear, 0.1, valid)
    lw = yaw_prior_loss(r, valid)
    assert float(terms.state) == float(ls) and float(terms.output) == float(ly)
    assert float(terms.vx_dir) == float(lv) and float(terms.yaw_prior) == float(lw)
    assert float(terms.total) == pytest.approx(float(ls + ly + 0.3 * lv + 0.7 * lw), rel=1e-15)
    # λ = 0 removes the physics terms; the paper's defaults are 0.1 and 0.5
    t0 = nss_loss(r, t, LossConfig(kind=kind, lambda_vx=0.0, lambda_yaw=0.0), 0.1)
    assert float(t0.total) == pytest.approx(float(ls + ly), rel=1e-15)
    assert LossConfig().lambda_vx == 0.1 and LossConfig().lambda_yaw == 0.5
    assert set(terms.as_floats()) == {"total", "state", "output", "vx_dir", "yaw_prior"}
