"""Fused forward-Euler rollout of a tanh MLP state network with hand-written BPTT.

The open-loop rollout ``x[k+1] = x[k] + dt·f([x[k], u[k]])`` is thousands of sequential
steps of small matrix products; in a plain eager loop the per-operation overhead of
autograd (graph nodes, saved tensors, Python dispatch) dominates the arithmetic. This
module computes exactly the same recurrence as one :class:`torch.autograd.Function`:

* the input part of the first layer, ``P[k] = W0u·u[k] + b0``, is one large matmul over
  all steps and windows before the loop;
* the forward loop (TorchScript) writes every hidden activation with out= kernels into
  one buffer, no autograd graph and no allocation per step;
* the backward is a reverse-time loop over the stored activations: per step only the
  products δ·W and the fused tanh derivative; the weight gradients are then single large
  matmuls over all steps and windows, Σ_k δ_kᵀ h_k, at full matmul efficiency;
* ``kernels="fast"`` (:data:`KERNELS`, ``model.fused_kernels``) evaluates the same
  functions by cheaper kernels with other rounding; the default keeps the old numbers;
  ``kernels="native"`` runs both loops, the hidden layers' weight gradients and the
  output network in C built for this machine (:mod:`parknss.nss.fused_native`, float32);
* the large buffers (input projections, activations, deltas) are recycled between epochs
  (:mod:`parknss.nss.workspace`), so hundreds of MB of fresh pages are not faulted in
  every epoch, and the loops get their per-step (B, H) views of them as lists made once
  per buffer (``Workspace.rows``), not 12 726 new views an epoch.

Shapes: x0 (B, 2); U (T-1, B, m) the scaled inputs of the steps, time-major; first layer
W0 (H, 2+m), b0 (H,) acting on [x, u]; hidden W_i (H, H), b_i (H,); head Wout (2, H),
bout (2,). The result X is (T, B, 2) with X[0] = x0. Checked against autograd with
``torch.autograd.gradcheck`` in float64 and against the eager loop (tests/nss/test_fused.py).
"""

from __future__ import annotations

import weakref

import torch
from torch import Tensor

from parknss.nss import fused_native
from parknss.nss.config import FUSED_KERNELS
from parknss.nss.workspace import WORKSPACE


def _forward_kernel(
    x0: Tensor,
    ps: list[Tensor],
    W0xT: Tensor,
    WT: list[Tensor],
    b: list[Tensor],
    WoutT: Tensor,
    bout_dt: Tensor,
    dt: float,
    hs: list[Tensor],
    store: bool,
) -> Tensor:
    """X (T, B, 2) of the reference kernels; ps: the T-1 rows P[k] (B, H); hs: the rows of
    the activations Hs (NL, T-1, B, H) if store (layer-major), else of (NL, 1, B, H)."""
    T1 = len(ps)
    NL = len(WT) + 1
    X = torch.empty((T1 + 1, x0.shape[0], x0.shape[1]), dtype=x0.dtype)
    X[0] = x0
    xs = X.unbind(0)
    stride = T1 if store else 1
    for k in range(T1):
        j = k if store else 0
        h = hs[j]
        torch.addmm(ps[k], xs[k], W0xT, out=h)
        h.tanh_()
        for i in range(NL - 1):
            hi = hs[(i + 1) * stride + j]
            torch.addmm(b[i], h, WT[i], out=hi)
            hi.tanh_()
            h = hi
        xn = xs[k + 1]
        torch.addmm(xs[k], h, WoutT, beta=1.0, alpha=dt, out=xn)
        xn.add_(bout_dt)
    return X


def _forward_fast_kernel(
    x0: Tensor,
    ps: list[Tensor],
    W0xT: Tensor,
    WT: list[Tensor],
    b: list[Tensor],
    WoutT: Tensor,
    c: Tensor,
    hs: list[Tensor],
    store: bool,
) -> Tensor:
    """X (T, B, 2) of the fast kernels: the rows of Hs hold s = σ(2a), tanh(a) = 2s - 1
    folded into the next product. ps[k] = 2·(W0u·u[k] + b0), W0xT = 2·W0xᵀ, WT[i] = 4·W_iᵀ,
    b[i] = 2·(b_i - W_i·1), WoutT = 2·dt·Woutᵀ, c = dt·(bout - Wout·1): two kernels a layer."""
    T1 = len(ps)
    NL = len(WT) + 1
    X = torch.empty((T1 + 1, x0.shape[0], x0.shape[1]), dtype=x0.dtype)
    X[0] = x0
    xs = X.unbind(0)
    stride = T1 if store else 1
    for k in range(T1):
        j = k if store else 0
        h = hs[j]
        torch.addmm(ps[k], xs[k], W0xT, out=h)
        h.sigmoid_()
        for i in range(NL - 1):
            hi = hs[(i + 1) * stride + j]
            torch.addmm(b[i], h, WT[i], out=hi)
            hi.sigmoid_()
            h = hi
        xn = xs[k + 1]
        torch.addmm(xs[k], h, WoutT, out=xn)
        xn.add_(c)
    return X


def _backward_kernel(
    gX: Tensor,
    hs: list[Tensor],
    ds: list[Tensor],
    W0x: Tensor,
    W: list[Tensor],
    Wout_dt: Tensor,
    B: int,
    H: int,
) -> Tensor:
    """Reverse-time loop of the reference kernels: layer deltas into the rows ds (like hs,
    layer-major over NL layers x T-1 steps); returns Lam (T, B, 2), dL/dx_k."""
    NL = len(W) + 1
    T1 = gX.shape[0] - 1
    Lam = torch.empty_like(gX)
    Lam[T1] = gX[T1]
    lams = Lam.unbind(0)
    gxs = gX.unbind(0)
    tmp = torch.empty((B, H), dtype=gX.dtype)
    dtanh = torch.empty_like(tmp)
    one = torch.ones((), dtype=gX.dtype)
    for kk in range(T1):
        k = T1 - 1 - kk
        torch.mm(lams[k + 1], Wout_dt, out=tmp)
        for jj in range(NL):
            i = NL - 1 - jj
            d = ds[i * T1 + k]
            # tanh_backward(tmp, h) = tmp·(1 - h²), bit for bit, in two cheaper kernels
            h = hs[i * T1 + k]
            torch.addcmul(one, h, h, value=-1.0, out=dtanh)
            torch.mul(tmp, dtanh, out=d)
            if i > 0:
                torch.mm(d, W[i - 1], out=tmp)
        lk = lams[k]
        torch.add(gxs[k], lams[k + 1], out=lk)
        lk.addmm_(ds[k], W0x)
    return Lam


def _backward_fast_kernel(
    gX: Tensor, ds: list[Tensor], W0x: Tensor, W: list[Tensor], Wout: Tensor, B: int, H: int
) -> Tensor:
    """Reverse-time loop of the fast kernels: the rows ds hold σ'-factors s·(1 - s) on entry
    and the deltas dL/d(2a) on return (multiplied in place); W0x = 2·W0x, W[i] = 4·W_i,
    Wout = 2·dt·Wout. Returns Lam (T, B, 2), dL/dx_k."""
    NL = len(W) + 1
    T1 = gX.shape[0] - 1
    Lam = torch.empty_like(gX)
    Lam[T1] = gX[T1]
    lams = Lam.unbind(0)
    gxs = gX.unbind(0)
    tmp = torch.empty((B, H), dtype=gX.dtype)
    for kk in range(T1):
        k = T1 - 1 - kk
        torch.mm(lams[k + 1], Wout, out=tmp)
        for jj in range(NL):
            i = NL - 1 - jj
            d = ds[i * T1 + k]
            d.mul_(tmp)
            if i > 0:
                torch.mm(d, W[i - 1], out=tmp)
        lk = lams[k]
        torch.add(gxs[k], lams[k + 1], out=lk)
        lk.addmm_(ds[k], W0x)
    return Lam


try:  # TorchScript removes the Python overhead of the per-step loop; same math either way
    _forward = torch.jit.script(_forward_kernel)
    _forward_fast = torch.jit.script(_forward_fast_kernel)
    _backward = torch.jit.script(_backward_kernel)
    _backward_fast = torch.jit.script(_backward_fast_kernel)
except Exception:  # pragma: no cover - scripting unavailable: run the identical Python
    _forward, _forward_fast = _forward_kernel, _forward_fast_kernel
    _backward, _backward_fast = _backward_kernel, _backward_fast_kernel


KERNELS = FUSED_KERNELS
"""The fused kernels' arithmetic: ``reference`` (the rounding the stored fits were made
with) or ``fast``: the same functions with cheaper kernels, rounded differently (float32
results agree to about 1e-6 relative; docs/nss.md): tanh(a) as 2·σ(2a) - 1 (torch's CPU
tanh costs several times its sigmoid) with the affine 2s - 1 folded into the next layer's
weights and bias (the stored activations are s; the reverse loop multiplies by s·(1 - s)
computed for all steps at once), and the products with a skinny factor (the first
layers' weight gradients δᵀ·[x, u] over 5-6 inputs, the output net's input gradient) in
the operand order and layout the BLAS runs 5-10x faster. ``native``: the reference
formulation (tanh activations, plain weights) with the two per-step loops, the
derivatives and the hidden layers' weight gradients in C compiled for this machine
(:mod:`parknss.nss.fused_native`; float32 only, rounded its own way); the output network
likewise."""


def is_fast(kernels: str) -> bool:
    """Whether a kernels name (:data:`KERNELS`) means ``fast`` (ValueError if unknown)."""
    if kernels not in KERNELS:
        raise ValueError(f"unknown fused kernels {kernels!r} (one of {', '.join(KERNELS)})")
    return kernels == "fast"


def _prepare(x0, U, W0, b0, Wout, bout, Ws, bs, dt, P):
    """The reference kernels' forward arguments; fills P (T-1, B, H) = W0u·u + b0."""
    T1, B, m = U.shape
    torch.addmm(b0, U.reshape(T1 * B, m), W0[:, 2:].t(), alpha=1.0, out=P.view(T1 * B, -1))
    return (
        x0.contiguous(),
        WORKSPACE.rows(P),
        W0[:, :2].t().contiguous(),
        [w.t().contiguous() for w in Ws],
        [bb.contiguous() for bb in bs],
        Wout.t().contiguous(),
        (bout * dt).contiguous(),
    )


def _prepare_fast(x0, U, W0, b0, Wout, bout, Ws, bs, dt, P, ps):
    """The fast kernels' forward arguments (the folded weights of _forward_fast_kernel);
    fills P (T-1, B, H) = 2·(W0u·u + b0), whose rows are ps."""
    T1, B, m = U.shape
    torch.addmm(b0 * 2.0, U.reshape(T1 * B, m), W0[:, 2:].t(), alpha=2.0, out=P.view(T1 * B, -1))
    return (
        x0.contiguous(),
        ps,
        (W0[:, :2] * 2.0).t().contiguous(),
        [(w * 4.0).t().contiguous() for w in Ws],
        [((bb - w.sum(1)) * 2.0).contiguous() for w, bb in zip(Ws, bs, strict=True)],
        (Wout * (2.0 * dt)).t().contiguous(),
        ((bout - Wout.sum(1)) * dt).contiguous(),
    )


def _native_forward(x0, U, W0, b0, Wout, bout, Ws, bs, dt: float, P, Hs, store: bool):
    """X (T, B, 2) by the native forward loop (the reference formulation: activations
    h = tanh(a), plain weights); fills P (T-1, B, H) = W0u·u + b0 first."""
    T1, B, m = U.shape
    torch.addmm(b0, U.reshape(T1 * B, m), W0[:, 2:].t(), out=P.view(T1 * B, -1))
    H, dtype = W0.shape[0], x0.dtype
    return fused_native.forward(
        x0.contiguous(),
        P,
        W0[:, :2].t().contiguous(),
        fused_native.stacked([w.t() for w in Ws], (H, H), dtype),
        fused_native.stacked(list(bs), (H,), dtype),
        (Wout * dt).contiguous(),
        (bout * dt).contiguous(),
        Hs,
        store,
    )


def _run_forward(x0, U, W0, b0, Wout, bout, Ws, bs, dt: float, kernels: str, Hs, store: bool):
    """X (T, B, 2); the activations into Hs (NL, T-1, B, H) if store, else Hs (NL, 1, B, H)
    is scratch. The fast and native kernels, storing, compute P into Hs[0] and each step's
    first product in place there (the same row objects: addmm then copies no bias)."""
    fast, native = is_fast(kernels), kernels == "native"
    T1 = U.shape[0]
    if native and store:
        return _native_forward(x0, U, W0, b0, Wout, bout, Ws, bs, dt, Hs[0], Hs, True)
    if native:
        P = WORKSPACE.take((T1, U.shape[1], W0.shape[0]), x0.dtype)
        X = _native_forward(x0, U, W0, b0, Wout, bout, Ws, bs, dt, P, Hs, False)
        WORKSPACE.give(P)
        return X
    hs = WORKSPACE.rows(Hs) if store else list(Hs.view(-1, Hs.shape[2], Hs.shape[3]).unbind(0))
    if fast and store:
        args = _prepare_fast(x0, U, W0, b0, Wout, bout, Ws, bs, dt, Hs[0], hs[:T1])
        return _loop(_forward_fast, *args, hs, store)
    P = WORKSPACE.take((T1, U.shape[1], W0.shape[0]), x0.dtype)
    if fast:
        args = _prepare_fast(x0, U, W0, b0, Wout, bout, Ws, bs, dt, P, WORKSPACE.rows(P))
        X = _loop(_forward_fast, *args, hs, store)
    else:
        args = _prepare(x0, U, W0, b0, Wout, bout, Ws, bs, dt, P)
        X = _loop(_forward, *args, float(dt), hs, store)
    WORKSPACE.give(P)
    return X


def _loop(kernel, *args):
    """Run a per-step loop under ``torch.inference_mode``: its ~30 000 small kernels then
    skip the autograd dispatch layer (the same kernels, bit for bit; ~4 % of the loop).
    Every buffer it writes was made outside, so stays a normal tensor; the tensor it
    returns is copied out of inference mode (X (T, B, 2) or Lam: small)."""
    with torch.inference_mode():
        out = kernel(*args)
    return out.clone()


def euler_forward(
    x0, U, W0, b0, Wout, bout, Ws, bs, dt: float, kernels: str = "reference"
) -> Tensor:
    """The rollout without gradients (inference): X (T, B, 2), no activations stored."""
    is_fast(kernels)  # an unknown name is refused here
    with torch.no_grad():
        scratch = torch.empty((len(Ws) + 1, 1, x0.shape[0], W0.shape[0]), dtype=x0.dtype)
        return _run_forward(x0, U, W0, b0, Wout, bout, Ws, bs, float(dt), kernels, scratch, False)


class FusedEulerRollout(torch.autograd.Function):
    """apply(dt, kernels, x0, U, W0, b0, Wout, bout, W1, b1, ..., W_{NL-1}, b_{NL-1})
    -> X (T, B, 2); ``kernels`` one of :data:`KERNELS`."""

    @staticmethod
    def forward(ctx, dt: float, kernels: str, x0, U, W0, b0, Wout, bout, *hidden):
        fast = is_fast(kernels)
        Ws, bs = list(hidden[0::2]), list(hidden[1::2])
        T1, B, _ = U.shape
        Hs = WORKSPACE.take((len(Ws) + 1, T1, B, W0.shape[0]), x0.dtype)
        X = _run_forward(x0, U, W0, b0, Wout, bout, Ws, bs, float(dt), kernels, Hs, True)
        ctx.dt, ctx.fast, ctx.native = float(dt), fast, kernels == "native"
        ctx.Hs = Hs
        # the activations return to the workspace when this graph node is freed
        weakref.finalize(ctx, WORKSPACE.give, Hs)
        ctx.save_for_backward(X, U, W0, Wout, *Ws)
        return X

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, gX):
        X, U, W0, Wout, *Ws = ctx.saved_tensors
        Hs, dt = ctx.Hs, ctx.dt
        NL, T1, B, nh = Hs.shape
        if ctx.native:  # the derivatives and the upper layers' weight gradients inside C
            D0 = WORKSPACE.take((T1, B, nh), Hs.dtype)
            rev = fused_native.backward(
                gX.contiguous(),
                Hs,
                D0,
                W0[:, :2].t().contiguous(),
                fused_native.stacked(list(Ws), (nh, nh), Hs.dtype),
                (Wout * dt).contiguous(),
            )
            xu = torch.cat([X[:-1].reshape(T1 * B, -1), U.reshape(T1 * B, -1)], dim=1)
            grads = _weight_grads_native(rev, xu, W0, U, dt, ctx.needs_input_grad[3])
            WORKSPACE.give(D0)
            return (None, None, rev.lam[0].clone(), *grads)
        Delta = WORKSPACE.take(tuple(Hs.shape), Hs.dtype)
        ds = WORKSPACE.rows(Delta)
        if ctx.fast:
            torch.addcmul(Hs, Hs, Hs, value=-1.0, out=Delta)  # σ' / 2 = s·(1 - s), all at once
            Lam = _loop(
                _backward_fast,
                gX.contiguous(),
                ds,
                (W0[:, :2] * 2.0).t().contiguous().t(),  # column-major: δ·W0x (N = 2) ~3x faster
                [(w * 4.0).contiguous() for w in Ws],
                (Wout * (2.0 * dt)).contiguous(),
                B,
                nh,
            )
        else:
            Lam = _loop(
                _backward,
                gX.contiguous(),
                WORKSPACE.rows(Hs),
                ds,
                W0[:, :2].contiguous(),
                [w.contiguous() for w in Ws],
                (Wout * dt).contiguous(),
                B,
                nh,
            )
        flat = [Delta[i].view(T1 * B, nh) for i in range(NL)]
        hflat = [Hs[i].view(T1 * B, nh) for i in range(NL)]
        lam_next = Lam[1:].reshape(T1 * B, -1)
        xu = torch.cat([X[:-1].reshape(T1 * B, -1), U.reshape(T1 * B, -1)], dim=1)
        needs_u = ctx.needs_input_grad[3]
        if ctx.fast:
            # the head's gradient λᵀ·h from h = 2s - 1 itself: 2·λᵀ·s - Σλ cancels badly
            h_last = WORKSPACE.take((T1, B, nh), Hs.dtype)
            torch.add(-1.0, Hs[NL - 1], alpha=2.0, out=h_last)
            hflat[NL - 1] = h_last.view(T1 * B, nh)
            grads = _weight_grads_fast(flat, hflat, lam_next, xu, W0, U, dt, needs_u)
            WORKSPACE.give(h_last)
        else:
            grads = _weight_grads(flat, hflat, lam_next, xu, W0, U, dt, needs_u)
        WORKSPACE.give(Delta)
        return (None, None, Lam[0].clone(), *grads)


def _weight_grads(flat, hflat, lam_next, xu, W0, U, dt, needs_u):
    """(g_U, g_W0, g_b0, g_Wout, g_bout, g_W1, g_b1, ...) of the reference kernels."""
    NL = len(flat)
    g_W0 = flat[0].t().mm(xu)
    g_b0 = flat[0].sum(0)
    g_U = flat[0].mm(W0[:, 2:]).view(U.shape) if needs_u else None
    g_Wout = lam_next.t().mm(hflat[NL - 1]) * dt
    g_bout = lam_next.sum(0) * dt
    hidden_grads = []
    for i in range(1, NL):
        hidden_grads.append(flat[i].t().mm(hflat[i - 1]))
        hidden_grads.append(flat[i].sum(0))
    return (g_U, g_W0, g_b0, g_Wout, g_bout, *hidden_grads)


def _weight_grads_fast(flat, hflat, lam_next, xu, W0, U, dt, needs_u):
    """The same for the fast kernels: flat holds dL/d(2a), hflat s = σ(2a) (h = 2s - 1), so
    dL/dW_i = 2·δᵀ·h = 4·δᵀ·s - 2·(Σδ)·1ᵀ and dL/db_i = 2·Σδ; hflat's last layer holds h
    itself (the head's gradient dt·λᵀ·h, where the folded form loses digits)."""
    NL = len(flat)
    col0 = flat[0].sum(0)
    g_W0 = xu.t().mm(flat[0]).t().mul_(2.0)  # skinny: (xᵀ·δ)ᵀ runs ~10x faster than δᵀ·x
    g_U = flat[0].mm(W0[:, 2:] * 2.0).view(U.shape) if needs_u else None
    lsum = lam_next.sum(0)
    g_Wout = lam_next.t().mm(hflat[NL - 1]).mul_(dt)  # hflat[NL - 1] holds h = 2s - 1 here
    hidden_grads = []
    for i in range(1, NL):
        col = flat[i].sum(0)
        corr = (col * -2.0)[:, None].expand(-1, hflat[i - 1].shape[1])
        hidden_grads.append(torch.addmm(corr, flat[i].t(), hflat[i - 1], alpha=4.0))
        hidden_grads.append(col * 2.0)
    return (g_U, g_W0, col0 * 2.0, g_Wout, lsum * dt, *hidden_grads)


def _weight_grads_native(rev, xu, W0, U, dt, needs_u):
    """The same from the native reverse loop's sums (:class:`fused_native.Reverse`): the
    first layer's from its deltas D0 (the skinny products in the fast order), the hidden
    layers' G_i and col_i as they are, the head's dt·GH and dt·lsum."""
    T1, B, H = rev.D0.shape
    d0 = rev.D0.view(T1 * B, H)
    g_W0 = xu.t().mm(d0).t()  # skinny: (xᵀ·δ)ᵀ runs ~10x faster than δᵀ·x
    g_U = d0.mm(W0[:, 2:]).view(U.shape) if needs_u else None
    hidden_grads = []
    for i in range(1, rev.col.shape[0]):
        hidden_grads += [rev.G[i - 1], rev.col[i]]
    return (g_U, g_W0, rev.col[0], rev.GH * dt, rev.lsum * dt, *hidden_grads)
