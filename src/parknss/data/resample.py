"""Signals with their own time stamps, and the two ways onto the 100 Hz grid.

Every reader hands its sources to :mod:`parknss.data.assemble` as :class:`Series` (any
rate, event times for CAN). This module holds what a series is, its checks, the grid
``t = k / 100`` s and the two resampling rules: **linear** interpolation between the two
neighbouring samples, and **hold** (the last sample at or before the grid time, a sample
within ``time_tolerance_s`` of it counting as at it). The span, gap and crop rules that
decide which grid times a trial keeps are in :mod:`parknss.data.assemble`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from parknss.errors import DataError
from parknss.signals import SAMPLE_RATE_HZ


@dataclass(frozen=True)
class Series:
    """One logged signal before resampling.

    Attributes:
        channel: the schema channel (or ``truth_*`` name) it becomes.
        key: its raw-column name, the source's own name (MDF channel, ``Message.Signal``).
        label: how messages name it, e.g. ``channel 'vx' (MDF channel 'VehSpd')``.
        t: time stamps, s, shape (N,), non-decreasing.
        values: samples, shape (N,); numbers, or text (enumerated labels, hold only).
        hold: previous-value hold instead of linear interpolation.
        unit: the unit the source declares for it ('' or None: none given).
        locate: how messages point at sample i (e.g. ``line 1353`` of a CSV), or None
            for ``t=... s``.
        event: the reader's default for the channel's ``event`` flag (MDF enumerated and
            integer channels are logged on change); the mapping's ``event`` overrides it.
    """

    channel: str
    key: str
    label: str
    t: np.ndarray
    values: np.ndarray
    hold: bool
    unit: str | None = None
    locate: Callable[[int], str] | None = None  # sample i in messages (default: its time)
    event: bool = False  # logged on change: holds until the next sample, however long


def _is_text(values: np.ndarray) -> bool:
    return values.dtype.kind in "OSU"


def check_series(s: Series, source: str) -> None:
    """Time stamps finite and non-decreasing, at least one sample; linear: numbers, no ties."""
    if len(s.t) == 0:
        raise DataError(f"{source}: {s.label}: no samples")
    if len(s.values) != len(s.t):
        raise DataError(f"{source}: {s.label}: {len(s.values)} values for {len(s.t)} time stamps")
    if not np.all(np.isfinite(s.t)):
        raise DataError(f"{source}: {s.label}: non-finite time stamps")
    dt = np.diff(s.t)
    back = np.flatnonzero(dt < 0.0)
    if len(back):
        k = int(back[0])
        raise DataError(
            f"{source}: {s.label}: non-monotonic time stamps, {len(back)} steps backwards "
            f"(first from t={s.t[k]:.6f} s to t={s.t[k + 1]:.6f} s)"
        )
    if s.hold:
        return
    if _is_text(s.values):
        raise DataError(
            f"{source}: {s.label}: text values cannot be interpolated (interpolation: hold)"
        )
    ties = np.flatnonzero(dt == 0.0)
    if len(ties):
        raise DataError(
            f"{source}: {s.label}: {len(ties)} duplicate time stamps (first at "
            f"t={s.t[int(ties[0])]:.6f} s); a linear channel needs increasing time"
        )


def grid_between(start: float, end: float, tol: float) -> np.ndarray:
    """Times k / SAMPLE_RATE_HZ inside [start - tol, end + tol], s, shape (T,)."""
    k0 = math.ceil((start - tol) * SAMPLE_RATE_HZ)
    k1 = math.floor((end + tol) * SAMPLE_RATE_HZ)
    return np.arange(k0, k1 + 1, dtype=np.float64) / SAMPLE_RATE_HZ


def hold(t: np.ndarray, values: np.ndarray, g: np.ndarray, tol: float) -> np.ndarray:
    """Zero-order hold: at each grid time the last value stamped at or before it (± tol).

    ``g`` must lie inside the series' span (grid() guarantees it); shapes (N,), (N,), (T,).
    """
    idx = np.searchsorted(t, g + tol, side="right") - 1
    return values[np.clip(idx, 0, len(values) - 1)]


def linear(t: np.ndarray, values: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Linear interpolation at the grid times (inside the span: no extrapolation)."""
    return np.interp(g, t, np.asarray(values, dtype=np.float64))
