"""One verdict rule for every finding: paired effects, a bootstrap interval, the seed floor.

An effect is relative (``option / baseline - 1``). It is measured as **pairs**: per CV fold
``k`` and seed ``s`` where both sides exist, ``d[k][s]``; the effect is the mean over folds
of each fold's mean over its seeds. Its interval (:func:`estimate`) is the wider of two:

* the percentile interval of a **paired bootstrap over folds x seeds**: ``resamples`` draws
  (seeded by ``seed``), each drawing the folds with replacement and, within each drawn
  fold, its seeds with replacement (:func:`bootstrap_means`);
* the **seed-noise interval** ``effect ± q·se``, ``q`` the normal quantile of ``level``
  and ``se = sqrt(sum_k sd_k² / m_k) / n``: ``sd_k`` is the spread of one pair's effect
  across seeds on fold ``k`` (the floor of that fold, :class:`FoldNoise`), ``m_k`` its
  seeds, ``n`` the folds.

So an interval is never narrower than the seeds' noise, nor than the spread the folds
show. Every spread is a sample standard deviation (ddof = 1). A claim
(:class:`Claim`) is then read against the interval: ``above t`` agrees when the whole
interval is above ``t`` and differs when it is wholly below; ``below t`` the mirror;
``within m`` (a claim of no effect, ``|effect| <= m``) agrees when the interval lies
inside ``[-m, m]`` and differs when it lies wholly outside it. Anything else is
"cannot tell at this budget (effect x, interval [a, b])": the budget of fits, not the
claim, decides nothing. Units: fractions (0.05 = 5 %).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from statistics import NormalDist

import numpy as np

from parknss.experiments.config import VerdictConfig


def sample_sd(values: Sequence[float]) -> float:
    """Sample standard deviation (ddof = 1) of the finite values; NaN below two."""
    a = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    return float(a.std(ddof=1)) if a.size >= 2 else math.nan


@dataclass
class FoldNoise:
    """The seed spread of one pair's effect per fold (fractions): ``sd[k]`` where fold k has
    at least ``min_seeds`` seeds (``seeds[k]``, NaN otherwise). A fold with fewer borrows
    the pooled value (root mean square over the measured folds), or its own estimate from
    two seeds (``few[k]``) where that is larger: never a narrower floor than its own
    seeds show."""

    sd: dict[int, float]
    seeds: dict[int, int]
    min_seeds: int = 3
    source: str = "measured"
    prior: float = math.nan  # the pooled value where no fold is measured (e.g. the paper's)
    few: dict[int, float] = field(default_factory=dict)

    def pooled(self) -> float:
        vals = [v for v in self.sd.values() if math.isfinite(v)]
        return math.sqrt(sum(v * v for v in vals) / len(vals)) if vals else self.prior

    def of(self, fold: int) -> float:
        """The fold's own spread, else the larger of the pooled one and its two-seed
        estimate (NaN: no floor at all)."""
        v = self.sd.get(fold, math.nan)
        if math.isfinite(v):
            return v
        got = [x for x in (self.pooled(), self.few.get(fold, math.nan)) if math.isfinite(x)]
        return max(got) if got else math.nan

    def describe(self) -> str:
        own = ", ".join(f"f{k} {100 * v:.1f} % ({self.seeds.get(k, 0)})"
                        for k, v in sorted(self.sd.items()) if math.isfinite(v))
        few = sorted(k for k in self.seeds if not math.isfinite(self.sd.get(k, math.nan)))
        text = f"seed sd per fold (seeds) {own or 'none'}"
        if few:
            borrowed = ", ".join(f"f{k} {100 * self.of(k):.1f} % ({self.seeds.get(k, 0)})"
                                 for k in few)
            text += (f"; < {self.min_seeds} seeds, the larger of pooled "
                     f"{100 * self.pooled():.1f} % and two seeds': {borrowed}")
        return text if self.source == "measured" else f"{text} ({self.source})"


@dataclass(frozen=True)
class Claim:
    """What the paper claims of an effect: ``above`` / ``below`` a threshold ``t`` or
    ``within`` ± ``t`` of zero (a claim of no effect)."""

    kind: str
    t: float = 0.0

    def read(self, lo: float, hi: float) -> bool | None:
        """True (agrees), False (differs) or None (cannot tell) from the interval."""
        if not (math.isfinite(lo) and math.isfinite(hi)):
            return None
        t = self.t
        if self.kind == "above":
            return True if lo > t else False if hi < t else None
        if self.kind == "below":
            return True if hi < t else False if lo > t else None
        if self.kind == "within":
            return True if -t <= lo and hi <= t else False if lo > t or hi < -t else None
        raise ValueError(f"unknown claim kind {self.kind!r}")


@dataclass
class Effect:
    """A relative effect, its interval and the two intervals it is the hull of."""

    effect: float
    lo: float
    hi: float
    boot: tuple[float, float]
    noise_se: float
    n_folds: int
    n_pairs: int

    def text(self) -> str:
        if not math.isfinite(self.effect):
            return "n/a"
        return f"{100 * self.effect:+.1f} % [{100 * self.lo:+.1f}, {100 * self.hi:+.1f}]"


def bootstrap_means(pairs: Sequence[Sequence[float]], resamples: int, seed: int) -> np.ndarray:
    """``resamples`` bootstrap means of the fold means: folds drawn with replacement, then
    within each drawn fold its values (seeds) with replacement. ``pairs[k]``: fold k's
    values (at least one each)."""
    rng = np.random.default_rng(seed)
    n = len(pairs)
    width = max(len(p) for p in pairs)
    table = np.full((n, width), np.nan)
    for k, p in enumerate(pairs):
        table[k, : len(p)] = p
    sizes = np.array([len(p) for p in pairs])
    folds = rng.integers(0, n, size=(resamples, n))
    m = sizes[folds]  # (B, n) seeds of each drawn fold
    draws = np.floor(rng.random((resamples, n, width)) * m[..., None]).astype(int)
    used = np.arange(width)[None, None, :] < m[..., None]
    vals = np.where(used, table[folds[..., None], draws], 0.0)
    return (vals.sum(axis=2) / m).mean(axis=1)


def estimate(pairs: Mapping[int, Sequence[float]], noise: FoldNoise | None,
             cfg: VerdictConfig, scale: float = 1.0) -> Effect:
    """The effect of paired values ``pairs`` (fold -> per-seed effects; non-finite dropped)
    with its interval (module doc). ``noise``: the per-pair seed spread per fold, times
    ``scale`` (sqrt 2 for two independent fits); None: the bootstrap alone."""
    clean = {k: [v for v in vs if math.isfinite(v)] for k, vs in pairs.items()}
    clean = {k: v for k, v in clean.items() if v}
    n_pairs = sum(len(v) for v in clean.values())
    if not clean:
        return Effect(math.nan, math.nan, math.nan, (math.nan, math.nan), math.nan, 0, 0)
    folds = sorted(clean)
    eff = float(np.mean([np.mean(clean[k]) for k in folds]))
    alpha = (1.0 - cfg.level) / 2
    if n_pairs >= 2:
        means = bootstrap_means([clean[k] for k in folds], cfg.resamples, cfg.seed)
        boot = (float(np.quantile(means, alpha)), float(np.quantile(means, 1 - alpha)))
    else:  # one pair has no spread to resample
        boot = (math.nan, math.nan)
    se = math.nan
    if noise is not None:
        var = [(scale * noise.of(k)) ** 2 / len(clean[k]) for k in folds]
        se = math.sqrt(sum(var)) / len(folds)
    q = NormalDist().inv_cdf(1 - alpha)
    lows = [x for x in (boot[0], eff - q * se) if math.isfinite(x)]
    highs = [x for x in (boot[1], eff + q * se) if math.isfinite(x)]
    lo = min(lows) if lows else math.nan
    hi = max(highs) if highs else math.nan
    return Effect(eff, lo, hi, boot, se, len(folds), n_pairs)


def estimate_unpaired(a: Sequence[float], b: Sequence[float], cv: float,
                      cfg: VerdictConfig) -> Effect:
    """The effect ``mean(b) / mean(a) - 1`` of two unpaired samples (e.g. the folds of two
    different splits), its interval the hull of the bootstrap (each sample resampled on
    its own) and ``effect ± q·se``, ``se = (1 + effect)·cv·sqrt(1/n_a + 1/n_b)`` (``cv``:
    the relative seed spread of one fit)."""
    a = np.asarray([v for v in a if math.isfinite(v)], dtype=float)
    b = np.asarray([v for v in b if math.isfinite(v)], dtype=float)
    if a.size == 0 or b.size == 0 or a.mean() == 0:
        return Effect(math.nan, math.nan, math.nan, (math.nan, math.nan), math.nan, 0, 0)
    eff = float(b.mean() / a.mean() - 1)
    alpha = (1.0 - cfg.level) / 2
    rng = np.random.default_rng(cfg.seed)
    ra = a[rng.integers(0, a.size, (cfg.resamples, a.size))].mean(axis=1)
    rb = b[rng.integers(0, b.size, (cfg.resamples, b.size))].mean(axis=1)
    ratio = rb / ra - 1
    boot = (float(np.quantile(ratio, alpha)), float(np.quantile(ratio, 1 - alpha)))
    se = (1 + eff) * cv * math.sqrt(1 / a.size + 1 / b.size)
    q = NormalDist().inv_cdf(1 - alpha)
    lows = [x for x in (boot[0], eff - q * se) if math.isfinite(x)]
    highs = [x for x in (boot[1], eff + q * se) if math.isfinite(x)]
    return Effect(eff, min(lows), max(highs), boot, se, min(a.size, b.size),
                  int(a.size + b.size))


def sd_ratio_interval(a: Sequence[float], b: Sequence[float],
                      cfg: VerdictConfig) -> tuple[float, float, float]:
    """The ratio of sample sds ``sd(a) / sd(b)`` (ddof = 1) and its percentile bootstrap
    interval (each sample resampled on its own; replicates whose ``b`` has no spread are
    dropped); NaNs when either has fewer than two values."""
    a = np.asarray([v for v in a if math.isfinite(v)], dtype=float)
    b = np.asarray([v for v in b if math.isfinite(v)], dtype=float)
    if a.size < 2 or b.size < 2 or b.std() == 0:
        return math.nan, math.nan, math.nan
    rng = np.random.default_rng(cfg.seed)
    ra = a[rng.integers(0, a.size, (cfg.resamples, a.size))].std(axis=1, ddof=1)
    rb = b[rng.integers(0, b.size, (cfg.resamples, b.size))].std(axis=1, ddof=1)
    ok = rb > 0
    ratio = ra[ok] / rb[ok]
    alpha = (1.0 - cfg.level) / 2
    return (float(a.std(ddof=1) / b.std(ddof=1)), float(np.quantile(ratio, alpha)),
            float(np.quantile(ratio, 1 - alpha)))


@dataclass
class Reading:
    """One effect of a finding read against its claim."""

    label: str
    effect: Effect
    claim: Claim

    @property
    def agrees(self) -> bool | None:
        return self.claim.read(self.effect.lo, self.effect.hi)


@dataclass
class Verdict:
    """The verdict of a finding from its readings: differs if any differs, agrees if all
    agree (and ``also``), else cannot tell, naming the first undecided effect."""

    readings: list[Reading] = field(default_factory=list)
    also: bool = True

    @property
    def agrees(self) -> bool | None:
        got = [r.agrees for r in self.readings]
        if not got or False in got:
            return False if got else None
        return None if None in got else self.also

    def undecided(self) -> str:
        r = next((r for r in self.readings if r.agrees is None), None)
        if r is None:
            return "no effect measured"
        e = r.effect
        if not math.isfinite(e.lo):
            return f"cannot tell at this budget ({r.label}: no interval)"
        return (f"cannot tell at this budget ({r.label}: effect {100 * e.effect:+.1f} %, "
                f"interval [{100 * e.lo:+.1f}, {100 * e.hi:+.1f}] %)")

    def text(self) -> str:
        return "; ".join(f"{r.label} {r.effect.text()} %" for r in self.readings)
