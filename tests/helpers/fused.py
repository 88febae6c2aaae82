"""Random weights and inputs of the fused rollout and output MLP, and their plain-autograd
references (float64; tests/nss/test_fused.py, tests/nss/test_fused_native.py)."""

from __future__ import annotations

import torch

F64 = torch.float64


def rand(*shape, scale=0.5, gen):
    """A float64 leaf tensor of normal draws times ``scale`` that requires grad."""
    return (torch.randn(*shape, generator=gen, dtype=F64) * scale).requires_grad_(True)


def euler_args(B=2, T=6, H=4, m=4, hidden_layers=1, seed=0):
    """x0 (B, 2), U (T-1, B, m), W0, b0, Wout, bout and the hidden [W, b, ...] of the rollout."""
    g = torch.Generator().manual_seed(seed)
    x0 = rand(B, 2, gen=g)
    U = rand(T - 1, B, m, gen=g)
    W0, b0 = rand(H, 2 + m, gen=g), rand(H, gen=g)
    Wout, bout = rand(2, H, gen=g), rand(2, gen=g)
    hidden = []
    for _ in range(hidden_layers):
        hidden += [rand(H, H, gen=g), rand(H, gen=g)]
    return x0, U, W0, b0, Wout, bout, hidden


def euler_reference(dt, x0, U, W0, b0, Wout, bout, *hidden):
    """The recurrence in plain autograd: x+ = x + dt·(Wout·tanh(...tanh(W0[x,u]+b0)) + bout)."""
    xs = [x0]
    x = x0
    for k in range(U.shape[0]):
        h = torch.tanh(torch.cat([x, U[k]], dim=1) @ W0.t() + b0)
        for W, b in zip(hidden[0::2], hidden[1::2], strict=True):
            h = torch.tanh(h @ W.t() + b)
        x = x + dt * (h @ Wout.t() + bout)
        xs.append(x)
    return torch.stack(xs)


def mlp_args(N, n_in, H, layers, n_out, seed=1, scale=0.5):
    """x (N, n_in) and the flat parameter list (W0, b0, ..., W_out, b_out) of a tanh MLP."""
    g = torch.Generator().manual_seed(seed)
    x = rand(N, n_in, gen=g, scale=scale)
    params = []
    width = n_in
    for _ in range(layers):
        params += [rand(H, width, gen=g, scale=scale), rand(H, gen=g, scale=scale)]
        width = H
    params += [rand(n_out, H, gen=g, scale=scale), rand(n_out, gen=g, scale=scale)]
    return x, params


def mlp_reference(x, *params):
    """The tanh MLP in plain autograd: W_out·tanh(... tanh(W0·x + b0) ...) + b_out."""
    h = x
    for W, b in zip(params[0:-2:2], params[1:-2:2], strict=True):
        h = torch.tanh(h @ W.t() + b)
    return h @ params[-2].t() + params[-1]
