"""A small deterministic job for checking an executor end to end (local pool or Ray).

``probe_fit`` fits a least-squares line to seeded noisy samples with torch and returns the
coefficients: a miniature of the real sweeps (seeded, torch, JSON result), cheap enough to
run on every worker of a cluster. tests/test_executor.py runs it in-process, on the local
pool and on Ray (:mod:`parknss.executor`) and compares the results.
"""

from __future__ import annotations

import torch


def probe_fit(seed: int, n: int = 256, steps: int = 50) -> dict[str, float]:
    """Fit y = a·x + b by Adam on n seeded samples; return a, b and the final loss (float)."""
    gen = torch.Generator().manual_seed(seed)
    x = torch.linspace(-1.0, 1.0, n, dtype=torch.float64)
    y = 0.7 * x - 0.2 + 0.05 * torch.randn(n, generator=gen, dtype=torch.float64)
    params = torch.zeros(2, dtype=torch.float64, requires_grad=True)
    opt = torch.optim.Adam([params], lr=0.05)
    loss = torch.tensor(0.0)
    for _ in range(steps):
        opt.zero_grad()
        loss = ((params[0] * x + params[1] - y) ** 2).mean()
        loss.backward()
        opt.step()
    a, b = params.detach().tolist()
    return {"seed": seed, "a": a, "b": b, "loss": float(loss.detach())}
