"""The fused Euler rollout and fused output MLP against autograd (float64, tiny sizes)."""

from __future__ import annotations

import functools

import pytest
import torch

from helpers.fused import euler_args, euler_reference, mlp_args, mlp_reference
from helpers.synth import make_campaign, tiny_model
from parknss.data.windows import whole_trials
from parknss.nss.fused import KERNELS, FusedEulerRollout, euler_forward
from parknss.nss.fused_mlp import FusedTanhMLP
from parknss.nss.workspace import WORKSPACE

F64 = torch.float64
TORCH_KERNELS = [k for k in KERNELS if k != "native"]  # float64 too (native: float32 only,
# tests/nss/test_fused_native.py)


@pytest.mark.parametrize("kernels", TORCH_KERNELS)
@pytest.mark.parametrize("hidden_layers", [0, 1, 2])
def test_fused_euler_gradcheck(hidden_layers, kernels):
    dt = 0.1  # large enough that every term of the BPTT matters
    x0, U, W0, b0, Wout, bout, hidden = euler_args(hidden_layers=hidden_layers)
    inputs = (x0, U, W0, b0, Wout, bout, *hidden)
    assert torch.autograd.gradcheck(
        lambda *a: FusedEulerRollout.apply(dt, kernels, *a), inputs, eps=1e-6, atol=1e-8
    )
    # and the values are the recurrence itself (with torch.tanh), with either kernels
    X = FusedEulerRollout.apply(dt, kernels, *inputs)
    torch.testing.assert_close(X, euler_reference(dt, *inputs), rtol=0, atol=1e-13)
    assert torch.equal(X[0], x0)
    Ws, bs = hidden[0::2], hidden[1::2]
    Xn = euler_forward(x0, U, W0, b0, Wout, bout, Ws, bs, dt=dt, kernels=kernels)
    torch.testing.assert_close(Xn, X.detach(), rtol=0, atol=1e-14)


def test_unknown_kernels_are_refused():
    x0, U, W0, b0, Wout, bout, hidden = euler_args()
    with pytest.raises(ValueError, match="fused kernels"):
        euler_forward(x0, U, W0, b0, Wout, bout, hidden[0::2], hidden[1::2], 0.1, kernels="x")


@pytest.mark.parametrize("kernels", TORCH_KERNELS)
@pytest.mark.parametrize(("layers", "n_out"), [(1, 2), (2, 2), (3, 2), (2, 1), (2, 5)])
def test_fused_mlp_gradcheck(layers, n_out, kernels):
    # n_out <= 4: the fast backward's head product is broadcast (fused_mlp._outer), else mm
    x, params = mlp_args(7, 5, 4, layers, n_out)
    mlp = functools.partial(FusedTanhMLP.apply, kernels)
    assert torch.autograd.gradcheck(mlp, (x, *params), eps=1e-6, atol=1e-8)
    ref = mlp_reference(x, *params)
    torch.testing.assert_close(mlp(x, *params), ref, rtol=0, atol=1e-14)


def _case(**model):
    camp = make_campaign(120, reps=1)
    m, _ = tiny_model(camp, seed=3, model=model)
    w = whole_trials(list(camp))
    x0 = torch.as_tensor(w.states[:, 0])
    u = torch.as_tensor(w.inputs)
    return m, x0, u


def _loss(r):
    # touches every readout channel, with nonuniform weights so no gradient cancels
    k = torch.linspace(0.5, 1.5, r.vx.shape[1], dtype=F64)
    return (
        ((r.vx_s * k) ** 2).sum() + (r.yaw_s * k).pow(2).sum() + r.ax_s.sum() + r.ay_s.pow(3).sum()
    )


def _grads(m, x0, u, engine):
    m.zero_grad(set_to_none=True)
    u = u.clone().requires_grad_(True)
    r = m.rollout(x0, u, engine=engine)
    _loss(r).backward()
    return r, {n: p.grad.clone() for n, p in m.named_parameters()}, u.grad.clone()


@pytest.mark.parametrize("residual_yaw", [True, False])
def test_fused_equals_eager_outputs_and_gradients(residual_yaw):
    m, x0, u = _case(residual_yaw=residual_yaw)
    assert m.engine_for(None) == "fused"
    rf, gf, guf = _grads(m, x0, u, "fused")
    re, ge, gue = _grads(m, x0, u, "eager")
    for name in ("vx", "yaw_rate", "ax", "ay", "state_s"):
        torch.testing.assert_close(getattr(rf, name), getattr(re, name), rtol=0, atol=1e-12)
    assert set(gf) == set(ge) == {n for n, _ in m.named_parameters()}
    for n in gf:
        assert gf[n].abs().max() > 0, n
        torch.testing.assert_close(gf[n], ge[n], rtol=1e-10, atol=1e-10, msg=n)
    assert guf.abs().max() > 0
    torch.testing.assert_close(guf, gue, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("kernels", KERNELS)
def test_fused_equals_eager_in_float32(kernels):
    """The training dtype: same numbers up to float32 rounding, with either kernels."""
    camp = make_campaign(120, reps=1)
    m, _ = tiny_model(camp, seed=3, dtype="float32", model={"fused_kernels": kernels})
    w = whole_trials(list(camp))
    x0, u = torch.as_tensor(w.states[:, 0]), torch.as_tensor(w.inputs)
    rf, gf, _ = _grads(m, x0, u, "fused")
    re, ge, _ = _grads(m, x0, u, "eager")
    assert rf.vx.dtype == torch.float32
    torch.testing.assert_close(rf.state_s, re.state_s, rtol=0, atol=1e-5)
    for n in gf:
        torch.testing.assert_close(gf[n], ge[n], rtol=0, atol=1e-5 * float(ge[n].abs().max()))


@pytest.mark.parametrize("dtype", [torch.float32, F64])
def test_reference_tanh_derivative_is_tanh_backward_bit_for_bit(dtype):
    """The reverse-time loop's addcmul + mul is aten's tanh_backward to the last bit (what
    keeps the reference kernels' numerics; also on a length that leaves a SIMD tail)."""
    g = torch.Generator().manual_seed(5)
    for shape in [(29, 128), (3, 37)]:
        grad = torch.randn(shape, generator=g, dtype=dtype)
        h = torch.tanh(2 * torch.randn(shape, generator=g, dtype=dtype))
        one = torch.ones((), dtype=dtype)
        mine = torch.mul(grad, torch.addcmul(one, h, h, value=-1.0))
        assert torch.equal(mine, torch.ops.aten.tanh_backward(grad, h))


def _rel_errors(kernels: str) -> dict[str, float]:
    """Max |float32 - float64| / max |float64| of the states and of every gradient, float32
    with these kernels against the float64 reference (same initial weights)."""
    camp = make_campaign(120, reps=1)
    w = whole_trials(list(camp))
    x0, u = torch.as_tensor(w.states[:, 0]), torch.as_tensor(w.inputs)
    m64, _ = tiny_model(camp, seed=3)
    m32, _ = tiny_model(camp, seed=3, dtype="float32", model={"fused_kernels": kernels})
    r64, g64, _ = _grads(m64, x0, u, "fused")
    r32, g32, _ = _grads(m32, x0, u, "fused")
    assert r32.vx.dtype == torch.float32

    def rel(a, b):
        return float((a.detach().double() - b).abs().max() / b.abs().max())

    return {"state_s": rel(r32.state_s, r64.state_s)} | {n: rel(g32[n], g64[n]) for n in g64}


@pytest.mark.parametrize("kernels", KERNELS)
def test_float32_kernels_agree_with_float64(kernels):
    """Both kernels in float32 against float64: states and gradients to 1e-5 relative."""
    errs = _rel_errors(kernels)
    assert max(errs.values()) < 1e-5, errs


def test_fused_input_gradient_with_frozen_weights():
    """Gradients w.r.t. the inputs flow through the fused rollout of a frozen model."""
    m, x0, u = _case()
    m.requires_grad_(False)
    outs = []
    for engine in ("fused", "eager"):
        uu = u.clone().requires_grad_(True)
        r = m.rollout(x0, uu, engine=engine)
        _loss(r).backward()
        outs.append(uu.grad)
    torch.testing.assert_close(outs[0], outs[1], rtol=1e-10, atol=1e-10)


def test_no_grad_path_equals_grad_path():
    m, x0, u = _case()
    r_grad = m.rollout(x0, u, engine="fused")
    with torch.no_grad():
        r_ng = m.rollout(x0, u, engine="fused")
        r_eager = m.rollout(x0, u, engine="eager")
    assert r_ng.vx.grad_fn is None
    for name in ("vx", "yaw_rate", "ax", "ay"):
        torch.testing.assert_close(
            getattr(r_ng, name), getattr(r_grad, name).detach(), rtol=0, atol=1e-13
        )
        torch.testing.assert_close(getattr(r_ng, name), getattr(r_eager, name), rtol=0, atol=1e-12)


def test_workspace_buffers_are_recycled():
    m, x0, u = _case()
    WORKSPACE.clear()

    def epoch():
        m.zero_grad(set_to_none=True)
        loss = _loss(m.rollout(x0, u, engine="fused"))
        loss.backward()
        del loss
        return {id(t) for t in WORKSPACE.free}

    first = epoch()
    assert first  # the activations and deltas came back
    for _ in range(3):
        assert epoch() == first  # the very same buffers each epoch, none new
    assert len(WORKSPACE.free) <= WORKSPACE.keep


def test_workspace_rows_are_the_unbound_views_made_once():
    ws = type(WORKSPACE)(keep_rows=2)
    a = torch.arange(2 * 3 * 4 * 5, dtype=torch.float32).view(2, 3, 4, 5)
    rows = ws.rows(a)
    assert len(rows) == 6 and all(torch.equal(r, a.view(6, 4, 5)[i]) for i, r in enumerate(rows))
    rows[4].fill_(-1.0)  # views: a write through a row lands in the buffer
    assert bool((a[1, 1] == -1.0).all())
    assert ws.rows(a) is rows  # the same list, not new views
    b, c = torch.zeros(3, 4, 5), torch.zeros(4, 5)
    ws.rows(b), ws.rows(c)  # a third buffer drops the least recently used one
    assert ws.rows(a) is not rows and len(ws._rows) == 2
    with pytest.raises(ValueError, match="contiguous"):
        ws.rows(a.transpose(2, 3))



@pytest.mark.parametrize("kernels", TORCH_KERNELS)
def test_loops_run_in_inference_mode_but_leave_normal_tensors(kernels):
    # the per-step loops run under torch.inference_mode (fused._loop); what they return and
    # the recycled buffers they write must stay normal tensors, so that autograd can save
    # them and the next epoch can write the buffers again, with the very same numbers
    x0, U, W0, b0, Wout, bout, hidden = euler_args(B=3, T=9, H=5, hidden_layers=2)
    inputs = (x0, U, W0, b0, Wout, bout, *hidden)
    WORKSPACE.clear()
    runs = []
    for _ in range(2):
        X = FusedEulerRollout.apply(0.1, kernels, *inputs)
        assert not X.is_inference()
        grads = torch.autograd.grad((X * X).sum(), inputs)
        assert not any(t.is_inference() for t in grads)
        runs.append((X.detach(), grads))
        del X
        assert WORKSPACE.free and not any(t.is_inference() for t in WORKSPACE.free)
    assert torch.equal(runs[0][0], runs[1][0])
    assert all(torch.equal(a, b) for a, b in zip(runs[0][1], runs[1][1], strict=True))
    ref = torch.autograd.grad((euler_reference(0.1, *inputs) ** 2).sum(), inputs)
    for a, b in zip(runs[0][1], ref, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-12)
