"""Bus-log signals onto the trial's 100 Hz grid: the one place for span, grid and holds.

MDF4 channels and decoded CAN signals arrive as :class:`Series`, each with its own time
stamps (any rate, event times for CAN). The rules (docs/data.md, "Bus logs"):

* **span**: the trial starts at the latest first sample of any channel and ends at the
  earliest last sample of the linear channels: a channel that starts late or a
  continuous one that ends early crops the trial (the provenance says which channel
  limited each end), and nothing is extrapolated. A held channel's samples are events
  (a value holds until the next one), so it keeps its last value up to the end; only
  when every channel is held (CAN) does the last sample of any of them end the trial.
* **grid**: times ``k / 100`` s (k integer) inside that span, so a log already at
  100 Hz on that grid is taken sample for sample.
* **linear** channels: linear interpolation between the two neighbouring samples.
* **hold** channels (gear, integer or enumerated MDF channels, every CAN signal): the
  last sample at or before the grid time (zero-order hold); a sample counts as at the
  grid time when within ``time_tolerance_s`` of it.

Then :func:`to_raw` hands the grid and the resampled values to the channel mapping
(:func:`parknss.data.mapping.apply_mapping`), which converts units in the one place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from parknss.data.mapping import ChannelMapping, ChannelSource, Column, TimeSource
from parknss.errors import DataError
from parknss.signals import CHANNEL_BY_NAME, SAMPLE_RATE_HZ, UNIT_CONVERSIONS

TIME_KEY = "t"  # raw-column key of the grid time; readers keep source names off it


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
    """

    channel: str
    key: str
    label: str
    t: np.ndarray
    values: np.ndarray
    hold: bool
    unit: str | None = None


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


@dataclass(frozen=True)
class Span:
    """The common time span of a set of series and the channels that limit it, s."""

    start: float
    end: float
    start_by: str  # label of the series that starts last
    end_by: str  # label of the series whose last sample ends the span
    log_start: float  # earliest first sample of any series
    log_end: float  # latest last sample of any series

    def to_json(self) -> dict:
        return {
            "span_s": [self.start, self.end],
            "log_span_s": [self.log_start, self.log_end],
            "start_limited_by": self.start_by,
            "end_limited_by": self.end_by,
        }


def common_span(series: list[Series], source: str) -> Span:
    """Latest first sample to the earliest last sample of the linear series (all held:
    the latest last sample); DataError if they do not overlap."""
    if not series:
        raise DataError(f"{source}: no channels to read (check the mapping)")
    first = max(series, key=lambda s: s.t[0])
    linear_ = [s for s in series if not s.hold]
    last = min(linear_, key=lambda s: s.t[-1]) if linear_ else max(series, key=lambda s: s.t[-1])
    span = Span(
        start=float(first.t[0]),
        end=float(last.t[-1]),
        start_by=first.label,
        end_by=last.label,
        log_start=float(min(s.t[0] for s in series)),
        log_end=float(max(s.t[-1] for s in series)),
    )
    if span.end < span.start:
        raise DataError(
            f"{source}: {first.label}: starts at t={span.start:.3f} s, after {last.label} "
            f"ends at t={span.end:.3f} s (no common time span)"
        )
    return span


def grid(span: Span, tol: float) -> np.ndarray:
    """Times k / SAMPLE_RATE_HZ inside [start - tol, end + tol], s, shape (T,)."""
    k0 = math.ceil((span.start - tol) * SAMPLE_RATE_HZ)
    k1 = math.floor((span.end + tol) * SAMPLE_RATE_HZ)
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


def resample(series: list[Series], source: str, tol: float) -> tuple[np.ndarray, dict, Span]:
    """Check every series, then put all on one 100 Hz grid over their common span.

    Returns:
        (grid, values by series key (each (T,)), the span).
    """
    for s in series:
        check_series(s, source)
    span = common_span(series, source)
    g = grid(span, tol)
    if len(g) == 0:
        raise DataError(
            f"{source}: {span.start_by}: the common time span "
            f"[{span.start:.3f}, {span.end:.3f}] s holds no 100 Hz grid time"
        )
    out = {
        s.key: hold(s.t, s.values, g, tol) if s.hold else linear(s.t, s.values, g) for s in series
    }
    return g, out, span


@dataclass(frozen=True)
class BusLog:
    """A bus log read and resampled, ready for :func:`~parknss.data.mapping.apply_mapping`.

    Attributes:
        raw: raw columns: the grid under TIME_KEY (s, shape (T,)) and one (T,) column per
            series key, in source units.
        applied: the mapping that turns ``raw`` into schema channels (units, sign, gear).
        provenance: format, span kept and the channels that limited it.
        header_text: the file's own comment (MDF header), or None.
    """

    raw: dict[str, Column]
    applied: ChannelMapping
    provenance: dict
    header_text: str | None = None


def unique_key(name: str, channel: str, taken: set[str]) -> str:
    """``name``, or ``name@channel`` when another series already uses ``name``."""
    key = name if name not in taken else f"{name}@{channel}"
    taken.add(key)
    return key


def _unit(s: Series, src: ChannelSource | None, use_file_units: bool, source: str) -> str | None:
    """The unit to convert from: the mapping's, else the file's (if used), else None."""
    if src is not None and src.unit is not None:
        return src.unit
    ch = CHANNEL_BY_NAME.get(s.channel)
    if ch is None or ch.integer or not use_file_units or not (s.unit or "").strip():
        return None
    unit = s.unit.strip()
    if unit not in UNIT_CONVERSIONS:
        raise DataError(
            f"{source}: {s.label}: unit {unit!r} in the file is not one parknss converts "
            f"(known: {', '.join(UNIT_CONVERSIONS)}); set the channel's unit in the mapping"
        )
    if UNIT_CONVERSIONS[unit][0] != ch.unit:
        raise DataError(
            f"{source}: {s.label}: unit {unit!r} in the file cannot be converted to the "
            f"channel's unit {ch.unit!r}; set the channel's unit in the mapping"
        )
    return unit


def to_raw(
    series: list[Series], m: ChannelMapping, source: str, fmt: str, use_file_units: bool
) -> BusLog:
    """Resample, then build the raw columns and the mapping that converts them.

    The applied mapping reads the grid time (s) under TIME_KEY and each schema channel
    from its series key, with the resolved unit (mapping's, else the file's when
    ``use_file_units``) and the mapping's sign; gear codes and vehicle as in ``m``.
    """
    g, values, span = resample(series, source, m.resample.time_tolerance_s)

    def locate(i: int) -> str:
        return f"t={g[i]:.2f} s"

    raw = {TIME_KEY: Column(g, locate)}
    channels: dict[str, ChannelSource] = {}
    for s in series:
        raw[s.key] = Column(values[s.key], locate)
        if s.channel in CHANNEL_BY_NAME:
            src = m.channels.get(s.channel)
            channels[s.channel] = ChannelSource(
                column=s.key,
                unit=_unit(s, src, use_file_units, source),
                invert=src.invert if src is not None else False,
            )
    applied = ChannelMapping(
        time=TimeSource(column=TIME_KEY, unit="s", start_at_zero=m.time.start_at_zero),
        channels=channels,
        gear_values=m.gear_values,
        vehicle=m.vehicle,
        resample=m.resample,
    )
    provenance = {"source_file": source, "format": fmt, "resampled_hz": SAMPLE_RATE_HZ}
    provenance.update(span.to_json())
    return BusLog(raw, applied, provenance)
