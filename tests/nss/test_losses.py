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
from parknss.nss.config import LossConfig, NSSConfig, fit_identity
from parknss.nss.losses import (
    BlindZoneObservation,
    Targets,
    blind_zone_observation,
    decoupling_loss,
    envelope_points,
    nss_loss,
    observed_speed,
    output_loss,
    pointwise,
    state_loss,
    torque_gain_loss,
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


# --- loss.blind_zone: observe (the blind zone as part of the observation model) -------------

BZ = kmh_to_ms(0.5)  # the wheel-speed blind zone, m/s
WIDTH = kmh_to_ms(0.05)  # the default gate width, m/s


def test_observed_speed_inside_and_outside_the_zone():
    v = torch.tensor([0.0, 0.02, 0.05, 0.1, 0.3, 1.0, -0.05, -0.3], dtype=F64)
    h = observed_speed(v, BZ, WIDTH)
    # inside the zone the sensor reads ~0 (well below the zone's edge: under 0.5 % of v)
    inside = v.abs() < BZ - 3 * WIDTH
    assert torch.all(h[inside].abs() <= 5e-3 * v[inside].abs() + 1e-300)
    assert float(h[0]) == 0.0
    # outside it reads the speed, signed
    outside = v.abs() > BZ + 10 * WIDTH
    torch.testing.assert_close(h[outside], v[outside], rtol=1e-4, atol=0.0)
    # odd and monotone in |v|, exactly half the speed at the edge
    torch.testing.assert_close(observed_speed(-v, BZ, WIDTH), -h, rtol=0.0, atol=0.0)
    grid = torch.linspace(0.0, 0.5, 501, dtype=F64)
    assert torch.all(torch.diff(observed_speed(grid, BZ, WIDTH)) >= 0)
    assert float(observed_speed(torch.tensor(BZ, dtype=F64), BZ, WIDTH)) == pytest.approx(BZ / 2)
    # homogeneous: the same gate in km/h or in scaled units
    torch.testing.assert_close(
        observed_speed(v * 3.6, 0.5, 0.05), h * 3.6, rtol=1e-12, atol=1e-15
    )


def test_observation_model_in_the_scaled_space():
    """The scaled reading of a scaled prediction is the physical reading, scaled."""
    tr = make_trial(300, seed=1, gears=(1, -1))
    m, _ = tiny_model(Campaign([tr]))
    cfg = LossConfig(blind_zone="observe")
    obs = blind_zone_observation(cfg, m.vx_zero_s(), m.st_sc[0])
    v = torch.tensor([[-0.4, -0.1, 0.0, 0.05, 0.13, 0.2, 0.6]], dtype=F64)
    vx_s = m.normalizer.transform("vx", v, clip=False)
    want = observed_speed(v, BZ, WIDTH) / m.normalizer.scale_of("vx")
    torch.testing.assert_close(obs.reading_s(vx_s), want, rtol=1e-10, atol=1e-12)


def test_observe_penalises_a_creeping_prediction_and_its_gradient_pushes_it_into_the_zone():
    # scaled space with s(0) = 0.2 and 1 scaled unit = 1 m/s
    obs = BlindZoneObservation(0.2, BZ, WIDTH)
    # sample 0 moving (measured 1.0 m/s, predicted 1.0), samples 1-3 logged in the blind
    # zone; predicted: creeping at 0.4 m/s (above the zone), 0.05 m/s (inside), 0.0
    pred = torch.tensor([[1.2, 0.6, 0.25, 0.2]], dtype=F64, requires_grad=True)
    meas = T(1.2, 0.2, 0.2, 0.2)  # the logged 0 is s(0)
    valid, moving = T(1.0, 1.0, 1.0, 1.0), T(1.0, 0.0, 0.0, 0.0)
    t = _targets(meas, T(0, 0, 0, 0), T(0, 0, 0, 0), T(0, 0, 0, 0), T(1, 1, 1, 1), valid, moving)
    r = _rollout(pred, T(0, 0, 0, 0), T(0, 0, 0, 0), T(0, 0, 0, 0), T(0, 0, 0, 0))
    loss = state_loss(r, t, "mae", blind=obs)
    # 4 vx samples + 4 yaw samples; the creeping one costs its reading, ~0.4
    want = float(observed_speed(torch.tensor([0.4, 0.05], dtype=F64), BZ, WIDTH).sum()) / 8
    assert float(loss.detach()) == pytest.approx(want, rel=1e-12)
    assert float(loss.detach()) > 0.4 / 8 * 0.99
    (g,) = torch.autograd.grad(loss, pred)
    assert float(g[0, 1]) > 0.1 / 8  # descent lowers the creeping speed
    assert abs(float(g[0, 2])) < 1e-2 * float(g[0, 1])  # inside the zone: < 1 % of the pull
    assert float(g[0, 3]) == 0.0
    # the masked loss does not see the creeping prediction at all
    (gm,) = torch.autograd.grad(state_loss(r, t, "mae"), pred)
    assert float(gm[0, 1]) == 0.0
    # plain gradient descent on the prediction ends inside the zone
    v = torch.tensor([[0.2 + 0.4]], dtype=F64, requires_grad=True)
    one = T(1.0)
    tb = _targets(T(0.2), T(0), T(0), T(0), T(1), one, T(0.0))
    for _ in range(200):
        rb = _rollout(v, T(0), T(0), T(0), T(0))
        (gv,) = torch.autograd.grad(state_loss(rb, tb, "mse", blind=obs), v)
        v = (v - 0.5 * gv).detach().requires_grad_(True)
    assert abs(float(v.detach()) - 0.2) < BZ


def test_default_blind_zone_mask_is_bit_identical():
    """`mask` (the default) computes exactly the masked loss it always did, ignores the gate
    width, and leaves the fit identity (resume fingerprints, store keys) as it was."""
    camp = make_campaign(150, reps=1)
    m, cfg = tiny_model(camp, dtype="float32")
    assert cfg.loss.blind_zone == "mask"
    tr = make_trial(300, seed=3)
    b = make_batch(m, make_windows([tr], 120), cfg.loss.blind_zone_kmh)
    assert 0 < float(b.targets.moving.sum()) < float(b.targets.valid.sum())
    with torch.no_grad():
        r = m.rollout(b.x0, b.u)
    t = b.targets
    ev, ew = (r.vx_s - t.vx_s).abs(), (r.yaw_s - t.yaw_s).abs()
    old = ((ev * t.moving).sum() + (ew * t.valid).sum()) / (
        t.moving.sum() + t.valid.sum()
    ).clamp(min=1.0)
    for lc in (cfg.loss, LossConfig(blind_zone_width_kmh=0.3)):
        terms = nss_loss(r, t, lc, m.vx_zero_s(), m.st_sc[0])
        assert torch.equal(terms.state, old)
        assert torch.equal(terms.total, nss_loss(r, t, cfg.loss, m.vx_zero_s()).total)
    observe = nss_loss(r, t, LossConfig(blind_zone="observe"), m.vx_zero_s(), m.st_sc[0])
    assert float(observe.state) != float(old)
    with pytest.raises(ValueError, match="vx scale"):
        nss_loss(r, t, LossConfig(blind_zone="observe"), m.vx_zero_s())
    doc = fit_identity(NSSConfig())
    assert set(doc["loss"]) == {"kind", "lambda_vx", "lambda_yaw", "blind_zone_kmh"}
    obs_doc = fit_identity(NSSConfig(loss=LossConfig(blind_zone="observe")))
    assert obs_doc["loss"]["blind_zone"] == "observe" and "blind_zone_width_kmh" in obs_doc["loss"]


def _gain_batch():
    camp = make_campaign(150, reps=1)
    m, cfg = tiny_model(camp)
    b = make_batch(m, make_windows([make_trial(300, seed=3)], 120), cfg.loss.blind_zone_kmh)
    return m, cfg, b


def test_torque_gain_prior_hand_computed():
    """A state net whose acceleration is linear in the scaled torque along the gear,
    dvx_s/dt = c·gear·τ_s: the prior is max(0, g_min·Δτ − c·Δτ_s·vx_scale) / ax_scale over
    the moving samples in gear (both gears); 0 for a gain at or above g_min."""
    m, _cfg, b = _gain_batch()
    t = b.targets
    gear = b.u[..., 0]
    mask = t.moving * (gear != 0)
    assert float(mask.sum()) > 0 and float((t.valid * (1 - t.moving)).sum()) > 0
    assert bool((gear > 0).any()) and bool((gear < 0).any())
    step_s = 10.0 / float(m.in_sc[1])
    for c, gmin in ((-2.0, 0.0), (0.5, 0.0), (0.5, 0.02), (0.0, 0.01)):
        def f(x_s, u_s, c=c):
            return torch.stack([c * u_s[..., 0] * u_s[..., 1], torch.zeros_like(u_s[..., 1])], -1)

        m.derivative = f  # the instance attribute shadows the method
        with torch.no_grad():
            r = m.rollout(b.x0, b.u, engine="eager")
        lc = LossConfig(lambda_torque=1.0, torque_gain_min=gmin, torque_step_nm=10.0)
        got = float(torque_gain_loss(m, r, b.u, t, lc))
        dv = c * gear * step_s * float(m.st_sc[0])  # Δ(dvx/dt), m/s², for a 10 N·m step
        pen = torch.relu(gmin * 10.0 - torch.sign(gear) * dv)
        want = float((pen * mask).sum() / mask.sum()) / abs(float(m.out_sc[0]))
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12)
        if c > 0 and gmin == 0.0:
            assert got == 0.0
        if c < 0:
            assert got > 0.0
    assert want > 0.0  # the last case: a gain of 0 against g_min 0.01


def test_torque_gain_prior_is_off_by_default_and_trains_the_gain_up():
    """Off (the default): the loss has no torque term and the fit identity is unchanged.
    On: gradient steps on the prior alone raise the state net's torque gain."""
    from parknss.nss.step import epoch_loss

    m, cfg, b = _gain_batch()
    terms = epoch_loss(m, b, cfg)
    assert terms.torque_gain is None and "torque_gain" not in terms.as_floats()
    assert "lambda_torque" not in fit_identity(cfg)["loss"]
    assert "lambda_torque" not in cfg.loss.model_dump()
    on = cfg.model_copy(update={"loss": LossConfig(lambda_torque=1.0, torque_gain_min=0.05)})
    doc = fit_identity(on)["loss"]
    assert doc["lambda_torque"] == 1.0 and doc["torque_gain_min"] == 0.05
    assert doc["torque_step_nm"] == 10.0
    t_on = epoch_loss(m, b, on)
    assert float(t_on.total) == pytest.approx(float(terms.total) + float(t_on.torque_gain))
    lc = on.loss
    first = float(t_on.torque_gain)
    assert first > 0.0
    opt = torch.optim.Adam(m.state_net.parameters(), lr=3e-2)
    with torch.no_grad():
        r = m.rollout(b.x0, b.u)
    for _ in range(80):
        opt.zero_grad()
        loss = torque_gain_loss(m, r, b.u, b.targets, lc)
        loss.backward()
        opt.step()
    assert float(torque_gain_loss(m, r, b.u, b.targets, lc)) < 0.4 * first


def test_torque_prior_envelope_points_span_the_normalizer_range_and_are_seeded():
    """The envelope draw: half the points per gear, |vx| from the blind-zone edge to the
    normalizer's range end in the gear's direction, torque over the range's non-negative
    part, steering over its range, brake released, residual yaw 0; the same points for
    the same seed, others for another; the logged-only identity keeps its old keys."""
    m, _cfg, _b = _gain_batch()
    lc = LossConfig(lambda_torque=1.0, torque_prior_states="envelope", torque_prior_samples=400)
    x_s, u_s, gear = envelope_points(m, lc, seed=3)
    assert x_s.shape == (400, 2) and u_s.shape == (400, 4) and gear.shape == (400,)
    assert int((gear > 0).sum()) == 200 and int((gear < 0).sum()) == 200
    vx = m.vx_phys(x_s[:, 0])
    edge = 0.5 / 3.6
    hi = float(m.st_off[0] + m.st_sc[0].abs())
    lo = float(m.st_off[0] - m.st_sc[0].abs())
    fwd, rev = gear > 0, gear < 0
    assert float(vx[fwd].min()) >= edge - 1e-6 and float(vx[fwd].max()) <= hi + 1e-6
    assert float(vx[rev].max()) <= -edge + 1e-6 and float(vx[rev].min()) >= lo - 1e-6
    assert float(vx[fwd].max()) > 0.9 * hi and float(vx[rev].min()) < 0.9 * lo
    u = u_s * m.in_sc + m.in_off
    assert torch.equal(u[:, 0], gear)
    assert float(u[:, 1].min()) >= -1e-5
    assert float(u[:, 1].max()) > 0.9 * float(m.in_off[1] + m.in_sc[1].abs())
    assert float(u[:, 2].abs().max()) < 1e-4  # the brake released (scaled 0 bar)
    assert float(u[:, 3].min()) < 0.0 < float(u[:, 3].max())
    assert float(x_s[:, 1].abs().max()) == 0.0  # ω_res = 0 on the kinematic prior
    again = envelope_points(m, lc, seed=3)
    other = envelope_points(m, lc, seed=4)
    assert torch.equal(again[1], u_s) and not torch.equal(other[1], u_s)
    doc = fit_identity(NSSConfig(loss=lc))["loss"]
    assert doc["torque_prior_states"] == "envelope" and doc["torque_prior_samples"] == 400
    logged = fit_identity(NSSConfig(loss=LossConfig(lambda_torque=1.0)))["loss"]
    assert "torque_prior_states" not in logged and "torque_prior_samples" not in logged


def test_torque_prior_envelope_reaches_a_trap_the_logged_samples_miss():
    """A state net whose torque gain inverts only above the logged torques (a speed
    attractor at high torque, the trap of docs/closed_loop.md): the logged prior reads 0,
    the envelope prior sees it and equals its hand computation; 'both' is their mean."""
    m, _cfg, b = _gain_batch()
    tau_logged = float(b.u[..., 1].max())
    tau_hi = float(m.in_off[1] + m.in_sc[1].abs())
    knee = tau_logged + 10.5  # beyond every logged torque plus the 10 N·m step
    assert tau_hi > knee + 5.0
    knee_s = float(m.scale_inputs(torch.tensor([0.0, knee, 0.0, 0.0]))[1])

    def f(x_s, u_s):  # gain +1 below the knee, -1 above it (scaled units), per gear
        tq = u_s[..., 1]
        a = u_s[..., 0] * torch.where(tq < knee_s, tq, 2 * knee_s - tq)
        return torch.stack([a, torch.zeros_like(a)], -1)

    m.derivative = f
    with torch.no_grad():
        r = m.rollout(b.x0, b.u, engine="eager")
    base = {"lambda_torque": 1.0, "torque_prior_samples": 600}
    got = {
        k: float(torque_gain_loss(m, r, b.u, b.targets,
                                  LossConfig(**base, torque_prior_states=k), seed=1))
        for k in ("logged", "envelope", "both")
    }
    assert got["logged"] == 0.0 and got["envelope"] > 0.0
    assert got["both"] == pytest.approx(0.5 * got["envelope"], rel=1e-12)
    x_s, u_s, gear = envelope_points(m, LossConfig(**base, torque_prior_states="envelope"), 1)
    step_s = 10.0 / float(m.in_sc[1])
    u_hi = u_s.clone()
    u_hi[:, 1] += step_s
    dv = (f(x_s, u_hi)[:, 0] - f(x_s, u_s)[:, 0]) * m.st_sc[0]
    want = float(torch.relu(-gear * dv).mean()) / abs(float(m.out_sc[0]))
    assert got["envelope"] == pytest.approx(want, rel=1e-9)


def test_decoupling_prior_penalises_the_yaw_state_as_a_hidden_speed_regulator():
    """A state net whose acceleration reads the second state (a = k·s2, the hidden speed
    regulator of docs/closed_loop.md) is penalised by max(0, |k·Δs2|·vx_scale − tol)
    averaged over the envelope, by hand; one that does not read it (or within the
    tolerance) costs 0; off by default, and an 'on' fit names its settings."""
    m, cfg, b = _gain_batch()
    lc = LossConfig(lambda_decouple=1.0, decouple_tolerance_ms2=0.05, torque_prior_samples=500)
    x_s, _u_s, _gear = envelope_points(m, lc, seed=2)
    shift = 2.0 * torch.rand(len(x_s), generator=torch.Generator().manual_seed(3),
                             dtype=torch.float64) - 1.0
    vsc = abs(float(m.st_sc[0]))
    for k in (0.0, 0.04 / vsc, 1.0):
        def f(x, u, k=k):
            return torch.stack([k * x[..., 1] + u[..., 1], torch.zeros_like(u[..., 1])], -1)

        m.derivative = f
        got = float(decoupling_loss(m, lc, seed=2))
        want = float(torch.relu((k * shift).abs() * vsc - 0.05).mean()) / abs(float(m.out_sc[0]))
        assert got == pytest.approx(want, rel=1e-9, abs=1e-15)
        assert (got == 0.0) == (k * vsc <= 0.05)
    assert got > 0.0
    assert "lambda_decouple" not in fit_identity(cfg)["loss"]
    doc = fit_identity(NSSConfig(loss=lc))["loss"]
    assert doc["lambda_decouple"] == 1.0 and doc["decouple_tolerance_ms2"] == 0.05
    assert doc["torque_prior_samples"] == 500
    from parknss.nss.step import epoch_loss

    del m.derivative
    on = cfg.model_copy(update={"loss": lc})
    t_on = epoch_loss(m, b, on)
    assert t_on.decouple is not None and "decouple" in t_on.as_floats()
    assert epoch_loss(m, b, cfg).decouple is None
