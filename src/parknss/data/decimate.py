"""A trial on a coarser grid: every m-th sample, the inputs averaged over each step.

The coarse-to-fine training recipe (:mod:`parknss.nss.recipes`, ``train.recipe: coarse``)
first fits the model with an Euler step of m·Δt. For such a step from sample i to i + m
the state x(i) is the measured one at i, and the input held over the step is the mean of
the m inputs it replaces (what a step of m·Δt integrates: Σ_{j<m} Δt·f(x, u(i+j)) ≈
m·Δt·f(x, mean u) to first order). So a decimated trial keeps, on the grid

    i_k = i_0 + k·m,  k = 0 .. K-1,  i_0 = (n - 1) mod m,  K = (n - 1) // m + 1,

every channel's sample at i_k, except the ``mean`` channels (the continuous inputs), which
hold the mean over [i_k, min(i_k + m, n)): the last grid point is the trial's last sample
(the final standstill stays a window end, as in :mod:`parknss.data.windows`), and its
input, which no later state sees, is that sample's own. Discrete channels (the gear) are
sampled, never averaged. ``sample_rate_hz`` becomes the trial's rate / m. m = 1 returns
the trial itself.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from parknss.data.trial import Trial
from parknss.errors import DataError


def grid_length(n: int, m: int) -> int:
    """K: how many samples of an n-sample trial the grid of every m-th one keeps."""
    if n < 1 or m < 1:
        raise DataError(f"cannot decimate {n} samples by {m}")
    return (n - 1) // m + 1


def grid(n: int, m: int) -> np.ndarray:
    """The kept sample indices i_k (module doc) of an n-sample trial, ascending, (K,)."""
    grid_length(n, m)  # the checks
    return np.arange((n - 1) % m, n, m)


def block_means(x: np.ndarray, m: int) -> np.ndarray:
    """Mean of ``x`` (n,) over [i_k, min(i_k + m, n)) for every grid index i_k, (K,)."""
    n = len(x)
    idx = grid(n, m)
    sums = np.add.reduceat(np.asarray(x, dtype=np.float64), idx)  # [i_k, i_k+1), the last to n
    return sums / (np.minimum(idx + m, n) - idx)


def decimate(trial: Trial, m: int, mean: Sequence[str]) -> Trial:
    """``trial`` on the grid of every m-th sample (module doc); ``mean`` names the
    channels averaged over each step (the continuous inputs), all others are sampled."""
    if m == 1:
        return trial
    idx = grid(trial.n, m)
    ch = {
        k: block_means(np.asarray(v, dtype=np.float64), m) if k in mean else v[idx].copy()
        for k, v in trial.channels.items()
    }
    return Trial(trial.id, trial.maneuver, trial.repetition, ch, trial.vehicle_id,
                 trial.sample_rate_hz / m, trial.provenance)
