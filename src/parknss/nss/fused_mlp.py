"""A tanh MLP over a large stack of samples with a hand-written backward.

The output network is not part of the recurrence, so it is applied once to the whole
stacked trajectory (all windows x all steps, ~60 000 rows at paper size). Its arithmetic
is a handful of large matmuls; under autograd each epoch also allocates a dozen fresh
31 MB activation and gradient tensors, and faulting those pages in costs more than the
arithmetic. This Function computes the same layers into recycled buffers
(:mod:`parknss.nss.workspace`) and backpropagates by hand: δ_L = g·W_out ⊙ (1 - h_L²),
δ_{i} = δ_{i+1}·W_{i+1} ⊙ (1 - h_i²), weight gradients δᵀ·h.

apply(kernels, x (N, n_in), W0, b0, W1, b1, ..., W_out, b_out) -> y (N, n_out), ``kernels``
one of :data:`parknss.nss.fused.KERNELS`. Checked against autograd by gradcheck in float64
(tests/nss/test_fused.py).
"""

from __future__ import annotations

import weakref

import torch

from parknss.nss import fused_native
from parknss.nss.fused import is_fast
from parknss.nss.workspace import WORKSPACE


class FusedTanhMLP(torch.autograd.Function):
    """y = W_out·tanh(... tanh(W0·x + b0) ...) + b_out, activations in recycled buffers.

    With the fast kernels the buffers hold s = σ(2a) (tanh(a) = 2s - 1) and the affine
    2s - 1 is folded into the next product's weights and bias, as in the fused rollout."""

    @staticmethod
    def forward(ctx, kernels: str, x, *params):
        fast = is_fast(kernels)
        Ws, bs = list(params[0::2]), list(params[1::2])
        N = x.shape[0]
        ctx.native = kernels == "native" and len(Ws) > 1
        if ctx.native:
            return _forward_native(ctx, x, Ws, bs)
        hs = []
        h = x
        for i, (W, b) in enumerate(zip(Ws[:-1], bs[:-1], strict=True)):
            buf = WORKSPACE.take((N, W.shape[0]), x.dtype)
            if fast and i == 0:  # s = σ(2a), the addmm giving 2a = 2b + 2·W·x
                torch.addmm(b * 2.0, h, W.t(), alpha=2.0, out=buf)
                buf.sigmoid_()
            elif fast:  # 2a = 2·(b - W·1) + 4·W·s_prev
                torch.addmm((b - W.sum(1)) * 2.0, h, W.t(), alpha=4.0, out=buf)
                buf.sigmoid_()
            else:
                torch.addmm(b, h, W.t(), out=buf)
                buf.tanh_()
            hs.append(buf)
            h = buf
        if fast and hs:
            y = torch.addmm(bs[-1] - Ws[-1].sum(1), h, Ws[-1].t(), alpha=2.0)
        else:
            y = torch.addmm(bs[-1], h, Ws[-1].t())
        ctx.hs, ctx.fast = hs, fast
        for buf in hs:
            weakref.finalize(ctx, WORKSPACE.give, buf)
        ctx.save_for_backward(x, *Ws)
        return y

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g):
        x, *Ws = ctx.saved_tensors
        if ctx.native:
            return _backward_native(ctx, g.contiguous(), x, Ws)
        if ctx.fast and ctx.hs:
            return _backward_fast(ctx, g.contiguous(), x, Ws)
        hs = ctx.hs
        g = g.contiguous()
        grads_W: list = [None] * len(Ws)
        grads_b: list = [None] * len(Ws)
        grads_W[-1] = g.t().mm(hs[-1])
        grads_b[-1] = g.sum(0)
        bufs = [WORKSPACE.take(tuple(h.shape), h.dtype) for h in hs[:2]]
        d_next = g
        W_next = Ws[-1]
        for i in range(len(hs) - 1, -1, -1):
            d = bufs[i % len(bufs)]
            torch.mm(d_next, W_next, out=d)
            torch.ops.aten.tanh_backward(d, hs[i], grad_input=d)
            h_in = hs[i - 1] if i > 0 else x
            grads_W[i] = d.t().mm(h_in)
            grads_b[i] = d.sum(0)
            d_next, W_next = d, Ws[i]
        gx = None
        if ctx.needs_input_grad[1]:
            gx = d_next.mm(W_next)
        for b in bufs:
            WORKSPACE.give(b)
        return _pack(gx, grads_W, grads_b)


def _pack(gx, grads_W, grads_b) -> tuple:
    out = [None, gx]
    for gw, gb in zip(grads_W, grads_b, strict=True):
        out += [gw, gb]
    return tuple(out)


_OUTER_MAX = 4
"""Up to this many outputs the fast backward forms the head's g·W (N x n_out x H) as n_out
broadcast products instead of one matmul: a product over so few terms runs at memory
speed either way, and this BLAS takes about twice as long (8 against 4 ms at N = 61 509)."""


def _outer(g, W, out) -> None:
    """out = g·W (N, H) for g (N, n) and W (n, H) as Σ_j g[:, j] ⊗ W[j] (n small)."""
    torch.mul(g[:, :1], W[0], out=out)
    for j in range(1, g.shape[1]):
        out.addcmul_(g[:, j : j + 1], W[j])


def _backward_fast(ctx, g, x, Ws) -> tuple:
    """Backward of the fast kernels: hs hold s = σ(2a); δ = dL/d(2a) = (dL/ds)·s·(1 - s);
    dL/dW = 2·δᵀ·h_in with h_in = 2s_in - 1 (4·δᵀ·s_in - 2·(Σδ)·1ᵀ) or x for the first."""
    hs = ctx.hs
    n = len(hs)
    grads_W: list = [None] * len(Ws)
    grads_b: list = [None] * len(Ws)
    h_last = WORKSPACE.take(tuple(hs[-1].shape), hs[-1].dtype)
    torch.add(-1.0, hs[-1], alpha=2.0, out=h_last)  # the head's gᵀ·h from h = 2s - 1 itself:
    grads_W[-1] = g.t().mm(h_last)  # 2·gᵀ·s - Σg cancels badly
    WORKSPACE.give(h_last)
    grads_b[-1] = g.sum(0)
    bufs = [WORKSPACE.take(tuple(h.shape), h.dtype) for h in hs[:2]]
    d_next = g
    W_next = Ws[-1] * 2.0  # dL/ds = d_next·(2·W_out), then (4·W_{i+1}) for the hidden ones
    for i in range(n - 1, -1, -1):
        d = bufs[i % len(bufs)]
        if i == n - 1 and g.shape[1] <= _OUTER_MAX:
            _outer(g, W_next, d)
        else:
            torch.mm(d_next, W_next, out=d)
        torch.ops.aten.sigmoid_backward(d, hs[i], grad_input=d)
        col = d.sum(0)
        if i > 0:
            corr = (col * -2.0)[:, None].expand(-1, hs[i - 1].shape[1])
            grads_W[i] = torch.addmm(corr, d.t(), hs[i - 1], alpha=4.0)
            W_next = (Ws[i] * 4.0).t().contiguous().t()  # column-major: ~10 % faster here
        else:  # skinny input: (xᵀ·δ)ᵀ runs ~10x faster than δᵀ·x
            grads_W[i] = x.t().mm(d).t().mul_(2.0)
            W_next = (Ws[i] * 2.0).t().contiguous().t()  # (H, n_in): ~3x faster
        grads_b[i] = col * 2.0
        d_next = d
    gx = None
    if ctx.needs_input_grad[1]:
        gx = d_next.mm(W_next)
    for b in bufs:
        WORKSPACE.give(b)
    return _pack(gx, grads_W, grads_b)


def _forward_native(ctx, x, Ws, bs):
    """The forward by the native kernels (:mod:`parknss.nss.fused_native`, tanh activations,
    plain weights): all hidden activations h into one recycled (NL, N, H) buffer."""
    H = Ws[0].shape[0]
    S = WORKSPACE.take((len(Ws) - 1, x.shape[0], H), x.dtype)
    hidden = list(zip(Ws[1:-1], bs[1:-1], strict=True))
    y = fused_native.mlp_forward(
        x.contiguous(),
        Ws[0].t().contiguous(),
        bs[0].contiguous(),
        fused_native.stacked([w.t() for w, _ in hidden], (H, H), x.dtype),
        fused_native.stacked([b for _, b in hidden], (H,), x.dtype),
        Ws[-1].contiguous(),
        bs[-1].contiguous(),
        S,
    )
    ctx.S = S
    weakref.finalize(ctx, WORKSPACE.give, S)
    ctx.save_for_backward(x, *Ws)
    return y


def _backward_native(ctx, g, x, Ws) -> tuple:
    """Its backward: the sums of the C loop (:class:`fused_native.MLPGrads`) are the weight
    gradients (the first layer's transposed)."""
    H = Ws[0].shape[0]
    hidden = Ws[1:-1]
    r = fused_native.mlp_backward(
        x.contiguous(),
        g,
        ctx.S,
        Ws[0].t().contiguous(),
        fused_native.stacked(list(hidden), (H, H), x.dtype),
        Ws[-1].contiguous(),
    )
    grads_W = [r.G0.t(), *r.G.unbind(0), r.GH]
    grads_b = [r.col[i] for i in range(r.col.shape[0])] + [r.gsum]
    gx = r.gx if ctx.needs_input_grad[1] else None
    return _pack(gx, grads_W, grads_b)
