"""The inference-time kinematic limiter (§V-B): velocity by gear, the yaw envelope, and why
the residual channel must not be clamped."""

from __future__ import annotations

import math

import pytest
import torch
from torch import nn

from helpers.synth import make_campaign, tiny_model
from parknss.nss.config import LimiterConfig
from parknss.nss.limiter import KinematicLimiter, make_limiter
from parknss.nss.model import I_STEER

F64 = torch.float64
CAMP = make_campaign(150, reps=1)


def _model(**model):
    m, _ = tiny_model(CAMP, seed=0, model=model)
    return m


def _scaled_state(m, vx, yaw_or_res):
    return torch.stack([m.normalizer.transform("vx", vx, clip=False), yaw_or_res], dim=-1)


def _u_s(m, gear, steer):
    n = len(gear)
    u = torch.stack([gear, torch.zeros(n, dtype=F64), torch.zeros(n, dtype=F64), steer], -1)
    return m.scale_inputs(u)


def test_velocity_clamps_by_gear():
    m = _model()
    lim = KinematicLimiter(m, LimiterConfig(enabled=True))
    vx = torch.tensor([0.4, -0.4, 0.4, -0.4, 0.4, -0.4], dtype=F64)
    gear = torch.tensor([1.0, 1.0, -1.0, -1.0, 0.0, 0.0], dtype=F64)
    want = torch.tensor([0.4, 0.0, 0.0, -0.4, 0.0, 0.0], dtype=F64)
    assert torch.equal(lim.clamp_vx(vx, gear), want)
    x_s = _scaled_state(m, vx, torch.zeros(6, dtype=F64))
    out = lim(x_s, _u_s(m, gear, torch.zeros(6, dtype=F64)))
    torch.testing.assert_close(m.vx_phys(out[:, 0]), want, rtol=0, atol=1e-15)
    assert make_limiter(m, LimiterConfig()) is None  # off by default (paper)


def test_envelope_is_the_geometric_yaw_limit():
    m = _model()
    cfg = LimiterConfig(enabled=True, yaw_margin=0.1, yaw_tol_degs=1.0)
    lim = KinematicLimiter(m, cfg)
    vx = torch.tensor([0.0, 0.5, -1.0], dtype=F64)
    r_min = m.geometry.min_turning_radius()
    want = vx.abs() / r_min * 1.1 + math.radians(1.0)
    torch.testing.assert_close(lim.envelope(vx), want)
    assert 4.0 < r_min < 5.5


def test_reconstructed_mode_keeps_yaw_inside_the_envelope():
    m = _model()
    lim = KinematicLimiter(m, LimiterConfig(enabled=True, mode="reconstructed"))
    g = torch.Generator().manual_seed(0)
    n = 500
    gear = torch.randint(-1, 2, (n,), generator=g).to(F64)
    vx = torch.randn(n, generator=g, dtype=F64) * 0.5
    steer = torch.rand(n, generator=g, dtype=F64) * 800 - 400
    res_s = torch.randn(n, generator=g, dtype=F64) * 2.0  # wild residuals
    u_s = _u_s(m, gear, steer)
    out = lim(_scaled_state(m, vx, res_s), u_s)
    yaw = _yaw(m, out, u_s)
    assert torch.all(yaw.abs() <= lim.envelope(m.vx_phys(out[:, 0])) + 1e-12)
    assert (yaw.abs() > 0.5 * lim.envelope(m.vx_phys(out[:, 0]))).any()  # it did bind
    # an admissible state (right direction, kinematic yaw, no residual) passes unchanged
    ok = _scaled_state(m, torch.full((n,), 0.5, dtype=F64), torch.zeros(n, dtype=F64))
    drive = _u_s(m, torch.ones(n, dtype=F64), steer)
    torch.testing.assert_close(lim(ok, drive), ok, rtol=0, atol=1e-12)


def _yaw(m, x_s, u_s):
    """The reconstructed yaw rate (rad/s) of scaled states."""
    return m.yaw_phys(m.yaw_scaled(m.yaw_ref(x_s[:, 0], u_s[:, I_STEER])) + x_s[:, 1])


def _limiters(m, **kw):
    cfg = LimiterConfig(enabled=True, **kw)
    return (
        KinematicLimiter(m, cfg.model_copy(update={"mode": "reconstructed"})),
        KinematicLimiter(m, cfg.model_copy(update={"mode": "residual"})),
    )


def test_modes_coincide_without_a_kinematic_yaw():
    """Straight wheel (ω_ref = 0): residual and reconstructed yaw are the same quantity."""
    m = _model()
    rec, res = _limiters(m)
    g = torch.Generator().manual_seed(1)
    n = 200
    x_s = _scaled_state(m, torch.randn(n, generator=g, dtype=F64) * 0.4,
                        torch.randn(n, generator=g, dtype=F64))  # fmt: skip
    u_s = _u_s(m, torch.randint(-1, 2, (n,), generator=g).to(F64), torch.zeros(n, dtype=F64))
    torch.testing.assert_close(rec(x_s, u_s), res(x_s, u_s), rtol=0, atol=1e-15)


def test_residual_mode_does_not_bound_the_yaw_rate():
    """Tight turn at speed with slip: ω_ref near the envelope plus a residual of the same
    sign. Clamping the residual channel leaves |ω̂_z| beyond the geometric envelope."""
    m = _model()
    rec, res = _limiters(m, yaw_margin=0.0, yaw_tol_degs=0.5)
    vx = torch.tensor([0.3], dtype=F64)
    u_s = _u_s(m, torch.ones(1, dtype=F64), torch.tensor([380.0], dtype=F64))
    r = 0.04  # rad/s, below the envelope on its own
    x_s = _scaled_state(m, vx, torch.tensor([r / m.normalizer.scale_of("yaw_rate")], dtype=F64))
    env = float(rec.envelope(vx))
    assert r < env < float(_yaw(m, x_s, u_s))
    assert float(_yaw(m, res(x_s, u_s), u_s)) > env  # unchanged: the residual fits
    assert float(_yaw(m, rec(x_s, u_s), u_s)) == pytest.approx(env, rel=1e-12)


def test_residual_mode_pins_the_residual():
    """A rollout whose residual drifts against the kinematic prior while |ω̂_z| stays
    admissible throughout: the reconstructed limiter never acts, the residual limiter
    pins ω_res at the envelope (±tol at standstill), gluing ω̂_z to the kinematic value
    instead of following the dynamics."""
    m = _model()
    sc = m.normalizer.scale_of("yaw_rate")
    drift = -0.04  # rad/s per s: d ω_res / dt, vx constant
    lin = nn.Linear(6, 2).double()
    with torch.no_grad():
        lin.weight.zero_()
        lin.bias.copy_(torch.tensor([0.0, drift / sc], dtype=F64))
    m.state_net = nn.Sequential(lin)
    n = 101
    u = torch.zeros(1, n, 4, dtype=F64)
    u[..., 0] = 1.0  # drive
    u[..., 3] = 380.0
    vx0 = torch.tensor([0.1], dtype=F64)
    ref0 = float(m.yaw_ref(m.normalizer.transform("vx", vx0), m.scale_inputs(u[:, 0])[:, I_STEER]))
    x0 = torch.tensor([[0.1, ref0]], dtype=F64)  # starts on the kinematic manifold
    rec, res = _limiters(m, yaw_margin=0.0, yaw_tol_degs=0.5)
    with torch.no_grad():
        free = m.rollout(x0, u, engine="eager")
        r_rec = m.rollout(x0, u, limiter=rec)
        r_res = m.rollout(x0, u, limiter=res)
    env = float(rec.envelope(vx0))
    assert torch.all(free.yaw_rate.abs() <= env)  # admissible all along
    assert float(free.yaw_res[0, -1]) == pytest.approx(drift * (n - 1) * m.dt, rel=1e-9)
    assert float(free.yaw_res[0, -1]) < -env  # ... with a residual beyond the envelope
    torch.testing.assert_close(r_rec.yaw_rate, free.yaw_rate, rtol=0, atol=1e-14)
    # residual mode: pinned at -env from the moment it reaches it
    assert float(r_res.yaw_res.min()) == pytest.approx(-env, rel=1e-12)
    k = int(torch.nonzero(free.yaw_res[0] < -env)[0])
    assert torch.allclose(r_res.yaw_res[0, k:], torch.full((n - k,), -env, dtype=F64))
    gap = r_res.yaw_rate[0, -1] - free.yaw_rate[0, -1]
    assert float(gap) == pytest.approx(-env - float(free.yaw_res[0, -1]), rel=1e-9)
    assert float(gap) > 0.25 * env  # the yaw no longer follows the (admissible) dynamics
    # at standstill the band shrinks to tol: the residual is pinned to the manifold
    u0 = u.clone()
    u0[..., 0] = 0.0  # neutral: vx is held at 0
    with torch.no_grad():
        r0 = m.rollout(torch.tensor([[0.0, 0.0]], dtype=F64), u0, limiter=res)
        r0_rec = m.rollout(torch.tensor([[0.0, 0.0]], dtype=F64), u0, limiter=rec)
    tol = math.radians(0.5)
    assert torch.allclose(r0.yaw_res[0, 30:], torch.full((n - 30,), -tol, dtype=F64))
    # ... where ω_ref = 0 and the correct limiter does exactly the same
    torch.testing.assert_close(r0_rec.yaw_rate, r0.yaw_rate, rtol=0, atol=1e-15)
