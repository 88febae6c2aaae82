"""Training recipes (``train.recipe``): which batch, learning rate and validation each step has.

A fit is a sequence of Adam steps k = 1..K; a recipe says, for each k, the batch it
trains on, its learning rate, whether the held-out trials are validated before it, and
whether its training loss is a deployment criterion (a full-batch step). The loop of
:func:`parknss.nss.train.fit` is the same for every recipe.

``paper`` (§IV-B): K = ``train.epochs`` full-batch steps over the end-aligned windows of
the shortest training trial (:mod:`parknss.data.windows`), LR cosine from ``train.lr`` to
``train.lr_min`` over K, validation every ``train.val_every`` steps and at the last.

``fast`` (this toolkit's, not the paper's; ``fast`` section of the NSS config):

1. ``fast.updates`` steps on minibatches of ``fast.batch`` windows of ``fast.window``
   samples, the same end-aligned tiling over every training trial, each rolled out from
   its measured initial state. The windows are drawn without replacement in passes of
   ⌊n / batch⌋ updates; pass p is ordered by a permutation seeded with
   (``train.seed``, p), so a resumed fit draws the same minibatches. LR cosine from
   ``fast.lr`` to ``train.lr_min`` over the phase; validation every ``fast.val_every``
   updates.
2. ``fast.finish_epochs`` full-batch steps on the paper's windows (the paper's objective:
   long-horizon open-loop rollouts), LR cosine from ``fast.finish_lr`` to
   ``train.lr_min``; validation every ``train.val_every`` steps and at the last.

A short-window update costs more than window·batch / (L·n_L) of a paper epoch (the
rollout's sequential steps carry a per-step overhead that small batches do not amortise:
on the paper-size net, 8 windows of 1024 samples cost 0.18 CPU s, 16 windows 0.28, 32
windows 0.51, a paper epoch of 29 x 2227 about 1.1), yet phase 1 still makes many
updates for the CPU time of few epochs; phase 2 teaches the whole-window horizon the
short windows cannot see.

``coarse`` (this toolkit's, not the paper's; ``coarse`` section of the NSS config):

1. ``coarse.epochs`` full-batch steps on the paper's windows of the training trials
   decimated by m = ``coarse.factor`` (:mod:`parknss.data.decimate`: every m-th sample,
   the continuous inputs averaged over each step), rolled out with an Euler step of m·dt:
   the same windows and horizon in seconds at 1/m of the sequential steps, so an epoch
   costs about 1/m of a paper epoch. f_θ is a time derivative (eq. 3b), so the vector
   field learnt at m·dt is the one the full-rate model integrates. LR cosine from
   ``coarse.lr`` to ``train.lr_min``; held-out validation at the full rate (the
   deployment criterion) every ``coarse.val_every`` epochs.
2. ``coarse.finish_epochs`` paper epochs at the full rate (the Euler step's own error
   and the fast input changes the coarse step averages), LR cosine from
   ``coarse.finish_lr`` to ``train.lr_min``; validation every ``train.val_every`` steps
   and at the last.

One Adam state runs through every phase of a recipe.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from parknss.data.decimate import decimate, grid_length
from parknss.data.trial import Trial
from parknss.data.windows import make_windows
from parknss.nss.batch import Batch, make_batch
from parknss.nss.config import NSSConfig
from parknss.nss.model import INPUTS, NSSModel

PERMUTATION_STRIDE = 1_000_003
"""Seed of pass p's permutation: train.seed · stride + p (distinct for p < stride)."""


def cosine(k: int, n: int, hi: float, lo: float) -> float:
    """Cosine from ``hi`` at k = 1 to ``lo`` at k = n (``hi`` throughout if n <= 1)."""
    if n <= 1:
        return hi
    return lo + 0.5 * (hi - lo) * (1.0 + math.cos(math.pi * (k - 1) / (n - 1)))


@dataclass(frozen=True)
class Step:
    """What step k does: train on ``batch`` at ``lr``; validate first if ``validate``.

    ``full``: a full-batch step at the full rate (its training loss is the criterion of a
    fit without held-out trials); ``phase``: "paper", "short", "coarse" or "full".
    """

    batch: Batch
    lr: float
    validate: bool
    full: bool
    phase: str


class PaperRecipe:
    """§IV-B: full-batch BPTT over the paper's windows, cosine over ``train.epochs``."""

    name = "paper"

    def __init__(self, cfg: NSSConfig, full: Batch) -> None:
        self.cfg, self.full = cfg, full
        self.steps = cfg.train.epochs

    def step(self, k: int) -> Step:
        t = self.cfg.train
        lr = t.lr if t.schedule == "constant" else cosine(k, self.steps, t.lr, t.lr_min)
        val = (k - 1) % t.val_every == 0 or k == self.steps
        return Step(self.full, lr, val, True, "paper")


def finish_step(cfg: NSSConfig, full: Batch, j: int, n: int, lr0: float) -> Step:
    """Step j (1-based) of an n-epoch full-rate finish on ``full`` (the paper's windows):
    LR cosine from ``lr0`` to ``train.lr_min``, validation every ``train.val_every`` and
    at the last."""
    t = cfg.train
    val = (j - 1) % t.val_every == 0 or j == n
    return Step(full, cosine(j, n, lr0, t.lr_min), val, True, "full")


class FastRecipe:
    """Minibatches of short windows, then a full-window finish (module docstring)."""

    name = "fast"

    def __init__(self, cfg: NSSConfig, full: Batch, short: Batch) -> None:
        self.cfg, self.full, self.short = cfg, full, short
        f = cfg.fast
        self.updates, self.finish = f.updates, f.finish_epochs
        self.steps = self.updates + self.finish
        self.size = min(f.batch, short.n)
        self.per_pass = max(short.n // self.size, 1)
        self._perm: tuple[int, torch.Tensor] | None = None

    def permutation(self, p: int) -> torch.Tensor:
        """Order of the short windows in pass p (deterministic under train.seed)."""
        if self._perm is None or self._perm[0] != p:
            g = torch.Generator().manual_seed(self.cfg.train.seed * PERMUTATION_STRIDE + p)
            self._perm = (p, torch.randperm(self.short.n, generator=g))
        return self._perm[1]

    def minibatch(self, k: int) -> Batch:
        """The windows of phase-1 update k (1-based)."""
        p, j = divmod(k - 1, self.per_pass)
        idx = self.permutation(p)[j * self.size : (j + 1) * self.size]
        return self.short.select(idx)

    def step(self, k: int) -> Step:
        f, t = self.cfg.fast, self.cfg.train
        if k <= self.updates:
            lr = cosine(k, self.updates, f.lr, t.lr_min)
            return Step(self.minibatch(k), lr, (k - 1) % f.val_every == 0, False, "short")
        return finish_step(self.cfg, self.full, k - self.updates, self.finish, f.finish_lr)


class CoarseRecipe:
    """Full-batch epochs at a coarse step, then a full-rate finish (module docstring)."""

    name = "coarse"

    def __init__(self, cfg: NSSConfig, full: Batch, coarse: Batch) -> None:
        self.cfg, self.full, self.coarse = cfg, full, coarse
        c = cfg.coarse
        self.epochs, self.finish = c.epochs, c.finish_epochs
        self.steps = self.epochs + self.finish

    def step(self, k: int) -> Step:
        c, t = self.cfg.coarse, self.cfg.train
        if k <= self.epochs:
            lr = cosine(k, self.epochs, c.lr, t.lr_min)
            val = (k - 1) % c.val_every == 0 or k == self.steps  # the last, without a finish
            return Step(self.coarse, lr, val, False, "coarse")
        return finish_step(self.cfg, self.full, k - self.epochs, self.finish, c.finish_lr)


HELD_INPUTS: tuple[str, ...] = tuple(c for c in INPUTS if c != "gear")
"""The inputs a coarse step averages over its samples (the gear is sampled)."""


def make_recipe(
    cfg: NSSConfig, model: NSSModel, train: Sequence[Trial], L: int
) -> PaperRecipe | FastRecipe | CoarseRecipe:
    """The recipe of ``cfg.train.recipe`` with its batches built for ``model``."""
    bz = cfg.loss.blind_zone_kmh
    full = make_batch(model, make_windows(train, L), bz)
    if cfg.train.recipe == "paper":
        return PaperRecipe(cfg, full)
    if cfg.train.recipe == "coarse":
        m = cfg.coarse.factor
        dec = [decimate(t, m, HELD_INPUTS) for t in train]
        coarse = make_batch(model, make_windows(dec, grid_length(L, m)), bz, stride=m)
        return CoarseRecipe(cfg, full, coarse)
    short = make_batch(model, make_windows(train, cfg.fast.window), bz)
    return FastRecipe(cfg, full, short)
