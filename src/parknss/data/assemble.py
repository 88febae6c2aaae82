"""One log -> trial channels on the 100 Hz grid: the single path every format takes.

Readers (:mod:`parknss.data.io` for CSV/Parquet/.mat, :mod:`parknss.data.mdf`,
:mod:`parknss.data.canlog`) hand over a :class:`LogRead`: one
:class:`~parknss.data.resample.Series` per mapped source, each with its own time stamps.
:func:`assemble` then applies the mapping (:mod:`parknss.data.mapping`) in the order
documented in docs/data.md ("From a log to a trial"):

1. **invalid samples** of each source (``invalid``, ``valid_range``, NaN only when listed)
   are dropped (``on_invalid: mask``) or mark a cut (``crop``);
2. **enumeration maps** (``values``, ``gear_values``) turn labels and codes into numbers;
3. **coverage**: a channel covers the time between two of its samples when they are at
   most ``max_gap_s`` apart (``event`` channels cover everything after their first
   sample); the trial is where every channel is covered, inside the ``time.crop``
   window. A longer hole inside it is a gap: refused with one line, or, with
   ``resample.on_gap: split``, each stretch becomes a trial; a ``crop`` mark keeps the
   longest stretch without it;
4. **grid**: times ``k / 100`` s inside the stretch; linear channels interpolated, held
   channels (gear, enumerations, integers, CAN signals) take their last value. A table
   log (CSV, Parquet, .mat) that is already at 100 Hz (every step 0.01 s within the
   validation tolerance) and loses no sample is taken row for row, unresampled;
5. **values**: ``combine`` the sources, ``scale``/``offset``, unit conversion
   (:func:`parknss.signals.convert_to_schema`, the one place), ``invert``,
   ``sign_from_gear``, ``clip``; absent channels are left out, constants filled in.

Every problem is a one-line :class:`~parknss.errors.DataError` naming the file, the
channel and what to change in the mapping. Nothing is extrapolated or silently repaired.
"""

from __future__ import annotations

import contextlib
import itertools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from parknss.data.mapping import GATE_SUFFIX, ChannelMapping, ChannelSource, ValidIf
from parknss.data.resample import Series, check_series, grid_between, hold, linear
from parknss.errors import DataError
from parknss.signals import (
    CHANNEL_BY_NAME,
    DT,
    SAMPLE_RATE_HZ,
    TRUTH_PREFIX,
    canonical_unit,
    convert_to_schema,
    unit_dimension,
)


@dataclass(frozen=True)
class LogRead:
    """What a reader hands to :func:`assemble`.

    Attributes:
        series: one per source of a mapped channel (keys ``<channel>#<k>``) and per kept
            ``truth_*`` channel (key = its name).
        fmt: the format, for the provenance (``csv``, ``mdf4``, ``blf``, ...).
        use_file_units: take a source's own unit (MDF, DBC) when the mapping gives none.
        table: a table log (one shared time column): may be taken row for row.
        meta: the file's parknss_trial metadata, if any.
        provenance: the reader's own provenance entries (DBC, buses, ...).
        unit_required: a source without a unit of its own (a DBC signal with an empty
            unit) needs the mapping's ``unit`` (refused otherwise, rather than taken to
            be the schema unit).
    """

    series: list[Series]
    fmt: str
    use_file_units: bool = False
    table: bool = False
    meta: dict = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)
    unit_required: bool = False


@dataclass(frozen=True)
class Assembled:
    """One trial's channels (float64 (T,), schema units) and how they were made."""

    channels: dict[str, np.ndarray]
    provenance: dict


@dataclass(frozen=True)
class _Prepared:
    """A series after masking and enumeration mapping."""

    s: Series  # valid samples only, numeric values
    n_masked: int
    crop_marks: np.ndarray  # times of samples marked invalid under on_invalid: crop, s
    max_gap_s: float
    event: bool


@dataclass(frozen=True)
class _Hole:
    """A hole between two samples of one series that breaks its coverage."""

    start: float
    end: float
    label: str
    gap: bool  # True: longer than max_gap_s; False: a crop mark


# ------------------------------------------------------------------ 1-2: masking, values


def spec_of(m: ChannelMapping, channel: str) -> ChannelSource:
    """The mapping spec of a schema channel, or the plain default of a truth_* channel."""
    if channel in CHANNEL_BY_NAME:
        return m.source(channel)
    return ChannelSource(column=channel)


def _locate(s: Series, i: int) -> str:
    if s.locate is not None:
        return s.locate(i)
    return f"t={s.t[i]:.3f} s"


_NAN_TEXT = ("nan", ".nan")


def _as_number(x: float | str) -> float | None:
    """An ``invalid`` entry as a number (``"nan"``/``".nan"`` -> NaN), or None for text."""
    if isinstance(x, str):
        if x.strip().lower() in _NAN_TEXT:
            return math.nan
        try:
            return float(x)
        except ValueError:
            return None
    return float(x)


def _invalid_mask(s: Series, spec: ChannelSource) -> np.ndarray:
    """Samples whose source value is listed in ``invalid`` or outside ``valid_range``.

    A text entry that is no number (``""``, ``"n/a"``) marks text samples equal to it; in
    a numeric column the table reader has already read such text as NaN, so it marks NaN.
    """
    v = s.values
    bad = np.zeros(len(v), dtype=bool)
    if not spec.invalid and spec.valid_range is None:
        return bad
    text = v.dtype.kind in "OSU"
    for x in spec.invalid:
        num = _as_number(x)
        if text:
            if num is None:
                bad |= np.array([str(e).strip() == str(x).strip() for e in v], dtype=bool)
            else:
                bad |= np.array([_text_equals_number(e, num) for e in v], dtype=bool)
        else:
            bad |= _equal(v, math.nan if num is None else num)
    if spec.valid_range is not None and not text:
        lo, hi = spec.valid_range
        with np.errstate(invalid="ignore"):
            num_v = np.asarray(v, dtype=np.float64)
            bad |= (num_v < lo) | (num_v > hi)
    return bad


def _equal(v: np.ndarray, x: float) -> np.ndarray:
    num = np.asarray(v, dtype=np.float64)
    if math.isnan(x):
        return np.isnan(num)
    # sentinels decoded through a DBC scale are not exact: compare to 1e-9 relative
    return np.isclose(num, x, rtol=1e-9, atol=1e-12)


def _text_equals_number(e: object, x: float) -> bool:
    try:
        y = float(str(e).strip())
    except ValueError:
        return False
    return (math.isnan(x) and math.isnan(y)) or y == x


def _map_values(s: Series, spec: ChannelSource, source: str) -> np.ndarray:
    """Enumeration map (labels or numeric codes -> numbers), else the values as float64."""
    v = s.values
    if spec.values is None:
        if v.dtype.kind in "OSU":
            k = next((i for i, e in enumerate(v) if not _is_number(e)), 0)
            hint = "gear_values" if s.channel == "gear" else f"channels.{s.channel}.values"
            raise DataError(
                f"{source}: {s.label}: value {str(v[k]).strip()!r} at {_locate(s, k)} is "
                f"not a number; map the codes with {hint}"
            )
        return np.asarray(v, dtype=np.float64)
    by_text = {k.strip(): float(code) for k, code in spec.values.items()}
    by_num: dict[float, float] = {}
    for k, code in spec.values.items():
        with contextlib.suppress(ValueError):
            by_num[float(k)] = float(code)
    out = np.empty(len(v), dtype=np.float64)
    cache: dict[object, float | None] = {}
    for i, raw in enumerate(v):
        key = raw.item() if isinstance(raw, np.generic) else raw
        code = cache.get(key, math.inf)
        if code == math.inf:
            text = str(key).strip()
            code = by_text.get(text)
            if code is None:
                with contextlib.suppress(ValueError):
                    code = by_num.get(float(text))
            cache[key] = code
        if code is None:
            known = ", ".join(spec.values)
            what = "gear_values" if s.channel == "gear" else f"channels.{s.channel}.values"
            raise DataError(
                f"{source}: {s.label}: value {str(key).strip()!r} at {_locate(s, i)} is not "
                f"in {what} ({known})"
            )
        out[i] = code
    return out


def _is_number(e: object) -> bool:
    try:
        float(str(e).strip())
    except ValueError:
        return False
    return True


def _check_finite(s: Series, values: np.ndarray, source: str) -> None:
    bad = ~np.isfinite(values)
    if not bad.any():
        return
    nan = np.isnan(values)
    kind = "NaN" if nan.any() else "infinite"
    idx = np.flatnonzero(nan if nan.any() else bad)
    raise DataError(
        f"{source}: {s.label}: {len(idx)} {kind} values (first at {_locate(s, int(idx[0]))}); "
        f"list them in channels.{s.channel}.invalid to mask them"
    )


def _subset(s: Series, keep: np.ndarray, values: np.ndarray | None = None, **changes) -> Series:
    """The samples ``keep`` of a series (``values``: already taken from them), with other
    fields changed; error locations still point into the source."""
    if keep.all():  # nothing dropped: share the arrays (a long log is not copied)
        return replace(s, values=s.values if values is None else values, **changes)
    idx = np.flatnonzero(keep)
    locate = s.locate
    return replace(
        s,
        t=s.t[keep],
        values=s.values[keep] if values is None else values,
        locate=None if locate is None else (lambda i: locate(int(idx[i]))),
        **changes,
    )


def _gate_ok(gate: Series, rule: ValidIf) -> np.ndarray:
    """Per gate sample: is its value one of ``rule.equals`` (numbers or text)."""
    v = gate.values
    nums = [x for x in (_as_number(e) for e in rule.equals) if x is not None]
    texts = {str(e).strip() for e in rule.equals if isinstance(e, str)}
    if v.dtype.kind in "OSU":
        out = np.array([str(e).strip() in texts for e in v], dtype=bool)
        for x in nums:
            out |= np.array([_text_equals_number(e, x) for e in v], dtype=bool)
        return out
    out = np.zeros(len(v), dtype=bool)
    for x in nums:
        out |= _equal(v, x)
    return out


def gated(s: Series, gate: Series, rule: ValidIf, tol: float) -> np.ndarray:
    """Samples of ``s`` the gate marks invalid: its last value at or before each sample
    time (± tol) is not valid, or there is none yet. Bool (N,)."""
    ok = _gate_ok(gate, rule)
    idx = np.searchsorted(gate.t, s.t + tol, side="right") - 1
    return (idx < 0) | ~ok[np.clip(idx, 0, None)]


def prepare(
    s: Series, m: ChannelMapping, source: str, extra_bad: np.ndarray | None = None
) -> _Prepared:
    """Steps 1-2 for one series: drop invalid samples (``extra_bad``: those its validity
    signal marks), map enumerations, check numbers."""
    spec = spec_of(m, s.channel)
    bad = _invalid_mask(s, spec)
    if extra_bad is not None:
        bad |= extra_bad
    values = _map_values(_subset(s, ~bad), spec, source)
    if spec.valid_range is not None and s.values.dtype.kind in "OSU":
        lo, hi = spec.valid_range
        out = (values < lo) | (values > hi)
        bad[np.flatnonzero(~bad)[out]] = True
        values = values[~out]
    hold = s.hold if spec.interpolation == "auto" else spec.interpolation == "hold"
    if s.channel in CHANNEL_BY_NAME and CHANNEL_BY_NAME[s.channel].integer:
        hold = True  # gear is never interpolated (the mapping check refuses linear)
    event = spec.event if spec.event is not None else s.event
    sub = _subset(s, ~bad, values, hold=hold, event=event)
    _check_finite(sub, values, source)
    if not len(values):
        raise DataError(
            f"{source}: {s.label}: all {len(bad)} samples are invalid (channels."
            f"{s.channel}.invalid / valid_range); check the sentinel values or the window"
        )
    crop_marks = s.t[bad] if spec.on_invalid == "crop" else np.empty(0)
    gap = spec.max_gap_s if spec.max_gap_s is not None else m.resample.max_gap_s
    return _Prepared(sub, int(bad.sum()), crop_marks, gap, event)


# ------------------------------------------------------------------ 3: coverage


def _intervals(p: _Prepared, holes: list[_Hole]) -> list[tuple[float, float]]:
    """The time the series covers, as sorted closed intervals; its holes are appended."""
    t = p.s.t
    if p.event:
        return [(float(t[0]), math.inf)]
    dt = np.diff(t)
    cut = dt > p.max_gap_s
    if len(p.crop_marks):
        k = np.searchsorted(t, p.crop_marks)  # mark between samples k-1 and k
        inside = (k > 0) & (k < len(t))
        crop = np.zeros(len(dt), dtype=bool)
        crop[k[inside] - 1] = True
        for j in np.flatnonzero(crop & ~cut):
            holes.append(_Hole(float(t[j]), float(t[j + 1]), p.s.label, gap=False))
    else:
        crop = np.zeros(len(dt), dtype=bool)
    for j in np.flatnonzero(cut):
        holes.append(_Hole(float(t[j]), float(t[j + 1]), p.s.label, gap=True))
    breaks = np.flatnonzero(cut | crop)
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [len(t) - 1]])
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends, strict=True)]


def _intersect(a: list[tuple[float, float]], b: list[tuple[float, float]]):
    out, i, j = [], 0, 0
    while i < len(a) and j < len(b):
        lo, hi = max(a[i][0], b[j][0]), min(a[i][1], b[j][1])
        if lo <= hi:
            out.append((lo, hi))
        if a[i][1] < b[j][1]:
            i += 1
        else:
            j += 1
    return out


@dataclass(frozen=True)
class _Stretch:
    start: float
    end: float
    start_by: str
    end_by: str


def _limits(prepared: list[_Prepared], cover: list[list], a: float, b: float) -> tuple[str, str]:
    """Labels of the series whose coverage starts last / ends first around [a, b]."""
    start_by, end_by = "", ""
    lo_best, hi_best = -math.inf, math.inf
    for p, iv in zip(prepared, cover, strict=True):
        for lo, hi in iv:
            if lo <= a + 1e-12 and hi >= b - 1e-12:
                if lo > lo_best:  # the first series in mapping order wins a tie
                    lo_best, start_by = lo, p.s.label
                if hi < hi_best:
                    hi_best, end_by = hi, p.s.label
                break
    return start_by, end_by


def stretches(
    prepared: list[_Prepared],
    m: ChannelMapping,
    source: str,
    window: tuple[float, float] | None,
) -> tuple[list[_Stretch], dict]:
    """Step 3: the stretches of the log that become trials, and what was dropped."""
    holes: list[_Hole] = []
    cover = [_intervals(p, holes) for p in prepared]
    log_start = min(float(p.s.t[0]) for p in prepared)
    common: list[tuple[float, float]] = [(-math.inf, math.inf)]
    for iv in cover:
        common = _intersect(common, iv)
    if window is not None:
        common = _intersect(common, [(log_start + window[0], log_start + window[1])])
    tol = m.resample.time_tolerance_s
    common = [(a, b) for a, b in common if len(grid_between(a, b, tol)) > 0]
    if not common:
        _no_span(prepared, source, window, log_start)
    groups: list[list[tuple[float, float]]] = [[common[0]]]
    for prev, nxt in itertools.pairwise(common):
        gap = next(
            (h for h in holes if h.gap and h.start < nxt[0] and h.end > prev[1]), None
        )
        if gap is not None and m.resample.on_gap == "refuse":
            ch = gap.label.split("'")[1] if "'" in gap.label else "?"
            raise DataError(
                f"{source}: {gap.label}: no sample for {gap.end - gap.start:.3f} s from "
                f"t={gap.start:.3f} s (longer than max_gap_s); raise channels.{ch}.max_gap_s, "
                "set resample.on_gap: split, or keep a window with time.crop"
            )
        if gap is not None:
            groups.append([nxt])
        else:
            groups[-1].append(nxt)
    info: dict = {"dropped_stretches_s": []}
    out = []
    for g in groups:
        a, b = max(g, key=lambda iv: iv[1] - iv[0])
        for other in g:
            if other != (a, b):
                info["dropped_stretches_s"].append([other[0], other[1]])
        if len(groups) > 1 and b - a < m.resample.min_segment_s:
            info["dropped_stretches_s"].append([a, b])
            continue
        out.append(_Stretch(a, b, *_limits(prepared, cover, a, b)))
    if not out:
        raise DataError(
            f"{source}: every stretch between gaps is shorter than resample.min_segment_s "
            f"({m.resample.min_segment_s:g} s)"
        )
    info["log_span_s"] = [log_start, max(float(p.s.t[-1]) for p in prepared)]
    return out, info


def _no_span(prepared, source: str, window, log_start: float) -> None:
    first = max(prepared, key=lambda p: p.s.t[0])
    last = min(prepared, key=lambda p: p.s.t[-1] if not p.event else math.inf)
    if window is not None:
        raise DataError(
            f"{source}: the crop window [{window[0]:g}, {window[1]:g}] s (from the log's "
            f"first time stamp t={log_start:.3f} s) holds no stretch where every channel "
            "has samples"
        )
    if first.s.t[0] > last.s.t[-1]:
        raise DataError(
            f"{source}: {first.s.label}: starts at t={first.s.t[0]:.3f} s, after "
            f"{last.s.label} ends at t={last.s.t[-1]:.3f} s (no common time span)"
        )
    raise DataError(
        f"{source}: no stretch of the log where every channel has samples (check the gaps "
        "and crop marks of each channel)"
    )


# ------------------------------------------------------------------ 5: values


def _file_unit(
    series: list[Series],
    spec: ChannelSource,
    use_file_units: bool,
    source: str,
    unit_required: bool = False,
):
    """The unit to convert from: the mapping's, else the sources' own, else None."""
    if spec.unit is not None:
        return spec.unit
    channel = series[0].channel
    ch = CHANNEL_BY_NAME.get(channel)
    if ch is None or ch.integer or not use_file_units:
        return None
    units = {(s.unit or "").strip() for s in series}
    if len(units) > 1:
        raise DataError(
            f"{source}: {series[0].label}: its sources have different units "
            f"({', '.join(sorted(units))}); set the channel's unit in the mapping"
        )
    unit = units.pop()
    if not unit and unit_required and ch.unit != "-":
        raise DataError(
            f"{source}: {series[0].label}: the DBC gives the signal no unit; state it in "
            f"the mapping (channels.{channel}.unit, e.g. {ch.unit!r} if it is in {ch.unit})"
        )
    if not unit:
        return None
    if canonical_unit(unit) is None:
        raise DataError(
            f"{source}: {series[0].label}: unit {unit!r} in the file is not one parknss "
            "converts; set the channel's unit in the mapping"
        )
    if unit_dimension(unit) != ch.unit:
        raise DataError(
            f"{source}: {series[0].label}: unit {unit!r} in the file cannot be converted to "
            f"the channel's unit {ch.unit!r}; set the channel's unit in the mapping"
        )
    return unit


def channel_values(
    name: str,
    spec: ChannelSource,
    parts: list[np.ndarray],
    series: list[Series],
    gear: np.ndarray | None,
    use_file_units: bool,
    source: str,
    clipped: dict,
    unit_required: bool = False,
) -> np.ndarray:
    """Step 5 for one schema channel on the grid: combine, scale, unit, sign, clip."""
    if spec.combine == "sum":
        v = np.sum(parts, axis=0)
    else:
        v = np.mean(parts, axis=0) if len(parts) > 1 else np.asarray(parts[0], dtype=np.float64)
    if spec.scale != 1.0 or spec.offset != 0.0:
        v = v * spec.scale + spec.offset
    unit = _file_unit(series, spec, use_file_units, source, unit_required)
    if unit is not None:
        v = convert_to_schema(v, unit, name)
    if spec.invert:
        v = -v
    if spec.sign_from_gear:
        assert gear is not None  # the mapping check guarantees a gear channel
        v = np.abs(v) * np.where(gear < -0.5, -1.0, 1.0)
    if spec.clip is not None:
        lo, hi = spec.clip
        n = int(np.count_nonzero((v < lo) | (v > hi)))
        if n:
            clipped[name] = n
        v = np.clip(v, lo, hi)
    return np.asarray(v, dtype=np.float64)


def _constant(name: str, spec: ChannelSource, n: int) -> np.ndarray:
    v = np.full(n, float(spec.constant), dtype=np.float64)
    return convert_to_schema(v, spec.unit, name) if spec.unit is not None else v


def to_channels(
    g: np.ndarray,
    values: dict[str, np.ndarray],
    read: LogRead,
    m: ChannelMapping,
    source: str,
) -> tuple[dict[str, np.ndarray], dict]:
    """Grid values by series key -> schema channels (+ truth_*), and the clip counts."""
    by_channel: dict[str, list[Series]] = {}
    for s in read.series:
        by_channel.setdefault(s.channel, []).append(s)
    out: dict[str, np.ndarray] = {"t": g - g[0] if m.time.start_at_zero else g.copy()}
    clipped: dict[str, int] = {}
    order = ["gear"] + [c for c in CHANNEL_BY_NAME if c not in ("t", "gear")]
    for name in order:
        spec = m.source(name)
        if spec.absent:
            continue
        if spec.constant is not None:
            out[name] = _constant(name, spec, len(g))
            continue
        series = by_channel.get(name)
        if not series:
            continue  # not in the log: the reader or validation names it
        parts = [values[s.key] for s in series]
        out[name] = channel_values(
            name, spec, parts, series, out.get("gear"), read.use_file_units, source, clipped,
            read.unit_required,
        )
    for name, series in by_channel.items():
        if name.startswith(TRUTH_PREFIX):
            out[name] = np.asarray(values[series[0].key], dtype=np.float64)
    ordered = {c: out[c] for c in CHANNEL_BY_NAME if c in out}
    ordered.update({c: v for c, v in out.items() if c not in ordered})
    return ordered, clipped


# ------------------------------------------------------------------ the whole path


def _row_for_row(read: LogRead, prepared: list[_Prepared], window, tol: float) -> bool:
    """A table log on the 100 Hz grid (every time stamp within ``tol`` of k/100 s, no
    sample missing) that loses no sample is taken row for row, unresampled."""
    if not read.table or window is not None or not prepared:
        return False
    if any(p.n_masked for p in prepared):
        return False
    t = prepared[0].s.t
    if len(t) < 2 or any(p.s.t is not t and not np.array_equal(p.s.t, t) for p in prepared):
        return False
    on_grid = np.abs(t - np.round(t * SAMPLE_RATE_HZ) / SAMPLE_RATE_HZ) <= tol
    return bool(np.all(on_grid) and np.all(np.abs(np.diff(t) - DT) <= tol))


def _rate_hz(read: LogRead) -> float | None:
    rates = []
    for s in read.series:
        if len(s.t) > 1:
            med = float(np.median(np.diff(s.t)))
            if med > 0:
                rates.append(1.0 / med)
    return round(max(rates), 3) if rates else None


def assemble(
    read: LogRead,
    m: ChannelMapping,
    source: str,
    window: tuple[float, float] | None = None,
) -> list[Assembled]:
    """Steps 1-5 for one log: the trials it gives (one, or several with on_gap: split).

    Args:
        read: the reader's series and provenance.
        m: the channel mapping.
        source: the file, named in every error.
        window: keep only [start, end] s from the log's first time stamp (time.crop or
            the manifest's start_s/end_s).
    """
    if not read.series:
        raise DataError(f"{source}: no channels to read (check the mapping)")
    for s in read.series:
        check_series(s, source)
    gates = {s.channel[: -len(GATE_SUFFIX)]: s for s in read.series
             if s.channel.endswith(GATE_SUFFIX)}
    series = [s for s in read.series if not s.channel.endswith(GATE_SUFFIX)]
    read = replace(read, series=series)
    prepared = []
    tol = m.resample.time_tolerance_s
    for s in series:
        rule = m.source(s.channel).valid_if if s.channel in CHANNEL_BY_NAME else None
        extra = None
        if rule is not None:
            if s.channel not in gates:
                raise DataError(f"{source}: {s.label}: valid_if is read from CSV, Parquet, "
                                ".mat and CAN logs only")
            extra = gated(s, gates[s.channel], rule, tol)
        prepared.append(prepare(s, m, source, extra))
    masked = {p.s.label: p.n_masked for p in prepared if p.n_masked}
    base = {"source_file": source, "format": read.fmt, **read.provenance}
    rate = _rate_hz(read)
    if masked:
        base["masked_samples"] = masked
    if _row_for_row(read, prepared, window, m.resample.time_tolerance_s):
        g = prepared[0].s.t
        values = {p.s.key: p.s.values for p in prepared}
        channels, clipped = to_channels(g, values, read, m, source)
        prov = {**base, "resampled": False, "source_rate_hz": rate}
        if clipped:
            prov["clipped_samples"] = clipped
        return [Assembled(channels, prov)]
    parts, info = stretches(prepared, m, source, window)
    out = []
    for k, st in enumerate(parts):
        g = grid_between(st.start, st.end, tol)
        values = {
            p.s.key: hold(p.s.t, p.s.values, g, tol) if p.s.hold else linear(p.s.t, p.s.values, g)
            for p in prepared
        }
        channels, clipped = to_channels(g, values, read, m, source)
        prov = {
            **base,
            "resampled": True,
            "resampled_hz": SAMPLE_RATE_HZ,
            "source_rate_hz": rate,
            "span_s": [st.start, st.end],
            "log_span_s": info["log_span_s"],
            "start_limited_by": st.start_by,
            "end_limited_by": st.end_by,
        }
        if window is not None:
            prov["crop_s"] = list(window)
        if len(parts) > 1:
            prov["stretch"] = [k + 1, len(parts)]
        if info["dropped_stretches_s"]:
            prov["dropped_stretches_s"] = info["dropped_stretches_s"]
        if clipped:
            prov["clipped_samples"] = clipped
        out.append(Assembled(channels, prov))
    return out
