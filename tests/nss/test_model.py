"""NSSModel: step == rollout, the per-sample step function == integrate, the residual yaw
readout, no gear in g, integrator orders."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from helpers.synth import make_campaign, make_trial, tiny_model
from parknss.errors import DataError
from parknss.nss.config import LimiterConfig
from parknss.nss.limiter import make_limiter
from parknss.nss.model import I_GEAR, I_STEER, I_TORQUE
from parknss.signals import ACTUAL_CHANNELS, STATE_CHANNELS
from parknss.vehicle import yaw_rate_ref

CAMP = make_campaign(150, reps=1)


def _moving_case(n=120):
    """x0, u of a window starting mid-motion (vx, steer well inside the clip range)."""
    tr = make_trial(400, seed=5)
    vx, steer = tr["vx"], tr["steer"]
    lo_v, hi_v = np.percentile(np.concatenate([t["vx"] for t in CAMP]), [5, 95])
    ok = (vx > 0.3) & (vx < hi_v) & (vx > lo_v) & (np.abs(steer) > 50) & (np.abs(steer) < 250)
    k0 = int(np.flatnonzero(ok)[0])
    x = torch.as_tensor(tr.array(STATE_CHANNELS)[k0 : k0 + n])
    u = torch.as_tensor(tr.array(ACTUAL_CHANNELS)[k0 : k0 + n])
    return x[None, 0], u[None]


@pytest.mark.parametrize("integrator", ["euler", "midpoint", "rk4"])
@pytest.mark.parametrize("limited", [False, True])
def test_step_reproduces_rollout(integrator, limited):
    m, _ = tiny_model(CAMP, seed=2, model={"integrator": integrator})
    x0, u = _moving_case(60)
    x0, u = x0.repeat(2, 1), u.repeat(2, 1, 1)
    x0[1, 0] = -0.4  # second sequence starts against the gear: the limiter acts
    lim = make_limiter(m, LimiterConfig(enabled=True)) if limited else None
    with torch.no_grad():
        r = m.rollout(x0, u, limiter=lim)
        state = m.initial_state(x0, u[:, 0])
        for k in range(u.shape[1]):
            out, state = m.step(state, u[:, k], limiter=lim)
            for name in ("vx", "yaw_rate", "ax", "ay", "yaw_res"):
                torch.testing.assert_close(
                    getattr(out, name)[:, 0], getattr(r, name)[:, k], rtol=0, atol=1e-12
                )
            if k + 1 < u.shape[1]:
                torch.testing.assert_close(state, r.state_s[:, k + 1], rtol=0, atol=1e-12)
    if limited:  # the limiter really changed this rollout
        with torch.no_grad():
            free = m.rollout(x0, u)
        assert (free.vx - r.vx).abs().max() > 1e-3


@pytest.mark.parametrize("integrator", ["euler", "rk4"])
def test_step_function_is_integrate(integrator):
    """The chain's per-sample integrator (weights taken out once) is the model's own step,
    to the bit, and reconstruct_yaw is the readout's yaw."""
    m, _ = tiny_model(CAMP, seed=4, model={"integrator": integrator})
    m = m.double()
    x0, u = _moving_case(40)
    step = m.step_function()
    with torch.no_grad():
        u_s = m.scale_inputs(u)
        x = m.initial_state_scaled(x0, u_s[:, 0])
        for k in range(u.shape[1]):
            assert torch.equal(step(x, u_s[:, k]), m.integrate(x, u_s[:, k]))
            x = m.integrate(x, u_s[:, k])
        r = m.rollout(x0, u)
        yaw_s = m.reconstruct_yaw(r.state_s, u_s[..., I_STEER])[2]
    assert torch.equal(m.yaw_phys(yaw_s), r.yaw_rate)


def test_residual_readout_and_initial_decomposition():
    m, _ = tiny_model(CAMP, seed=1)
    x0, u = _moving_case()
    with torch.no_grad():
        r = m.rollout(x0, u)
    geom = m.geometry
    # eq. 5: ω̂_z = ω_ref(v̂x, δ_sw) + ω_res, the residual state in yaw-scaled units
    ref = yaw_rate_ref(r.vx, u[..., I_STEER], geom)
    res = r.state_s[..., 1] * m.normalizer.scale_of("yaw_rate")
    torch.testing.assert_close(r.yaw_rate, ref + res, rtol=0, atol=1e-12)
    torch.testing.assert_close(r.yaw_res, res, rtol=0, atol=1e-12)
    assert ref.abs().max() > 0.02  # a case where the prior is not trivially zero
    # ω_res(0) = ω_z(0) - ω_ref(0): the reconstruction starts at the measured state
    torch.testing.assert_close(r.vx[:, 0], x0[:, 0], rtol=0, atol=1e-13)
    torch.testing.assert_close(r.yaw_rate[:, 0], x0[:, 1], rtol=0, atol=1e-13)
    ref0 = yaw_rate_ref(x0[:, 0], u[:, 0, I_STEER], geom)
    torch.testing.assert_close(res[:, 0], x0[:, 1] - ref0, rtol=0, atol=1e-13)


def test_direct_yaw_variant_reads_the_state():
    m, _ = tiny_model(CAMP, seed=1, model={"residual_yaw": False})
    x0, u = _moving_case()
    with torch.no_grad():
        r = m.rollout(x0, u)
    torch.testing.assert_close(r.yaw_s, r.state_s[..., 1], rtol=0, atol=0)
    torch.testing.assert_close(r.yaw_rate[:, 0], x0[:, 1], rtol=0, atol=1e-13)
    torch.testing.assert_close(
        r.state_s[:, 0, 1], m.normalizer.transform("yaw_rate", x0[:, 1]), rtol=0, atol=1e-13
    )
    # the residual variant of the same weights reads something else
    m2, _ = tiny_model(CAMP, seed=1)
    with torch.no_grad():
        r2 = m2.rollout(x0, u)
    assert (r2.yaw_rate - r.yaw_rate).abs().max() > 1e-3


def test_output_network_receives_no_gear():
    m, _ = tiny_model(CAMP, seed=4)
    x0, u = _moving_case(50)
    k = 20
    with torch.no_grad():
        base = m.rollout(x0, u)
        u_gear = u.clone()
        u_gear[:, k, I_GEAR] = -u_gear[:, k, I_GEAR]  # drive -> reverse at sample k only
        g = m.rollout(x0, u_gear)
        u_tq = u.clone()
        u_tq[:, k, I_TORQUE] += 40.0
        t = m.rollout(x0, u_tq)
    for name in ("ax", "ay", "vx", "yaw_rate"):
        torch.testing.assert_close(getattr(g, name)[:, : k + 1], getattr(base, name)[:, : k + 1])
    # the gear of sample k does act on the state from k+1 on
    assert (g.vx[:, k + 1 :] - base.vx[:, k + 1 :]).abs().max() > 0
    # a torque change at sample k reaches ax(k) through g: the check can fail
    assert (t.ax[:, k] - base.ax[:, k]).abs().max() > 1e-6


def _linear_field_model(integrator, a, c1, c2, dt=0.01):
    """State net replaced by the affine field dx1/dt = a·x2 + c1, dx2/dt = c2."""
    m, _ = tiny_model(CAMP, model={"integrator": integrator, "dt": dt})
    lin = nn.Linear(6, 2).double()
    with torch.no_grad():
        lin.weight.zero_()
        lin.weight[0, 1] = a
        lin.bias.copy_(torch.tensor([c1, c2], dtype=torch.float64))
    m.state_net = nn.Sequential(lin)
    return m


@pytest.mark.parametrize("dt", [0.01, 0.02])
def test_integrators_on_an_analytic_case(dt):
    """x2 = x2(0) + c2·t, x1 = x1(0) + c1·t + a·(x2(0)·t + c2·t²/2): quadratic in t.

    Midpoint and RK4 integrate a quadratic exactly; forward Euler misses a·c2·dt·t/2.
    """
    a, c1, c2 = 1.5, -0.2, 0.8
    x0, u = _moving_case(101)
    t = torch.arange(u.shape[1], dtype=torch.float64) * dt
    errs = {}
    for integ in ("euler", "midpoint", "rk4"):
        m = _linear_field_model(integ, a, c1, c2, dt)
        with torch.no_grad():
            X = m.rollout(x0, u, engine="eager").state_s[0]
        x10, x20 = X[0]
        x2 = x20 + c2 * t
        x1 = x10 + c1 * t + a * (x20 * t + 0.5 * c2 * t * t)
        torch.testing.assert_close(X[:, 1], x2, rtol=0, atol=1e-13)
        errs[integ] = X[:, 0] - x1
    assert errs["midpoint"].abs().max() < 1e-13
    assert errs["rk4"].abs().max() < 1e-13
    # Euler: exactly the first-order term, proportional to dt
    torch.testing.assert_close(errs["euler"], -0.5 * a * c2 * dt * t, rtol=0, atol=1e-13)
    assert errs["euler"].abs().max() > 1e-3 * dt / 0.01


@pytest.mark.parametrize("m", [1, 3, 8])
def test_a_strided_rollout_integrates_over_stride_times_dt(m):
    """stride m: each step spans m·dt. On the affine field the states at the kept samples
    are the analytic ones (midpoint, RK4 exact; Euler misses a·c2·(m·dt)·t/2: first order in
    the step), and stride 1 is the plain rollout bit for bit."""
    a, c1, c2, dt = 1.5, -0.2, 0.8, 0.01
    x0, u = _moving_case(97)
    uc = u[:, ::m]
    t = torch.arange(uc.shape[1], dtype=torch.float64) * m * dt
    for integ in ("euler", "midpoint", "rk4"):
        mod = _linear_field_model(integ, a, c1, c2, dt)
        with torch.no_grad():
            X = mod.rollout(x0, uc, engine="eager", stride=m).state_s[0]
        x10, x20 = X[0]
        x1 = x10 + c1 * t + a * (x20 * t + 0.5 * c2 * t * t)
        torch.testing.assert_close(X[:, 1], x20 + c2 * t, rtol=0, atol=1e-13)
        err = X[:, 0] - x1
        want = -0.5 * a * c2 * m * dt * t if integ == "euler" else torch.zeros_like(t)
        torch.testing.assert_close(err, want, rtol=0, atol=1e-13)
    mod, _ = tiny_model(CAMP, seed=3)
    with torch.no_grad():
        plain = mod.rollout(x0, u)
        one = mod.rollout(x0, u, stride=1)
    assert torch.equal(plain.state_s, one.state_s) and torch.equal(plain.ax, one.ax)


@pytest.mark.parametrize("m", [2, 8])
def test_strided_fused_rollout_and_gradients_equal_the_eager_ones(m):
    mod, _ = tiny_model(CAMP, seed=1)
    x0, u = _moving_case(121)
    uc = u[:, ::m]
    outs = {}
    for engine in ("eager", "fused"):
        mod.zero_grad()
        r = mod.rollout(x0, uc, engine=engine, stride=m)
        (r.vx_s.square().sum() + r.ax_s.sum()).backward()
        outs[engine] = (r.state_s.detach(), [p.grad.clone() for p in mod.parameters()])
    torch.testing.assert_close(outs["fused"][0], outs["eager"][0], rtol=1e-10, atol=1e-12)
    for gf, ge in zip(outs["fused"][1], outs["eager"][1], strict=True):
        torch.testing.assert_close(gf, ge, rtol=1e-9, atol=1e-11)
    with pytest.raises(DataError, match="stride"):
        mod.rollout(x0, uc, stride=0)


@pytest.mark.parametrize(
    ("x0_shape", "u_shape"),
    [
        ((1, 3), (1, 10, 4)),
        ((2,), (1, 10, 4)),
        ((1, 2), (1, 10, 3)),
        ((2, 2), (1, 10, 4)),
        ((1, 2), (10, 4)),
        ((1, 2), (1, 0, 4)),
    ],
)
def test_bad_shapes_raise(x0_shape, u_shape):
    m, _ = tiny_model(CAMP)
    with pytest.raises(DataError):
        m.rollout(torch.zeros(x0_shape, dtype=torch.float64), torch.zeros(u_shape))


def test_single_sample_rollout_is_the_initial_state():
    m, _ = tiny_model(CAMP)
    x0, u = _moving_case(1)
    with torch.no_grad():
        r = m.rollout(x0, u)
    assert r.vx.shape == (1, 1)
    torch.testing.assert_close(r.yaw_rate[:, 0], x0[:, 1], rtol=0, atol=1e-13)


def test_fused_engine_refuses_other_integrators_and_limiters():
    m, _ = tiny_model(CAMP, model={"integrator": "rk4"})
    x0, u = _moving_case(10)
    with pytest.raises(DataError):
        m.rollout(x0, u, engine="fused")
    m2, _ = tiny_model(CAMP)
    lim = make_limiter(m2, LimiterConfig(enabled=True))
    assert m2.engine_for(lim) == "eager" and m2.engine_for(None) == "fused"
    with pytest.raises(DataError):
        m2.rollout(x0, u, limiter=lim, engine="fused")
