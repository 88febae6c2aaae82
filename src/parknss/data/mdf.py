"""MDF4 logs (.mf4, .mdf) through asammdf: find the mapped channels, resample, hand over.

Each schema channel comes from the MDF channel the mapping names (``channels.<name>.
column``, compared by ``mdf.match``: exact, or asammdf's plain/wildcard/regex search,
where a name matching the whole pattern wins over names merely containing a match;
``group`` picks the data group when a name occurs in several), else from a channel of
its own name; ``truth_*`` channels are kept. Channels may have any rate and their own
time base; :mod:`parknss.data.resample` puts them on one 100 Hz grid (linear for
continuous channels, previous-value hold for gear, integer and enumerated ones), over
the span all of them cover. Units come from the mapping, else from the MDF channel
(``mdf.use_file_units``), and are converted by the channel mapping. Every problem is a
one-line DataError naming the file and the channel; asammdf's own log output and
tracebacks are kept off the terminal.
"""

from __future__ import annotations

import contextlib
import difflib
import gc
import logging
import os
import re
import sys
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from parknss.data.assemble import LogRead
from parknss.data.mapping import ChannelMapping, ChannelSource, SourceRef, iter_sources, source_key
from parknss.data.meta import META_KEY, parse_meta
from parknss.data.resample import Series
from parknss.errors import DataError, one_line
from parknss.signals import CHANNEL_BY_NAME, TRUTH_PREFIX

MDF_SUFFIXES: tuple[str, ...] = (".mf4", ".mdf")
MDF_VERSION = "4.10"  # written by write_mdf



@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """Silence asammdf's logger and the 'Exception ignored in __del__' of failed opens."""
    log = logging.getLogger("asammdf")
    level, hook = log.level, sys.unraisablehook
    log.setLevel(logging.CRITICAL + 1)
    sys.unraisablehook = lambda _u: None
    try:
        yield
    finally:
        log.setLevel(level)
        sys.unraisablehook = hook


def open_mdf(path: Path, **kwargs: Any) -> Any:
    """An asammdf MDF object (``kwargs`` go to ``MDF``), or DataError for an unreadable,
    corrupt or truncated file."""
    try:
        from asammdf import MDF
    except ImportError as exc:  # a pinned dependency; only a broken install lacks it
        raise DataError(f"{path}: reading MDF4 needs the package asammdf ({exc})") from exc

    problem = None
    with quiet():
        try:
            mdf = MDF(path, **kwargs)
        except Exception as exc:  # asammdf raises many types for bad files
            problem = one_line(exc)
        if problem is not None:
            gc.collect()  # the half-built MDF object's __del__ fails; let it do so quietly
    if problem is not None:
        raise DataError(f"{path}: not a readable MDF file, corrupt or truncated ({problem})")
    return mdf


def header_text(mdf: Any) -> str | None:
    """The text of the file's header comment (the <TX> of MDF4's XML), or None."""
    comment = str(getattr(mdf.header, "comment", "") or "").strip()
    if not comment:
        return None
    if comment.startswith("<"):
        with contextlib.suppress(ET.ParseError):
            return (ET.fromstring(comment).findtext(".//TX") or "").strip() or None
    return comment


def _occurrences(mdf: Any, names: list[str], group: int | None) -> list[tuple[str, int, int]]:
    """(name, group, index) of every non-master channel called one of ``names``."""
    masters = mdf.masters_db
    out = []
    for name in dict.fromkeys(names):
        for g, i in mdf.channels_db.get(name, ()):
            if masters.get(g) != i and (group is None or g == group):
                out.append((name, g, i))
    return out


def _whole_match(name: str, pattern: str, mode: str, case_insensitive: bool) -> bool:
    """Does ``name`` match all of ``pattern`` (asammdf's search finds it anywhere)?"""
    flags = re.IGNORECASE if case_insensitive else 0
    if mode == "regex":
        return re.fullmatch(pattern, name, flags) is not None
    if mode == "wildcard":
        parts = (re.escape(p) for p in pattern.split("*"))
        return re.fullmatch(".*".join(parts), name, flags) is not None
    return name.casefold() == pattern.casefold() if case_insensitive else name == pattern


def _find(mdf: Any, src: SourceRef, m: ChannelMapping, label: str, path: Path):
    """Resolve a mapped MDF channel to exactly one (name, group, index)."""
    pattern = str(src.column)
    opts = m.mdf
    if opts.match == "exact":
        names = [pattern]
    else:
        try:
            with quiet():
                names = mdf.search(pattern, mode=opts.match, case_insensitive=opts.case_insensitive)
        except Exception as exc:  # a bad regex
            raise DataError(
                f"{path}: {label}: bad {opts.match} pattern {pattern!r} ({one_line(exc)})"
            ) from exc
    found = _occurrences(mdf, names, src.group)
    whole = [f for f in found if _whole_match(f[0], pattern, opts.match, opts.case_insensitive)]
    found = whole or found
    where = f" in group {src.group}" if src.group is not None else ""
    if not found:
        similar = difflib.get_close_matches(pattern, list(mdf.channels_db), n=3)
        hint = f"; similar: {', '.join(similar)}" if similar else ""
        what = (
            f"MDF channel {pattern!r} not found"
            if opts.match == "exact"
            else f"no MDF channel matches the {opts.match} pattern {pattern!r}"
        )
        raise DataError(f"{path}: {label}: {what}{where}{hint}")
    if len(found) > 1:
        listed = ", ".join(f"{n!r} (group {g})" for n, g, _ in found[:5])
        raise DataError(
            f"{path}: {label}: {pattern!r} matches {len(found)} channels{where}: {listed}; "
            "narrow the name or give 'group' in the mapping"
        )
    return found[0]


@dataclass(frozen=True)
class _Target:
    """One MDF channel to read: the schema channel it feeds and where it is."""

    channel: str
    key: str
    name: str
    group: int
    index: int
    label: str
    spec: ChannelSource


def _targets(mdf: Any, m: ChannelMapping, path: Path) -> list[_Target]:
    """Every source of every mapped channel, and the truth_* channels, resolved."""
    out = []
    for name, k, ref, spec in iter_sources(m):
        if ref.column is None:
            raise DataError(
                f"{path}: channel {name!r}: the mapping gives a CAN {ref.describe()}; an MDF "
                "log needs 'column' (the MDF channel name), or a bus-logging MDF4 and the "
                "mapping's can.dbc"
            )
        label = f"channel {name!r}"
        if not m.is_mapped(name):
            found = _occurrences(mdf, [name], None)
            if len(found) > 1:
                raise DataError(
                    f"{path}: {label}: {len(found)} MDF channels of that name; map it "
                    "with 'column' and 'group'"
                )
            if found:
                out.append(_Target(name, source_key(name, k), *found[0], label, spec))
            continue
        ch, g, i = _find(mdf, ref, m, label, path)
        full = label + (f" (MDF channel {ch!r})" if ch != name else "")
        out.append(_Target(name, source_key(name, k), ch, g, i, full, spec))
    truth = sorted(n for n in mdf.channels_db if n.startswith(TRUTH_PREFIX))
    for name in truth:
        found = _occurrences(mdf, [name], None)
        if len(found) == 1:
            tspec = ChannelSource(column=name)
            out.append(_Target(name, name, *found[0], f"channel {name!r}", tspec))
    return out


def _text(samples: np.ndarray) -> np.ndarray:
    """Enumerated (value-to-text) samples as Python str labels."""
    return np.array(
        [
            x.decode("utf-8", "replace").strip("\x00 ") if isinstance(x, bytes) else str(x)
            for x in samples
        ],
        dtype=object,
    )


def _series(mdf: Any, tg: _Target, path: Path) -> Series:
    try:
        with quiet():
            sig = mdf.get(tg.name, group=tg.group, index=tg.index)
    except Exception as exc:
        raise DataError(
            f"{path}: {tg.label}: cannot read the channel, corrupt or truncated file "
            f"({one_line(exc)})"
        ) from exc
    samples, t = np.asarray(sig.samples), np.asarray(sig.timestamps, dtype=np.float64)
    if samples.ndim != 1 or samples.dtype.kind not in "biufOSU":
        raise DataError(f"{path}: {tg.label}: not a scalar channel (samples {samples.dtype})")
    text = samples.dtype.kind in "OSU"
    values = _text(samples) if text else samples
    mode = tg.spec.interpolation
    schema = CHANNEL_BY_NAME.get(tg.channel)
    integer = schema is not None and schema.integer
    if mode == "auto":
        hold = integer or text or samples.dtype.kind in "biu"
    else:
        hold = mode == "hold" or integer
    event = hold and (integer or text or samples.dtype.kind in "biu")
    return Series(tg.channel, tg.key, tg.label, t, values, hold, str(sig.unit or ""), None, event)


def read_mdf(path: Path, m: ChannelMapping) -> LogRead:
    """Read one (decoded) MDF4 log: every mapped source as a series, for the assembly.

    Args:
        path: an existing, non-empty .mf4/.mdf file with physical channels (a bus-logging
            file of raw CAN frames goes through :mod:`parknss.data.canlog` instead).
        m: the channel mapping (``channels``, ``mdf``).

    Returns:
        A LogRead: one series per source (MDF time stamps, s; source units), the file's
        header comment's parknss_trial metadata if it has one.
    """
    mdf = open_mdf(path)
    try:
        series = [_series(mdf, tg, path) for tg in _targets(mdf, m, path)]
        meta: dict = {}
        text = header_text(mdf) or ""
        if text.startswith(META_KEY):
            meta = parse_meta(text[len(META_KEY) :], path)
        return LogRead(series, "mdf4", use_file_units=m.mdf.use_file_units, meta=meta)
    finally:
        with quiet():
            mdf.close()


def write_mdf(channels: dict[str, np.ndarray], names: list[str], comment: str, path: Path) -> Path:
    """One trial as MDF4: one data group, master ``t`` (s), one channel per name.

    Schema channels carry their schema unit; ``gear`` is stored as int8 (so readers
    hold it), every other channel as float64. ``comment`` goes into the header comment.
    Written to a temporary file and renamed (asammdf always writes a .mf4 name).
    """
    from asammdf import MDF, Signal

    t = np.asarray(channels["t"], dtype=np.float64)
    signals = []
    for name in names:
        if name == "t":
            continue
        ch = CHANNEL_BY_NAME.get(name)
        values = np.asarray(channels[name], dtype=np.float64)
        if ch is not None and ch.integer:
            values = values.astype(np.int8)
        unit = ch.unit if ch is not None else ""
        signals.append(Signal(values, t, name=name, unit=unit))
    tmp = path.with_name(f".{path.stem}.tmp.mf4")
    with quiet():
        mdf = MDF(version=MDF_VERSION)
        try:
            mdf.header.comment = comment
            mdf.append(signals, comment="parknss trial")
            written = mdf.save(tmp, overwrite=True)
        finally:
            mdf.close()
    os.replace(written, path)
    return path
