"""ISO/TS 18571 rating: agreement with objective-rating-metrics, exact properties,
degenerate rules, the §V-F low-pass, speed and memory.

The independent implementation (objective-rating-metrics, TU Graz) runs its dtwalign
kernels interpreted (``py_func``) here: identical arithmetic, without the ~14 s numba
compilation; benchmarks/bench_iso.py times it compiled.
"""

from __future__ import annotations

import importlib
import math
import sys
import time
import tracemalloc

import numpy as np
import pytest
from pydantic import ValidationError

from parknss.errors import ConfigError, DataError
from parknss.metrics.iso18571 import (
    ISORatingConfig,
    Rating,
    dtw_path_sums,
    dtw_path_sums_many,
    grade_of,
    lowpass,
    min_samples,
    phase_shift,
    rate,
    rate_many,
)

DT = 0.01
N = 300
FIELDS = ("corridor", "phase", "magnitude", "slope", "overall")


@pytest.fixture(scope="module")
def reference():
    """The reference ISO18571 class with its numba kernels replaced by their Python."""
    pytest.importorskip("objective_rating_metrics")
    dtw_mod = importlib.import_module("dtwalign.dtw")
    bt_mod = sys.modules["dtwalign.backtrack"]
    saved = (dtw_mod._calc_cumsum_matrix_jit, dtw_mod._backtrack_jit, bt_mod._get_local_path)
    dtw_mod._calc_cumsum_matrix_jit = saved[0].py_func
    dtw_mod._backtrack_jit = saved[1].py_func
    bt_mod._get_local_path = saved[2].py_func
    from objective_rating_metrics.rating import ISO18571

    yield ISO18571
    dtw_mod._calc_cumsum_matrix_jit, dtw_mod._backtrack_jit, bt_mod._get_local_path = saved


def reference_rating(cls, measured, predicted) -> dict:
    """All sub-ratings (unrounded) and |shift| from the reference; DTW run once."""
    t = np.arange(measured.size) * DT
    r = cls(np.column_stack([t, measured]), np.column_stack([t, predicted]), dt=DT)
    out = {
        "corridor": r.corridor_rating(-1),
        "phase": r.phase_rating(-1),
        "magnitude": r.magnitude_rating(-1),
        "slope": r.slope_rating(-1),
    }
    r.magnitude_rating = lambda ndigits=3: out["magnitude"]  # reuse it in overall_rating
    out["overall"] = r.overall_rating(-1)
    out["shift"] = int(r._n_eps)
    return out


def _t(n: int = N) -> np.ndarray:
    return np.arange(n) * DT


def _mix(t: np.ndarray) -> np.ndarray:
    return np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 2.1 * t + 0.4)


def _delayed(f, lag: int, n: int = N) -> tuple[np.ndarray, np.ndarray]:
    """(f on n samples, the same samples delayed by lag > 0 or advanced by lag < 0)."""
    full = f(np.arange(n + abs(lag)) * DT)
    if lag >= 0:
        return full[lag:], full[:n]
    return full[:n], full[-lag:]


def _first_order(t, t0, tau, gain=1.0):
    return gain * np.where(t > t0, 1.0 - np.exp(-np.clip(t - t0, 0, None) / tau), 0.0)


def _cases() -> dict[str, tuple[np.ndarray, np.ndarray, int | None]]:
    """name -> (measured, predicted, expected signed shift or None)."""
    rng = np.random.default_rng(7)
    t = _t()
    cases: dict[str, tuple[np.ndarray, np.ndarray, int | None]] = {}
    m, p = _delayed(_mix, 12)
    cases["lagged_12"] = (m, p, 12)
    m, p = _delayed(_mix, -9)
    cases["leading_9"] = (m, p, -9)
    m = _mix(t)
    cases["scaled_1.25"] = (m, 1.25 * m, 0)
    cases["offset_0.15"] = (m, m + 0.15, 0)
    cases["noisy_seeded"] = (m, m + 0.1 * rng.standard_normal(N), None)
    cases["step_responses"] = (
        _first_order(t, 0.5, 0.3),
        _first_order(t, 0.7, 0.5, gain=1.1),
        None,
    )
    cases["pulses"] = (
        np.exp(-(((t - 1.2) / 0.15) ** 2)),
        0.8 * np.exp(-(((t - 1.35) / 0.22) ** 2)),
        None,
    )
    ramp = np.clip((t - 0.5) / 1.5, 0, None)
    cases["ramp_saturating"] = (ramp, np.minimum(1.1 * ramp, 0.9), None)
    cases["damped_oscillation"] = (
        np.exp(-0.6 * t) * np.sin(2 * np.pi * 1.3 * t),
        np.exp(-0.9 * t) * np.sin(2 * np.pi * 1.2 * t + 0.2),
        None,
    )
    chirp = lambda s: np.sin(2 * np.pi * (0.3 + 0.8 * s) * s)  # noqa: E731
    m, p = _delayed(chirp, 7)
    cases["chirp_lag_scaled"] = (m, 0.9 * p + 0.02 * rng.standard_normal(N), None)
    tri = 1.0 - 2.0 * np.abs((t * 0.8) % 1.0 - 0.5)
    cases["triangle_vs_smooth"] = (tri, lowpass(tri, DT, 2.0), None)
    cases["half_sine_vs_rect"] = (
        np.where((t > 1.0) & (t < 1.6), np.sin(np.pi * (t - 1.0) / 0.6), 0.0) + 0.01 * t,
        np.where((t > 1.05) & (t < 1.55), 0.8, 0.0) + 0.01 * t,
        None,
    )
    cases["inverted"] = (m, -0.7 * m + 0.05 * rng.standard_normal(N), None)
    m, p = _delayed(_mix, 60)  # the largest shift searched (0.2 N): EP = 0
    cases["lag_at_limit"] = (m, p, 60)
    cases["unrelated_noise"] = (rng.standard_normal(N), rng.standard_normal(N), None)
    v = np.clip(np.sin(np.pi * t / 3.0), 0, None) * 0.8  # a speed-like profile
    cases["speed_noise_vs_model"] = (
        v + 0.02 * rng.standard_normal(N),
        np.concatenate([np.zeros(4), v[:-4]]) * 1.05,
        None,
    )
    return cases


CASES = _cases()


@pytest.mark.parametrize("name", sorted(CASES))
def test_agrees_with_objective_rating_metrics(reference, name):
    measured, predicted, expected_shift = CASES[name]
    ours = rate(measured, predicted, DT)
    ref = reference_rating(reference, measured, predicted)
    assert abs(ours.shift_samples) == ref["shift"]
    if expected_shift is not None:
        assert ours.shift_samples == expected_shift
    for f in FIELDS:
        assert abs(getattr(ours, f) - ref[f]) <= 1e-6, (f, getattr(ours, f), ref[f])


def test_tie_sensitive_periodic_case_is_resolved_to_the_smallest_shift(reference):
    """Excluded from the agreement table, with the reason.

    An exactly periodic signal (40 samples per period, built from one period's samples)
    delayed by 10 samples correlates perfectly (rho = 1 analytically) at shifts +10,
    -30 and +50: the truncated windows are identical copies at each. Which of them the
    reference keeps depends on last-bit rounding of np.corrcoef; the standard's rule
    (minimum shift on ambiguity) gives +10, which we return by treating correlations
    within 1e-12 of the best as ties.
    """
    period = np.sin(2 * np.pi * np.arange(40) / 40) + 0.3 * np.cos(6 * np.pi * np.arange(40) / 40)
    base = np.tile(period, 10)
    measured, predicted = base[10 : 10 + N], base[:N]
    ours = rate(measured, predicted, DT)
    assert ours.shift_samples == 10
    ref = reference_rating(reference, measured, predicted)
    assert ref["shift"] in (10, 30, 50)


@pytest.mark.parametrize("name", ["noisy_seeded", "step_responses", "pulses", "chirp_lag_scaled"])
def test_identical_signals_rate_one(name):
    measured = CASES[name][0]
    r = rate(measured, measured.copy(), DT)
    assert (r.corridor, r.phase, r.magnitude, r.slope, r.overall) == (1.0, 1.0, 1.0, 1.0, 1.0)
    assert r.grade == "Excellent" and r.shift_samples == 0


def _brute_dtw(x, y, band):
    """Full-matrix DTW with the standard's back-tracking (test oracle, small sizes)."""
    n = x.size
    D = np.full((n, n), np.inf)
    for i in range(n):
        for j in range(max(0, i - band), min(n, i + band + 1)):
            c = (x[i] - y[j]) ** 2
            if i == j == 0:
                D[i, j] = c
                continue
            prev = min(
                D[i - 1, j] if i else np.inf,
                D[i, j - 1] if j else np.inf,
                D[i - 1, j - 1] if i and j else np.inf,
            )
            D[i, j] = prev + c
    i = j = n - 1
    num, den = abs(x[i] - y[j]), abs(y[j])
    while i or j:
        cand = [
            D[i - 1, j] if i else np.inf,
            D[i, j - 1] if j else np.inf,
            D[i - 1, j - 1] if i and j else np.inf,
        ]
        k = int(np.argmin(cand))
        i, j = (i - 1, j) if k == 0 else (i, j - 1) if k == 1 else (i - 1, j - 1)
        num += abs(x[i] - y[j])
        den += abs(y[j])
    return num, den


@pytest.mark.parametrize(("n", "band"), [(9, 0), (12, 1), (25, 2), (40, 3), (41, 6), (60, 59)])
def test_banded_dtw_matches_full_matrix_oracle(n, band):
    rng = np.random.default_rng(n)
    x, y = rng.standard_normal(n), rng.standard_normal(n)
    assert dtw_path_sums(x, y, band) == pytest.approx(_brute_dtw(x, y, band), rel=1e-12)
    # plateaus make many exactly equal costs: the tie rule decides the path length
    x = np.r_[np.zeros(n // 3), np.ones(n // 3), np.zeros(n - 2 * (n // 3))]
    y = np.roll(x, 1)
    assert dtw_path_sums(x, y, band) == pytest.approx(_brute_dtw(x, y, band), rel=1e-12)


def test_batched_dtw_is_bit_identical_to_one_pair_at_a_time():
    # different lengths and bands side by side, plateaus (exact ties) among them
    rng = np.random.default_rng(11)
    plateau = np.r_[np.zeros(20), np.ones(25), np.zeros(22)]
    xs = [rng.standard_normal(50), plateau, rng.standard_normal(9), rng.standard_normal(80)]
    ys = [rng.standard_normal(50), np.roll(plateau, 2), rng.standard_normal(9),
          np.roll(xs[3], 3) + 0.1 * rng.standard_normal(80)]
    bands = [4, 7, 0, 11]
    nums, dens = dtw_path_sums_many(xs, ys, bands, block=5)
    for k, (x, y, band) in enumerate(zip(xs, ys, bands, strict=True)):
        assert (nums[k], dens[k]) == dtw_path_sums(x, y, band)
        assert (nums[k], dens[k]) == pytest.approx(_brute_dtw(x, y, band), rel=1e-12)


def test_rate_many_equals_rate_pair_by_pair():
    rng = np.random.default_rng(12)
    pairs = []
    for n, lag in ((400, 7), (250, -5), (300, 0)):
        t = _t(n)
        m = np.sin(2 * np.pi * 0.4 * t) + 0.05 * rng.standard_normal(n)
        pairs.append((m, 0.9 * np.roll(m, lag)))
    pairs.append((np.zeros(200), np.zeros(200)))
    assert rate_many(pairs, DT) == [rate(m, p, DT) for m, p in pairs]
    assert rate_many([], DT) == []
    with pytest.raises(DataError, match="second"):
        rate_many([pairs[0], (np.ones(5), np.ones(5))], DT, labels=["first", "second"])


def test_shift_sign_and_pearson_search_match_a_direct_loop():
    rng = np.random.default_rng(3)
    m = np.cumsum(rng.standard_normal(200))
    for lag in (-17, -1, 0, 5, 33):
        p = np.roll(m, lag) + 0.3 * rng.standard_normal(200)
        best, best_shift = -np.inf, 0
        for k in range(0, 41):
            for sign in (1, -1) if k else (1,):
                s = sign * k
                a, b = (m[: 200 - k], p[k:]) if s >= 0 else (m[k:], p[: 200 - k])
                rho = np.corrcoef(a, b)[0, 1]
                if rho > best + 1e-12:
                    best, best_shift = rho, s
        assert phase_shift(m, p) == best_shift


# --- degenerate input -------------------------------------------------------------


def test_all_zero_measured_and_prediction_rate_one():
    z = np.zeros(50)
    r = rate(z, z, DT)
    assert (r.corridor, r.phase, r.magnitude, r.slope, r.overall) == (1.0, 1.0, 1.0, 1.0, 1.0)


def test_all_zero_measured_against_nonzero_prediction():
    t = _t(100)
    p = np.where(t > 0.5, 0.2, 0.0)  # differs from zero on 49 of 100 samples
    r = rate(np.zeros(100), p, DT)
    assert r.corridor == pytest.approx(0.51)  # only exact matches score in zero corridors
    assert (r.phase, r.magnitude, r.slope, r.shift_samples) == (1.0, 0.0, 0.0, 0)
    assert r.overall == pytest.approx(0.4 * 0.51 + 0.2)
    assert all(math.isfinite(getattr(r, f)) for f in FIELDS)


def test_constant_measured_signal():
    t = _t(100)
    flat = np.full(100, 2.0)
    r = rate(flat, flat + 0.05 * np.sin(2 * np.pi * t), DT)
    assert r.corridor == 1.0  # |C - T| <= 0.05 * 2.0 everywhere
    assert r.phase == 1.0 and r.shift_samples == 0  # no correlation measurable
    assert r.magnitude == pytest.approx(1.0 - (0.05 * 2 / np.pi) / 2.0 / 0.5, abs=0.02)
    assert r.slope == 0.0  # the measurement has no slope, the prediction does
    same = rate(flat, flat.copy(), DT)
    assert same.overall == 1.0


def test_identically_zero_prediction():
    m = _mix(_t(200))
    r = rate(m, np.zeros(200), DT)
    assert r.shift_samples == 0 and r.phase == 1.0
    assert r.magnitude == 0.0  # relative error 1 > 0.5
    assert r.slope == pytest.approx(0.5)  # relative slope error exactly 1
    t_norm = np.max(np.abs(m))
    dev = np.abs(m)
    expect = np.where(
        dev <= 0.05 * t_norm,
        1.0,
        np.where(dev <= 0.5 * t_norm, ((0.5 * t_norm - dev) / (0.45 * t_norm)) ** 2, 0.0),
    ).mean()
    assert r.corridor == pytest.approx(expect, rel=1e-12)
    assert r.grade == "Poor"


def test_length_mismatch_is_an_error():
    with pytest.raises(DataError, match="100 samples, predicted 99"):
        rate(np.zeros(100), np.zeros(99), DT, label="trial x channel vx")


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_is_an_error(bad):
    m = np.ones(50)
    p = np.ones(50)
    p[17] = bad
    with pytest.raises(
        DataError, match=r"vx: predicted has 1 non-finite samples \(first at index 17\)"
    ):
        rate(m, p, DT, label="vx")


def test_too_short_after_shift_is_an_error():
    assert min_samples() == 11  # 11 - floor(2.2) = 9 samples after the largest shift
    rate(np.arange(11.0), np.arange(11.0) * 1.1, DT)
    with pytest.raises(DataError, match="at least 11"):
        rate(np.arange(10.0), np.arange(10.0), DT)


def test_bad_dt_and_shape_are_errors():
    with pytest.raises(DataError, match="dt"):
        rate(np.zeros(20), np.zeros(20), 0.0)
    with pytest.raises(DataError, match="1-D"):
        rate(np.zeros((20, 2)), np.zeros((20, 2)), DT)


def test_config_validation_and_grades():
    with pytest.raises(ValidationError):
        ISORatingConfig(weight_corridor=0.5)
    with pytest.raises(ValidationError):
        ISORatingConfig(a0=0.6)
    with pytest.raises(ValidationError):
        ISORatingConfig(slope_window=8)
    assert [grade_of(x) for x in (0.9401, 0.94, 0.8001, 0.80, 0.5801, 0.58, 0.0)] == [
        "Excellent",
        "Good",
        "Good",
        "Fair",
        "Fair",
        "Poor",
        "Poor",
    ]


def test_rating_fields():
    r = rate(*CASES["lagged_12"][:2], DT)
    assert isinstance(r, Rating)
    assert set(r.as_dict()) == {*FIELDS, "grade", "shift_samples"}
    assert r.overall == pytest.approx(
        0.4 * r.corridor + 0.2 * r.phase + 0.2 * r.magnitude + 0.2 * r.slope
    )


# --- the §V-F conditioning ----------------------------------------------------------


def test_lowpass_is_zero_phase_with_butterworth_gain():
    t = _t(2000)
    slow = np.sin(2 * np.pi * 1.0 * t)
    fast = np.sin(2 * np.pi * 20.0 * t)
    out_slow, out_fast = lowpass(slow, DT), lowpass(fast, DT)
    mid = slice(500, 1500)
    # forward-backward: |H|² of the order-4 Butterworth, no phase shift
    gain = lambda f: 1.0 / (1.0 + (f / 5.0) ** 8)  # noqa: E731
    assert np.max(np.abs(out_slow[mid] - gain(1.0) * slow[mid])) < 1e-3
    assert np.max(np.abs(out_fast[mid])) < 2 * gain(20.0)
    pulse = np.exp(-(((t - 10.0) / 0.4) ** 2))  # zero phase: the peak does not move
    out = lowpass(pulse, DT)
    assert np.argmax(out) == np.argmax(pulse) == 1000
    assert np.allclose(out[1000 - 300 : 1000], out[1000 + 300 : 1000 : -1], atol=1e-9)
    assert phase_shift(pulse, out) == 0


def test_lowpass_conditioning_raises_the_slope_rating_of_noisy_pairs():
    rng = np.random.default_rng(11)
    t = _t(1000)
    truth = np.sin(2 * np.pi * 0.4 * t)
    measured = truth + 0.1 * rng.standard_normal(t.size)
    raw = rate(measured, truth, DT)
    filt = rate(lowpass(measured, DT), lowpass(truth, DT), DT)
    assert filt.slope > raw.slope + 0.1
    assert filt.overall > raw.overall + 0.05


def test_lowpass_bad_input():
    with pytest.raises(ConfigError, match="cutoff"):
        lowpass(np.zeros(100), DT, cutoff_hz=60.0)
    with pytest.raises(DataError, match="needs > 15"):
        lowpass(np.zeros(15), DT)
    with pytest.raises(DataError, match="non-finite"):
        lowpass(np.r_[np.zeros(30), np.nan], DT)


# --- speed and memory ---------------------------------------------------------------


def test_6000_samples_rate_in_under_a_second_with_linear_memory():
    rng = np.random.default_rng(5)
    t = _t(6000)
    m = np.sin(2 * np.pi * 0.2 * t) + 0.05 * rng.standard_normal(t.size)
    p = 1.1 * np.roll(m, 25)
    t0 = time.perf_counter()
    r = rate(m, p, DT)
    elapsed = time.perf_counter() - t0
    assert r.shift_samples == 25
    assert elapsed < 1.0
    tracemalloc.start()
    dtw_path_sums(p[:4000], m[:4000], 399)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 4e6  # a full 4000² float matrix is 128 MB, the band alone 26 MB
