"""The verdict rule on synthetic effects: a paired effect of known size and known seed
noise is decided when it is 3x its noise and not when it is 0.5x; the bootstrap is
deterministic under its seed and its intervals cover the true effect."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parknss.experiments.config import VerdictConfig
from parknss.experiments.verdict import (
    Claim,
    FoldNoise,
    Reading,
    Verdict,
    bootstrap_means,
    estimate,
    estimate_unpaired,
    sample_sd,
)

CFG = VerdictConfig(resamples=1000)
FOLDS, SEEDS, SIGMA = 4, 3, 0.10  # one fit's relative seed spread: 10 %


def _noise() -> FoldNoise:
    return FoldNoise({k: SIGMA for k in range(FOLDS)}, {k: SEEDS for k in range(FOLDS)})


def _se() -> float:
    """The noise of the effect: sd of a fold-mean paired effect (two independent fits)."""
    return math.sqrt(2) * SIGMA / math.sqrt(FOLDS * SEEDS)


def _pairs(effect: float, rng) -> dict[int, list[float]]:
    """Option and baseline fits with independent 10 % seed noise, the option ``effect``
    worse; the paired relative effects per fold and seed."""
    out = {}
    for k in range(FOLDS):
        base = 1.0 + k * 0.3  # folds differ in level; the relative effect does not
        b = base * (1 + SIGMA * rng.standard_normal(SEEDS))
        o = base * (1 + effect) * (1 + SIGMA * rng.standard_normal(SEEDS))
        out[k] = list(o / b - 1)
    return out


def _verdicts(multiple: float, claim: Claim, trials: int = 40) -> list[bool | None]:
    rng = np.random.default_rng(7)
    out = []
    for _ in range(trials):
        eff = estimate(_pairs(multiple * _se(), rng), _noise(), CFG, scale=math.sqrt(2))
        out.append(Verdict([Reading("x", eff, claim)]).agrees)
    return out


def test_an_effect_of_three_times_its_noise_is_decided_both_ways():
    worse = _verdicts(3.0, Claim("above"))
    assert sum(v is True for v in worse) >= 0.7 * len(worse)  # power at 3 sd: ~0.85
    assert not any(v is False for v in worse)  # never the wrong sign
    better = _verdicts(3.0, Claim("below"))  # the same effects against the opposite claim
    assert sum(v is False for v in better) >= 0.7 * len(better)
    assert not any(v is True for v in better)


def test_an_effect_of_half_its_noise_cannot_be_told():
    got = _verdicts(0.5, Claim("above"))
    assert sum(v is None for v in got) >= 0.9 * len(got)
    rng = np.random.default_rng(1)
    eff = estimate(_pairs(0.5 * _se(), rng), _noise(), CFG, scale=math.sqrt(2))
    text = Verdict([Reading("x", eff, Claim("above"))]).undecided()
    assert text.startswith("cannot tell at this budget (x: effect ") and "interval [" in text


def test_the_interval_is_never_narrower_than_the_seed_noise():
    # four identical paired effects: the bootstrap has no width, the floor gives it
    eff = estimate({k: [0.05] for k in range(4)}, _noise(), CFG, scale=math.sqrt(2))
    assert eff.boot == (pytest.approx(0.05), pytest.approx(0.05))
    half = 1.959964 * math.sqrt(2) * SIGMA / 2  # se = sqrt(4 x 2 sigma^2) / 4
    assert eff.lo == pytest.approx(0.05 - half, rel=1e-4)
    assert eff.hi == pytest.approx(0.05 + half, rel=1e-4)
    # without a floor the folds' own spread is the interval; one pair has none
    spread = estimate({0: [0.0], 1: [0.1]}, None, CFG)
    assert spread.lo == pytest.approx(0.0) and spread.hi == pytest.approx(0.1)
    assert math.isnan(estimate({0: [0.05]}, None, CFG).lo)
    assert Verdict([Reading("x", estimate({0: [0.05]}, None, CFG), Claim("above"))]) \
        .undecided() == "cannot tell at this budget (x: no interval)"


def test_a_fold_without_enough_seeds_borrows_the_pooled_floor():
    fn = FoldNoise({0: 0.1, 1: math.nan, 2: 0.2, 3: math.nan}, {0: 3, 1: 2, 2: 4, 3: 2},
                   few={1: 0.05, 3: 0.3})
    pooled = math.sqrt((0.01 + 0.04) / 2)
    assert fn.of(0) == 0.1 and fn.of(1) == pytest.approx(pooled)
    assert fn.of(3) == 0.3  # its two seeds spread more than the pool: theirs
    assert "< 3 seeds, the larger of pooled 15.8 %" in fn.describe()
    assert FoldNoise({}, {}, prior=0.02).of(3) == 0.02


def test_claims_read_the_interval():
    above, within = Claim("above", 0.0), Claim("within", 0.03)
    assert above.read(0.01, 0.2) is True and above.read(-0.2, -0.01) is False
    assert above.read(-0.01, 0.2) is None and above.read(math.nan, 1) is None
    assert within.read(-0.02, 0.02) is True and within.read(0.04, 0.1) is False
    assert within.read(-0.02, 0.05) is None
    assert Claim("below", 0.05).read(-0.3, 0.04) is True


def test_a_finding_differs_if_any_reading_differs_and_agrees_only_if_all_agree():
    yes = Reading("a", estimate({0: [0.5], 1: [0.5]}, _noise(), CFG), Claim("above"))
    no = Reading("b", estimate({0: [-0.5], 1: [-0.5]}, _noise(), CFG), Claim("above"))
    maybe = Reading("c", estimate({0: [0.01], 1: [0.01]}, _noise(), CFG), Claim("above"))
    assert Verdict([yes, yes]).agrees is True and Verdict([yes, no, maybe]).agrees is False
    assert Verdict([yes, maybe]).agrees is None and Verdict([yes], also=False).agrees is False


def test_the_bootstrap_is_deterministic_under_its_seed():
    pairs = [[0.1, 0.2, 0.05], [0.3], [0.0, -0.1]]
    a, b = bootstrap_means(pairs, 500, 3), bootstrap_means(pairs, 500, 3)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, bootstrap_means(pairs, 500, 4))
    # every replicate is a mean of fold means drawn from the data
    assert a.min() >= -0.1 - 1e-12 and a.max() <= 0.3 + 1e-12


def test_the_bootstrap_draws_folds_then_seeds():
    # fold 0 always 1, fold 1 always 0: the replicate mean is the share of fold-0 draws
    means = bootstrap_means([[1.0, 1.0], [0.0]], 4000, 0)
    assert set(np.round(means, 12)) <= {0.0, 0.5, 1.0}
    assert np.mean(means == 0.5) == pytest.approx(0.5, abs=0.03)


def test_the_interval_covers_the_true_effect_in_a_simulated_check():
    rng = np.random.default_rng(11)
    true = 0.08
    cfg = VerdictConfig(resamples=400)
    boot_hits = hits = 0
    n = 200
    for _ in range(n):
        # 8 folds x 3 seeds: the true effect varies by fold (sd 3 %) around its mean
        pairs = {k: list(true + 0.03 * rng.standard_normal() + 0.05 * rng.standard_normal(3))
                 for k in range(8)}
        e = estimate(pairs, None, cfg)
        boot_hits += e.lo <= true <= e.hi
        e = estimate(pairs, FoldNoise({k: 0.05 for k in range(8)}, {k: 3 for k in range(8)}),
                     cfg)
        hits += e.lo <= true <= e.hi
    assert boot_hits / n >= 0.85  # the percentile bootstrap, a little below 95 % at 8 folds
    assert hits / n >= 0.90 and hits >= boot_hits  # the floor only widens it


def test_unpaired_effects_and_the_sample_sd():
    cfg = VerdictConfig(resamples=500)
    e = estimate_unpaired([0.2, 0.22, 0.18, 0.2], [0.1, 0.11, 0.09, 0.1], 0.02, cfg)
    assert e.effect == pytest.approx(-0.5) and e.hi < 0
    assert estimate_unpaired([], [0.1], 0.02, cfg).n_pairs == 0
    assert sample_sd([1.0, 2.0, 3.0]) == pytest.approx(1.0) and math.isnan(sample_sd([1.0]))
