"""The magnitude rating's DTW in C against the NumPy sweep: the same sums, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.cbuild import no_c_compiler
from parknss.errors import ParknssError
from parknss.metrics import dtw_native
from parknss.metrics.iso18571 import ISORatingConfig, dtw_path_sums, rate, warping_sums


def _cases():
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 5, 17, 64, 300):
        for band in sorted({0, 1, n // 10, n // 3, n - 1}):
            if band >= n:
                continue
            yield n, band, rng.normal(size=n), rng.normal(size=n)  # no ties
            # integers from {0, 1, 2}: equal costs everywhere, every tie rule exercised
            yield n, band, rng.integers(0, 3, n) * 1.0, rng.integers(0, 3, n) * 1.0
            x = np.sin(np.arange(n) / 7.0)
            yield n, band, x, np.roll(x, 3)
            yield n, band, np.zeros(n), np.zeros(n)


@pytest.mark.parametrize(("n", "band", "x", "y"), list(_cases()))
def test_native_sums_are_the_sweeps_bit_for_bit(n, band, x, y):
    assert dtw_native.path_sums(x, y, band) == dtw_path_sums(x, y, band)


def test_ratings_equal_with_either_engine_and_batched():
    t = np.linspace(0.0, 8.0, 800)
    pairs = [(np.sin(t), np.sin(t - 0.3) * 1.1), (np.tanh(t - 2), np.tanh(t - 2.2) + 0.05),
             (np.cos(2 * t), np.cos(2 * t) + 0.2 * np.sin(7 * t))]
    cfgs = {e: ISORatingConfig(dtw_engine=e) for e in ("numpy", "native", "auto")}
    for m, p in pairs:
        r = {e: rate(m, p, 0.01, c) for e, c in cfgs.items()}
        assert r["numpy"] == r["native"] == r["auto"]
    xs, ys, bands = [p for _, p in pairs], [m for m, _ in pairs], [79, 10, 0]
    a, b = warping_sums(xs, ys, bands, "numpy"), warping_sums(xs, ys, bands, "native")
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_bad_input_is_refused_like_the_sweep():
    with pytest.raises(ValueError, match="equal lengths and 0 <= band < L"):
        dtw_native.path_sums(np.zeros(5), np.zeros(4), 1)
    with pytest.raises(ValueError, match="equal lengths and 0 <= band < L"):
        dtw_native.path_sums(np.zeros(5), np.zeros(5), 5)


def test_without_a_compiler_auto_is_the_sweep_and_native_one_line(monkeypatch, tmp_path):
    with no_c_compiler(monkeypatch, tmp_path, dtw_native.library, dtw_native.available):
        t = np.linspace(0.0, 4.0, 400)
        m, p = np.sin(t), np.sin(t - 0.2)
        assert not dtw_native.available()
        want = rate(m, p, 0.01, ISORatingConfig(dtw_engine="numpy"))
        assert rate(m, p, 0.01, ISORatingConfig(dtw_engine="auto")) == want
        with pytest.raises(ParknssError, match=r"no C compiler.*dtw_engine numpy") as e:
            rate(m, p, 0.01, ISORatingConfig(dtw_engine="native"))
        assert "\n" not in str(e.value)
