"""End-aligned training windows (paper §IV-B) and padded whole-trial batches.

Tiling rule. The window length L is the shortest training trial (or a given N). A trial
of n >= L samples is tiled from its end backwards in steps of L: windows
[n-L, n), [n-2L, n-L), ... while they fit, and the remainder at the start is covered by
one more window aligned to the trial start, [0, L), which overlaps its neighbour. A trial
thus gives ceil(n / L) windows, every sample is in at least one, every window holds
exactly L real samples, and the end of every trial (the final standstill) is a window
end. A trial shorter than L (only when L is given explicitly) gives one window [0, n)
padded to L by holding its last sample, with ``valid`` False on the padding.

This is the rule consistent with the paper's counts: 12 training trials of 21-64 s give
sum ceil(n_i / 2121) = 29 sequences at L = 2121 (§IV-B), and at L = 6390 (the longest
trial) every trial becomes one padded sequence, 12 in all (§V-C). Windows start
mid-trial; each is rolled out from its own measured initial state.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from parknss.data.trial import Trial
from parknss.errors import DataError
from parknss.signals import ACTUAL_CHANNELS, OUTPUT_CHANNELS, STATE_CHANNELS


def window_length(lengths: Sequence[int], rule: str | int = "shortest") -> int:
    """L from the training-trial lengths: the shortest one, or the integer given."""
    if not lengths:
        raise DataError("no training trials to take a window length from")
    if rule == "shortest":
        return int(min(lengths))
    if isinstance(rule, int) and rule >= 2:
        return rule
    raise DataError(f"window rule must be 'shortest' or an integer >= 2, got {rule!r}")


def tile(n: int, L: int) -> list[tuple[int, int]]:
    """(start, stop) of the windows of a trial of n samples, ascending by start.

    Stops are end-aligned at n, n-L, n-2L, ...; the last partial window is [0, L).
    """
    if n < 1 or L < 1:
        raise DataError(f"cannot tile {n} samples into windows of {L}")
    if n <= L:
        return [(0, n)]
    count = math.ceil(n / L)
    spans = [(n - (j + 1) * L, n - j * L) for j in range(count - 1)]
    spans.append((0, L))
    return sorted(spans)


@dataclass
class Windows:
    """A batch of equal-length sequences in physical units.

    inputs (N, L, 4) [gear, torque, brake_pressure, steer]; states (N, L, 2) [vx, yaw_rate];
    outputs (N, L, 2) [ax, ay]; valid (N, L) bool (False on padding); trial_ids and starts
    (N,) say where each sequence comes from; lengths (N,) real samples per sequence.
    """

    inputs: np.ndarray
    states: np.ndarray
    outputs: np.ndarray
    valid: np.ndarray
    trial_ids: list[str]
    starts: list[int]
    lengths: list[int]

    @property
    def n(self) -> int:
        return self.inputs.shape[0]

    @property
    def length(self) -> int:
        return self.inputs.shape[1]


def _padded(x: np.ndarray, L: int) -> np.ndarray:
    if len(x) >= L:
        return x[:L]
    return np.concatenate([x, np.repeat(x[-1:], L - len(x), axis=0)], axis=0)


def _stack(pieces: list[tuple[Trial, int, int]], L: int) -> Windows:
    ins, sts, outs, val, ids, starts, lens = [], [], [], [], [], [], []
    for tr, a, b in pieces:
        ins.append(_padded(tr.array(ACTUAL_CHANNELS)[a:b], L))
        sts.append(_padded(tr.array(STATE_CHANNELS)[a:b], L))
        outs.append(_padded(tr.array(OUTPUT_CHANNELS)[a:b], L))
        v = np.zeros(L, dtype=bool)
        v[: b - a] = True
        val.append(v)
        ids.append(tr.id)
        starts.append(a)
        lens.append(b - a)
    return Windows(np.stack(ins), np.stack(sts), np.stack(outs), np.stack(val), ids, starts, lens)


def make_windows(trials: Sequence[Trial], L: int) -> Windows:
    """All windows of all trials (tiling rule in the module docstring), trial order kept."""
    if not trials:
        raise DataError("no trials to window")
    return _stack([(tr, a, b) for tr in trials for a, b in tile(tr.n, L)], L)


def whole_trials(trials: Sequence[Trial]) -> Windows:
    """Every trial whole, padded to the longest (for open-loop validation and evaluation)."""
    if not trials:
        raise DataError("no trials to batch")
    L = max(tr.n for tr in trials)
    return _stack([(tr, 0, tr.n) for tr in trials], L)
