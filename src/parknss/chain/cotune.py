"""Consequence-level co-tuning of one submodel (paper §III-C, §V-E).

The chain's blind-zone-masked velocity loss (MSE of vx in (km/h)² over the samples whose
logged speed is outside the blind zone, |vx| >= 0.5 km/h) is backpropagated through the
frozen NSS and the other frozen submodels into the weights of one submodel alone.

Budget: trials are tiled into windows of ``window`` samples (the last end-aligned), each
rolled out from its measured state and actuals at the window start; the first ``burn_in``
samples of a window are not scored (the command histories fill from the first command).
Each Adam step uses ``batch`` windows drawn at random (seeded), so a step costs a fixed
number of samples whatever the campaign size. Every ``eval_every`` steps (and after the
last) the loss over *all* windows is evaluated without gradients, and the weights with the
lowest such loss are kept, the starting weights included, so co-tuning never leaves the
submodel worse on its tuning data than it found it (a noisy minibatch run can otherwise
end above its start).

The NSS stays frozen: its parameters are never handed to the optimiser. Its fused Euler
kernel computes the input gradient only when its parameters require gradients, so a
float32 copy (the NSS's training precision) has them switched on and their gradients are
discarded.

When other submodels read the vehicle state (state-aware variants) the exact chain is an
interleaved per-sample loop, too slow to differentiate on one core. The gradient then uses
a frozen context: the exact chain is run once (and every ``refresh_every`` steps, if set)
without gradients; the state-aware frozen submodels' outputs are held at those values (as
if measured) and state features read those states. The path tuned submodel -> vehicle
state -> other submodel is neglected between refreshes; every reported chain score is of
the exact chain.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from parknss.actuators.config import CotuneConfig
from parknss.actuators.spec import CHANNEL_INDEX, CHANNELS
from parknss.chain.model import ACTUALS, Chain
from parknss.chain.trials import chain_predictions
from parknss.data.trial import Trial
from parknss.errors import DataError, ParknssError
from parknss.signals import BLIND_ZONE_MS, COMMAND_CHANNELS, KMH_PER_MS


@dataclass
class CotuneReport:
    """Minibatch loss per step ((km/h)², masked), seconds."""

    channel: str
    history: list[float] = field(default_factory=list)
    wall_s: float = 0.0
    evals: list[tuple[int, float]] = field(default_factory=list)
    best_step: int = 0

    def to_json(self) -> dict:
        h = self.history
        return {"channel": self.channel, "iters": len(h), "wall_s": self.wall_s,
                "loss_first": h[0] if h else None,
                "loss_last5_mean": float(np.mean(h[-5:])) if h else None,
                "full_loss": [[s, v] for s, v in self.evals], "best_step": self.best_step}


@dataclass
class _Windows:
    cmds: np.ndarray  # (N, L, 4)
    actuals: np.ndarray  # (N, L, 3), frozen state-aware channels from the context
    x0: np.ndarray  # (N, 2)
    y0: np.ndarray  # (N, 3)
    vx: np.ndarray  # (N, L) logged
    mask: np.ndarray  # (N, L)
    states: tuple[np.ndarray, np.ndarray] | None  # context (vx, yaw) (N, L)


def _starts(n: int, L: int) -> list[int]:
    if n <= L:
        return [0]
    s = list(range(0, n - L + 1, L))
    return s if s[-1] == n - L else [*s, n - L]


def make_windows(trials: Sequence[Trial], cfg: CotuneConfig, context: dict | None,
                 frozen: Sequence[str]) -> _Windows:
    """Windows of every trial (see the module doc); ``context`` = chain predictions."""
    L = min(cfg.window, max(tr.n for tr in trials))
    rows: dict[str, list] = {k: [] for k in ("c", "a", "x0", "y0", "vx", "m", "sv", "sy")}
    for tr in trials:
        cm, ac = tr.array(COMMAND_CHANNELS), tr.array(ACTUALS)
        if context is not None:
            p = context[tr.id]
            for ch in frozen:
                ac[:, CHANNEL_INDEX[ch]] = p[ACTUALS[CHANNEL_INDEX[ch]]]
        for a in _starts(tr.n, L):
            b = min(a + L, tr.n)
            pad = L - (b - a)

            def cut(x, a=a, b=b, pad=pad):
                return np.pad(x[a:b], [(0, pad)] + [(0, 0)] * (x.ndim - 1), mode="edge")

            rows["c"].append(cut(cm))
            rows["a"].append(cut(ac))
            rows["x0"].append([tr["vx"][a], tr["yaw_rate"][a]])
            rows["y0"].append(ac[a])
            rows["vx"].append(cut(tr["vx"]))
            m = np.zeros(L, dtype=bool)
            m[min(cfg.burn_in, b - a - 1) : b - a] = True
            rows["m"].append(m & (np.abs(cut(tr["vx"])) >= BLIND_ZONE_MS))
            if context is not None:
                rows["sv"].append(cut(context[tr.id]["vx"]))
                rows["sy"].append(cut(context[tr.id]["yaw_rate"]))
    st = (np.stack(rows["sv"]), np.stack(rows["sy"])) if context is not None else None
    return _Windows(np.stack(rows["c"]), np.stack(rows["a"]), np.array(rows["x0"]),
                    np.array(rows["y0"]), np.stack(rows["vx"]), np.stack(rows["m"]), st)


def _loss(chain: Chain, w: _Windows, idx: np.ndarray, kind: str) -> torch.Tensor:
    states = None
    if w.states is not None:
        states = (torch.as_tensor(w.states[0][idx]), torch.as_tensor(w.states[1][idx]))
    r = chain.rollout(w.cmds[idx], torch.as_tensor(w.x0[idx]), torch.as_tensor(w.y0[idx]),
                      torch.as_tensor(w.actuals[idx]), states=states)
    e = (r.nss.vx.to(torch.float64) - torch.as_tensor(w.vx[idx])) * KMH_PER_MS
    m = torch.as_tensor(w.mask[idx])
    if not bool(m.any()):
        return (e * 0.0).sum()
    return (e**2)[m].mean() if kind == "mse" else e.abs()[m].mean()


def cotune(
    chain: Chain,
    channel: str,
    trials: Sequence[Trial],
    cfg: CotuneConfig,
    progress: Callable[[str], None] | None = None,
) -> CotuneReport:
    """Fine-tune ``chain.model(channel)`` in place; every other weight stays as it was."""
    target = chain.model(channel)
    if target is None:
        raise DataError(f"co-tuning: channel {channel} has no submodel in this chain")
    trials = list(trials)
    t0 = time.perf_counter()
    chain.requires_grad_(False)
    frozen = [c for c in CHANNELS if c != channel and (m := chain.model(c)) is not None
              and m.spec.state_aware]
    need_ctx = bool(frozen) or target.spec.state_aware
    nss32 = copy.deepcopy(chain.nss).float()
    nss32.requires_grad_(True)  # for the fused kernel's input gradient only
    sur = Chain(nss32, {c: m for c, m in chain.models().items() if c not in frozen},
                chain.envelope)
    rng = np.random.default_rng(cfg.seed)
    opt = torch.optim.Adam(target.parameters(), lr=cfg.lr)
    hist: list[float] = []
    evals: list[tuple[int, float]] = []
    best: tuple[float, int, dict] | None = None
    w = None

    def full_loss() -> float:
        with torch.no_grad():
            return float(_loss(sur, w, np.arange(len(w.cmds)), cfg.loss))

    def checkpoint(step: int) -> None:
        nonlocal best
        v = full_loss()
        evals.append((step, v))
        if best is None or v < best[0]:
            best = (v, step, copy.deepcopy(target.state_dict()))

    try:
        for it in range(cfg.iters):
            if w is None or (cfg.refresh_every and it % cfg.refresh_every == 0 and need_ctx):
                target.requires_grad_(False)
                ctx = chain_predictions(chain.double(), trials) if need_ctx else None
                w = make_windows(trials, cfg, ctx, frozen)
                if best is None:
                    checkpoint(0)
            target.requires_grad_(True)
            idx = rng.choice(len(w.cmds), size=min(cfg.batch, len(w.cmds)), replace=False)
            opt.zero_grad(set_to_none=True)
            loss = _loss(sur, w, np.sort(idx), cfg.loss)
            lv = float(loss.detach())
            if not math.isfinite(lv):
                raise ParknssError(f"co-tuning diverged at step {it} (loss {lv})")
            hist.append(lv)
            if progress is not None and (it % 5 == 0 or it == cfg.iters - 1):
                progress(f"co-tune {channel} step {it + 1}/{cfg.iters}: "
                         f"minibatch loss {lv:.5f} (km/h)^2")
            loss.backward()
            opt.step()
            if (it + 1) % cfg.eval_every == 0 or it == cfg.iters - 1:
                target.requires_grad_(False)
                checkpoint(it + 1)
    finally:
        target.requires_grad_(False)
        target.eval()
    best_step = 0
    if best is not None:
        target.load_state_dict(best[2])
        best_step = best[1]
        if progress is not None:
            progress(f"co-tune {channel}: kept step {best_step} (all-window loss {best[0]:.5f})")
    return CotuneReport(channel, hist, time.perf_counter() - t0, evals, best_step)
