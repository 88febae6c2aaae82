"""A trial on the grid of every m-th sample (the coarse-to-fine recipe's phase 1)."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.synth import make_trial
from parknss.data.decimate import block_means, decimate, grid, grid_length
from parknss.errors import DataError

HELD = ("torque", "brake_pressure", "steer")


@pytest.mark.parametrize(("n", "m"), [(1, 4), (7, 1), (8, 8), (9, 8), (300, 7), (301, 16)])
def test_grid_ends_at_the_last_sample_every_m_apart(n, m):
    idx = grid(n, m)
    assert len(idx) == grid_length(n, m) == (n - 1) // m + 1
    assert idx[-1] == n - 1 and 0 <= idx[0] < m
    assert np.all(np.diff(idx) == m)


def test_block_means_are_the_means_over_each_step():
    x = np.random.default_rng(0).normal(size=103)
    m = 8
    want = [x[i : min(i + m, len(x))].mean() for i in grid(len(x), m)]
    np.testing.assert_allclose(block_means(x, m), want, rtol=1e-14, atol=1e-15)
    ramp = 2.0 * np.arange(41, dtype=float)  # 0, 2, .., 80: a step's mean is its midpoint
    idx = grid(41, 5)
    np.testing.assert_allclose(block_means(ramp, 5)[:-1], 2.0 * (idx[:-1] + 2.0))
    assert block_means(ramp, 5)[-1] == 80.0  # the last sample's own (no later state)


def test_decimate_samples_states_and_the_gear_and_averages_the_held_inputs():
    tr = make_trial(301, seed=2)
    d = decimate(tr, 6, HELD)
    idx = grid(tr.n, 6)
    assert d.n == len(idx) and d.sample_rate_hz == pytest.approx(100.0 / 6)
    assert (d.id, d.maneuver, d.repetition) == (tr.id, tr.maneuver, tr.repetition)
    for name in tr.channels:
        if name in HELD:
            np.testing.assert_allclose(d[name], block_means(tr[name], 6), rtol=1e-14)
        else:
            np.testing.assert_array_equal(d[name], tr[name][idx])
    assert set(np.unique(d["gear"])) <= set(np.unique(tr["gear"]))  # never averaged
    assert d["vx"][-1] == tr["vx"][-1]  # the final standstill stays
    assert decimate(tr, 1, HELD) is tr


def test_refusals():
    with pytest.raises(DataError, match="cannot decimate"):
        grid(0, 4)
    with pytest.raises(DataError, match="cannot decimate"):
        grid_length(10, 0)
