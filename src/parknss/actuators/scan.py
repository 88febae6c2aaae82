"""Parallel (log-depth) scans of linear recurrences, differentiable, for whole-sequence rollouts.

``scalar_scan`` solves x[k+1] = a[k]·x[k] + b[k] and ``matrix_scan`` solves
x[k+1] = A[k] x[k] + b[k] by Hillis-Steele doubling over the composed affine maps: log2(T)
vectorised steps instead of T sequential ones, so fitting a lag over long windows costs
milliseconds. The result equals the sequential recurrence up to floating-point rounding
(the products are associated differently; the tests bound the difference at 1e-12).
"""

from __future__ import annotations

import torch
from torch import Tensor


def scalar_scan(x0: Tensor, a: Tensor, b: Tensor) -> Tensor:
    """States (B, T) with X[:, 0] = x0 (B,), X[:, k+1] = a[:, k]·X[:, k] + b[:, k].

    a, b: (B, T-1) coefficients of the steps.
    """
    M, c = a, b
    n = a.shape[1]
    d = 1
    while d < n:
        M, c = (
            torch.cat([M[:, :d], M[:, d:] * M[:, :-d]], dim=1),
            torch.cat([c[:, :d], M[:, d:] * c[:, :-d] + c[:, d:]], dim=1),
        )
        d *= 2
    return torch.cat([x0[:, None], M * x0[:, None] + c], dim=1)


def matrix_scan(x0: Tensor, A: Tensor, b: Tensor) -> Tensor:
    """States (B, T, 2) with X[:, 0] = x0 (B, 2), X[:, k+1] = A[:, k] @ X[:, k] + b[:, k].

    A: (B, T-1, 2, 2); b: (B, T-1, 2). The 2x2 products are written out elementwise
    (batched tiny matmuls are slow on the CPU).
    """
    m = [A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1]]
    c = [b[..., 0], b[..., 1]]
    steps = A.shape[1]
    d = 1
    while d < steps:
        a = [x[:, d:] for x in m]
        p = [x[:, :-d] for x in m]
        q = [x[:, :-d] for x in c]
        new_m = [
            a[0] * p[0] + a[1] * p[2], a[0] * p[1] + a[1] * p[3],
            a[2] * p[0] + a[3] * p[2], a[2] * p[1] + a[3] * p[3],
        ]
        new_c = [a[0] * q[0] + a[1] * q[1] + c[0][:, d:], a[2] * q[0] + a[3] * q[1] + c[1][:, d:]]
        m = [torch.cat([x[:, :d], y], dim=1) for x, y in zip(m, new_m, strict=True)]
        c = [torch.cat([x[:, :d], y], dim=1) for x, y in zip(c, new_c, strict=True)]
        d *= 2
    x0a, x0b = x0[:, 0:1], x0[:, 1:2]
    r0 = m[0] * x0a + m[1] * x0b + c[0]
    r1 = m[2] * x0a + m[3] * x0b + c[1]
    return torch.cat([x0[:, None], torch.stack([r0, r1], dim=-1)], dim=1)
