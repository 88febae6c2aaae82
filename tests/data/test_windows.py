"""End-aligned training windows (paper §IV-B): the tiling rule, the paper's counts, padding."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers.synth import make_trial
from parknss.data.windows import make_windows, tile, whole_trials, window_length
from parknss.errors import DataError
from parknss.signals import ACTUAL_CHANNELS, OUTPUT_CHANNELS, STATE_CHANNELS


@pytest.mark.parametrize("L", [2, 3, 7, 50])
def test_tiling_rule_properties(L):
    for n in range(L, 6 * L + 3):
        spans = tile(n, L)
        assert len(spans) == math.ceil(n / L)
        assert spans == sorted(spans)
        assert all(b - a == L for a, b in spans)  # every window holds L real samples
        assert spans[0][0] == 0 and spans[-1][1] == n  # starts at 0, ends at the trial end
        covered = np.zeros(n, dtype=int)
        for a, b in spans:
            covered[a:b] += 1
        assert covered.min() >= 1  # every sample covered
        # end-aligned: stops at n, n-L, n-2L, ...; only the first window overlaps
        stops = sorted((b for _, b in spans), reverse=True)
        assert stops[: len(spans) - 1] == [n - j * L for j in range(len(spans) - 1)]
        assert covered.max() <= 2 and (covered == 2).sum() == (-n) % L


def test_short_trial_is_one_window():
    assert tile(5, 9) == [(0, 5)] and tile(9, 9) == [(0, 9)]
    with pytest.raises(DataError):
        tile(0, 5)


# 12 training trials of 21.21-63.9 s at 100 Hz; sum ceil(n/2121) = 29 as in the paper
PAPER_LIKE = [2121, 2500, 2600, 3000, 3200, 3500, 4000, 4300, 4500, 5000, 5500, 6390]


def test_paper_counts():
    assert window_length(PAPER_LIKE) == 2121
    assert sum(math.ceil(n / 2121) for n in PAPER_LIKE) == 29
    trials = [make_trial(n, seed=i, repetition=i + 1) for i, n in enumerate(PAPER_LIKE)]
    w = make_windows(trials, 2121)
    assert w.n == 29 and w.length == 2121 and w.valid.all()
    # the longest trial as window: every trial one (padded) sequence, 12 in all
    w2 = make_windows(trials, window_length(PAPER_LIKE, 6390))
    assert w2.n == 12 and w2.lengths == PAPER_LIKE
    assert w2.valid.sum(axis=1).tolist() == PAPER_LIKE


def test_window_contents_are_the_trial_slices():
    trials = [make_trial(230, seed=1, repetition=1), make_trial(95, seed=2, repetition=2)]
    w = make_windows(trials, 100)
    assert w.trial_ids == [trials[0].id] * 3 + [trials[1].id]
    assert w.starts == [0, 30, 130, 0] and w.lengths == [100, 100, 100, 95]
    for i, (tid, a) in enumerate(zip(w.trial_ids, w.starts, strict=True)):
        tr = trials[0] if i < 3 else trials[1]
        assert tid == tr.id
        n = w.lengths[i]
        assert np.array_equal(w.inputs[i, :n], tr.array(ACTUAL_CHANNELS)[a : a + n])
        assert np.array_equal(w.states[i, :n], tr.array(STATE_CHANNELS)[a : a + n])
        assert np.array_equal(w.outputs[i, :n], tr.array(OUTPUT_CHANNELS)[a : a + n])
    # the short trial is padded by holding its last sample, valid False there
    assert w.valid[3, :95].all() and not w.valid[3, 95:].any()
    assert np.array_equal(w.inputs[3, 95:], np.repeat(w.inputs[3, 94:95], 5, axis=0))
    assert np.array_equal(w.states[3, 95:], np.repeat(w.states[3, 94:95], 5, axis=0))


def test_whole_trials_padded_to_the_longest():
    trials = [make_trial(n, seed=n, repetition=i + 1) for i, n in enumerate((120, 180, 150))]
    w = whole_trials(trials)
    assert w.length == 180 and w.starts == [0, 0, 0] and w.lengths == [120, 180, 150]
    assert w.valid.sum(axis=1).tolist() == [120, 180, 150]
    assert np.array_equal(w.states[0, :120], trials[0].array(STATE_CHANNELS))
    with pytest.raises(DataError):
        whole_trials([])


def test_window_length_rule_errors():
    assert window_length([300, 200, 250]) == 200 and window_length([300], 64) == 64
    with pytest.raises(DataError):
        window_length([])
    with pytest.raises(DataError):
        window_length([100], 1)
    with pytest.raises(DataError):
        make_windows([], 10)
