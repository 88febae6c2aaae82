"""Identification data of one candidate: clamped commands, features, actuals, windows.

Commands go through the chain's input envelope before anything else (a submodel is
fitted on what the chain will feed it). Features come from the measured states, or from
NSS-predicted ones for the fine-tune of §III-C (``states``). Truth channels are never read.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from parknss.actuators.config import FitConfig
from parknss.actuators.envelopes import Envelope, clean_commands
from parknss.actuators.spec import (
    ACTUAL_OF,
    CHANNEL_INDEX,
    CandidateSpec,
    feature_matrix,
)
from parknss.data.trial import Trial
from parknss.errors import DataError
from parknss.signals import COMMAND_CHANNELS


@dataclass
class ChannelData:
    """Per trial: cmd (T,), feat (T, F), y (T,) physical; ids."""

    ids: list[str]
    cmd: list[np.ndarray]
    feat: list[np.ndarray]
    y: list[np.ndarray]

    def cat(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return np.concatenate(self.cmd), np.concatenate(self.feat), np.concatenate(self.y)


def channel_data(
    spec: CandidateSpec,
    trials: Sequence[Trial],
    env: Envelope,
    states: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
) -> ChannelData:
    """Clamped command, features and measured actual of ``spec``'s channel per trial.

    states: optional trial id -> (vx, yaw) arrays replacing the measured state features.
    """
    if not trials:
        raise DataError("no trials to identify from")
    j = 1 + CHANNEL_INDEX[spec.channel]
    out = ChannelData([], [], [], [])
    for tr in trials:
        c = clean_commands(env, tr.array(COMMAND_CHANNELS)[None], np.array([tr["steer"][0]]))[0]
        vx, yaw = states[tr.id] if states is not None else (tr["vx"], tr["yaw_rate"])
        out.ids.append(tr.id)
        out.cmd.append(c[:, j])
        out.feat.append(feature_matrix(spec.features, vx, yaw, c[:, 0]))
        out.y.append(np.asarray(tr[ACTUAL_OF[spec.channel]], dtype=np.float64))
    return out


@dataclass
class Windows:
    """Training windows: cmd (N, L), feat (N, L, F), y (N, L), y0 (N,), mask (N, L)."""

    cmd: np.ndarray
    feat: np.ndarray
    y: np.ndarray
    y0: np.ndarray
    mask: np.ndarray


def windows(d: ChannelData, cfg: FitConfig) -> Windows:
    """Tile every trial into windows of burn_in + window samples (stride = window), the
    last one end-aligned; the first burn_in samples of each are not scored (the lag starts
    from the measured actual, NARX from a constant history, GRU/LSTM from zero)."""
    L = cfg.burn_in + cfg.window
    cs, fs, ys, y0s, ms = [], [], [], [], []
    for c, f, y in zip(d.cmd, d.feat, d.y, strict=True):
        n = len(c)
        if n <= L:
            starts = [0]
        else:
            starts = list(range(0, n - L + 1, cfg.window))
            if starts[-1] != n - L:
                starts.append(n - L)
        for a in starts:
            b = min(a + L, n)
            pad = L - (b - a)
            cs.append(np.pad(c[a:b], (0, pad), mode="edge"))
            fs.append(np.pad(f[a:b], ((0, pad), (0, 0)), mode="edge"))
            ys.append(np.pad(y[a:b], (0, pad), mode="edge"))
            y0s.append(y[a])
            m = np.zeros(L, dtype=bool)
            m[min(cfg.burn_in, b - a - 1) : b - a] = True
            ms.append(m)
    keep = _spread(len(cs), cfg.max_windows)
    return Windows(
        np.stack([cs[i] for i in keep]), np.stack([fs[i] for i in keep]),
        np.stack([ys[i] for i in keep]), np.array([y0s[i] for i in keep]),
        np.stack([ms[i] for i in keep]),
    )


def _spread(n: int, cap: int) -> list[int]:
    """At most ``cap`` of n indices, evenly spread (all trials stay represented)."""
    if n <= cap:
        return list(range(n))
    return sorted({round(i) for i in np.linspace(0, n - 1, cap)})
