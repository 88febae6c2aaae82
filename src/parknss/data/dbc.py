"""DBC files: lenient loading with warnings, and a vectorised signal decoder.

Real DBCs are often not strictly valid: community files lack the ``BS_:``/``BU_:``
sections (cantools' parser then fails), OEM files define overlapping signals
(cantools' strict mode refuses them). :func:`load_dbc` loads them leniently by default
and reports what it tolerated as warning lines (issued once per load with
:func:`warnings.warn` and returned for provenance); ``strict=True`` refuses any problem
with a one-line :class:`~parknss.errors.DataError` naming the DBC file.

:func:`decode_signal` decodes one signal of many frames at once from an (N, W) uint8
payload array, bit for bit as cantools' ``Message.decode`` does (Intel and Motorola
bit numbering, signed and IEEE float signals, scale and offset, value tables as
labels, multiplexing), with frames too short for the signal masked out and counted.
:func:`encode_signal` is its inverse (used by :mod:`parknss.data.canwrite`).
"""

from __future__ import annotations

import contextlib
import difflib
import logging
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from parknss.errors import DataError, one_line

DBC_SUFFIXES: tuple[str, ...] = (".dbc",)  # text fixed up before parsing; other formats as is


class DbcWarning(UserWarning):
    """Something in a DBC was tolerated (lenient load); the message is one line."""



# ----------------------------------------------------------------------------- loading


@dataclass(frozen=True)
class LoadedDbc:
    """A CAN database and what was tolerated while loading it.

    Attributes:
        db: the cantools ``Database``.
        path: the DBC file.
        warnings: one line per tolerated problem (empty for a clean file).
        strict: whether it was loaded in strict mode.
    """

    db: Any
    path: Path
    warnings: tuple[str, ...] = ()
    strict: bool = False

    def message(self, name: str) -> Any:
        """The message called ``name``; KeyError if there is none."""
        return self.db.get_message_by_name(name)

    def message_names(self) -> list[str]:
        return [m.name for m in self.db.messages]


def close_matches(name: str, candidates: list[str], n: int = 3) -> list[str]:
    """Up to ``n`` names like ``name`` (difflib, then case-insensitive substring)."""
    found = difflib.get_close_matches(name, candidates, n=n, cutoff=0.6)
    if len(found) < n:
        low = name.casefold()
        found += [c for c in candidates if low in c.casefold() and c not in found]
    return found[:n]


def similar_hint(name: str, candidates: list[str]) -> str:
    """'; similar: A, B' or '' (for error messages)."""
    found = close_matches(name, candidates)
    return f"; similar: {', '.join(found)}" if found else ""


_SECTION = re.compile(r"^[ \t]*(BS_|BU_)[ \t]*:", re.MULTILINE)
_NS_LINE = re.compile(r"^[ \t]*NS_[ \t]*:", re.MULTILINE)


def _fix_sections(text: str) -> tuple[str, list[str]]:
    """Add empty ``BS_:``/``BU_:`` sections where a DBC lacks them.

    cantools reads the ``NS_`` symbol list up to the first ``word :``; without a
    ``BS_:`` line right after it, the first message is swallowed and parsing fails.
    Returns the text to parse and the warning lines.
    """
    present = set(_SECTION.findall(text))
    missing = [s for s in ("BS_", "BU_") if s not in present]
    if not missing:
        return text, []
    insert = "".join(f"{s}:\n" for s in missing)
    ns = _NS_LINE.search(text)
    if ns is None:  # no symbol list: the sections can go anywhere; put them first
        pos = 0
        version = re.search(r"^[ \t]*VERSION[ \t]+\"[^\"\n]*\"[ \t]*$", text, re.MULTILINE)
        if version is not None:
            pos = version.end() + 1
    else:  # after the NS_ block: its indented, blank or keyword-only lines
        pos = len(text)
        for m in re.finditer(r"^.*$", text[ns.end() :], re.MULTILINE):
            line = m.group(0)
            if m.start() == 0 or not line.strip() or line[:1].isspace():
                continue
            if re.fullmatch(r"[ \t]*[A-Z_]+[ \t]*", line) is None:
                pos = ns.end() + m.start()
                break
    names = "/".join(f"{s}:" for s in missing)
    what = "sections (empty ones assumed)" if len(missing) > 1 else "section (empty one assumed)"
    return text[:pos] + insert + text[pos:], [f"no {names} {what}"]


def _bit_mask(signal: Any) -> int:
    """The signal's bits as an int, bit 8*k+j = bit j (LSB 0) of payload byte k."""
    if signal.byte_order == "little_endian":
        return ((1 << signal.length) - 1) << signal.start
    ns = _network_msb(signal)
    out = 0
    for n in range(ns, ns + signal.length):
        out |= 1 << (8 * (n // 8) + 7 - n % 8)
    return out


def _mux_path(message: Any, signal: Any) -> dict[str, frozenset[int]]:
    """{multiplexer signal: mux values} along the chain of multiplexers above ``signal``."""
    out: dict[str, frozenset[int]] = {}
    s = signal
    while s is not None and s.multiplexer_ids and s.multiplexer_signal:
        out[s.multiplexer_signal] = frozenset(s.multiplexer_ids)
        try:
            s = message.get_signal_by_name(s.multiplexer_signal)
        except KeyError:
            break
    return out


def _exclusive(a: dict[str, frozenset[int]], b: dict[str, frozenset[int]]) -> bool:
    """Never in the same frame: different values of a common multiplexer."""
    return any(name in b and not (ids & b[name]) for name, ids in a.items())


def lint_message(message: Any) -> list[str]:
    """Signals that do not fit in the message or overlap another one (one line each)."""
    out = []
    masks = [(s, _bit_mask(s), _mux_path(message, s)) for s in message.signals]
    for s, _, _ in masks:
        need = bytes_needed(s)
        if need > message.length:
            out.append(
                f"message {message.name!r}: signal {s.name!r} does not fit (needs {need} "
                f"bytes, the message has {message.length})"
            )
    for i, (a, ma, pa) in enumerate(masks):
        for b, mb, pb in masks[i + 1 :]:
            if ma & mb and not _exclusive(pa, pb):
                out.append(f"message {message.name!r}: signals {a.name!r} and {b.name!r} overlap")
    return out


@contextlib.contextmanager
def _captured_log(lines: list[str]) -> Iterator[None]:
    """cantools' own logger warnings (duplicate names, ids) into ``lines``."""

    class _Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            lines.append(" ".join(record.getMessage().split()))

    log = logging.getLogger("cantools")
    handler, propagate = _Keep(logging.WARNING), log.propagate
    log.addHandler(handler)
    log.propagate = False
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.propagate = propagate


def _parse(path: Path, strict: bool) -> tuple[Any, list[str]]:
    """(cantools Database, warning lines); exceptions of cantools pass through."""
    import cantools

    notes: list[str] = []
    with _captured_log(notes):
        if path.suffix.lower() in DBC_SUFFIXES:
            text = path.read_bytes().decode("cp1252", errors="replace")
            fixed, missing = _fix_sections(text)
            notes[:0] = missing
            db = cantools.database.load_string(
                text if strict else fixed, database_format="dbc", strict=strict
            )
        else:
            db = cantools.database.load_file(path, strict=strict)
    if not hasattr(db, "get_message_by_name"):
        raise TypeError("not a CAN database")
    for message in db.messages:
        notes += lint_message(message)
    return db, notes


@lru_cache(maxsize=16)
def _load_cached(path: Path, stamp: tuple[int, int], strict: bool) -> LoadedDbc:
    del stamp  # part of the cache key only: a changed file is loaded again
    try:
        db, notes = _parse(path, strict)
    except Exception as exc:  # cantools raises many types for bad files
        if strict:
            raise DataError(
                f"DBC file {path}: refused in strict mode ({one_line(exc)}); set "
                "can.strict_dbc: false to load it leniently"
            ) from exc
        raise DataError(f"DBC file {path}: not readable ({one_line(exc)})") from exc
    if strict and notes:
        more = f" (and {len(notes) - 1} more)" if len(notes) > 1 else ""
        raise DataError(
            f"DBC file {path}: refused in strict mode ({notes[0]}{more}); set "
            "can.strict_dbc: false to load it leniently"
        )
    for line in notes:
        warnings.warn(f"DBC file {path}: {line}", DbcWarning, stacklevel=4)
    return LoadedDbc(db, path, tuple(notes), strict)


def load_dbc(path: str | Path, strict: bool = False) -> LoadedDbc:
    """Load a DBC (or any database cantools reads) and report what was tolerated.

    Lenient (default): a .dbc without ``BS_:``/``BU_:`` sections gets empty ones,
    overlapping signals and signals that do not fit their message are kept; each such
    problem is one line of ``LoadedDbc.warnings`` and is issued once with
    ``warnings.warn`` (category :class:`DbcWarning`). ``strict=True``: cantools' strict
    mode, and any such problem is a DataError. The result is cached per file (path,
    size, modification time), so warnings are issued on the first load only.

    Raises:
        DataError: one line naming the DBC file: missing, unreadable, or (strict)
            not strictly valid.
    """
    p = Path(path)
    if not p.is_file():
        raise DataError(f"DBC file {p} not found")
    st = p.stat()
    return _load_cached(p, (st.st_size, st.st_mtime_ns), bool(strict))


# ------------------------------------------------------------------------ bit layout


def _network_msb(signal: Any) -> int:
    """Motorola: network bit index (byte 0 bit 7 = 0) of the signal's MSB."""
    return 8 * (signal.start // 8) + 7 - signal.start % 8


def _byte_shifts(signal: Any) -> list[tuple[int, int]]:
    """(payload byte index, shift) pairs: raw = OR of byte << shift (>> -shift if < 0)."""
    if signal.byte_order == "little_endian":
        first, last = signal.start // 8, (signal.start + signal.length - 1) // 8
        return [(b, 8 * b - signal.start) for b in range(first, last + 1)]
    ns = _network_msb(signal)
    ne = ns + signal.length - 1  # network index of the LSB
    return [(b, ne - 8 * b - 7) for b in range(ns // 8, ne // 8 + 1)]


def bytes_needed(signal: Any) -> int:
    """How many payload bytes a frame needs to carry the signal."""
    return _byte_shifts(signal)[-1][0] + 1


def _mask(length: int) -> np.uint64:
    return np.uint64((1 << length) - 1)


def raw_values(signal: Any, data: np.ndarray) -> np.ndarray:
    """The signal's raw bits of every frame, as unsigned integers, shape (N,) uint64.

    ``data`` is (N, W) uint8 with W >= bytes_needed(signal); bits are taken as cantools
    does (Intel: start = LSB in little-endian bit numbering; Motorola: start = MSB in
    the DBC's sawtooth numbering).
    """
    out = np.zeros(len(data), dtype=np.uint64)
    if not len(data):
        return out
    for b, shift in _byte_shifts(signal):
        col = data[:, b].astype(np.uint64)
        if shift >= 0:
            out |= col << np.uint64(shift)
        else:
            out |= col >> np.uint64(-shift)
    if signal.length < 64:
        out &= _mask(signal.length)
    return out


def _as_number(signal: Any, raw: np.ndarray) -> np.ndarray:
    """Raw bits -> the raw number: signed two's complement or IEEE float, float64 (N,)."""
    if signal.is_float:
        if signal.length == 32:
            with np.errstate(invalid="ignore"):  # signalling NaNs become quiet ones
                return raw.astype(np.uint32).view(np.float32).astype(np.float64)
        if signal.length == 64:
            return raw.view(np.float64).copy()
        raise DataError(f"signal {signal.name!r}: a float signal must have 32 or 64 bits")
    if signal.is_signed:
        if signal.length == 64:
            return raw.view(np.int64).astype(np.float64)
        sign = np.uint64(1 << (signal.length - 1))
        return ((raw ^ sign).astype(np.int64) - np.int64(int(sign))).astype(np.float64)
    return raw.astype(np.float64)


def _integer_valued(signal: Any) -> bool:
    """Does cantools give an int (not a float) for this signal's unlabelled values?"""
    conv = signal.conversion
    inner = getattr(conv, "_conversion", conv)  # NamedSignalConversion wraps another
    return not conv.is_float and type(inner).__name__ in (
        "IdentityConversion",
        "LinearIntegerConversion",
    )


def physical(signal: Any, number: np.ndarray) -> np.ndarray:
    """Raw numbers -> physical values: ``raw * scale + offset`` (float64, as cantools)."""
    conv = signal.conversion
    scale, offset = conv.scale, conv.offset
    if scale == 1 and offset == 0:
        return number
    return number * float(scale) + float(offset)


def _labels(signal: Any, number: np.ndarray, phys: np.ndarray) -> np.ndarray:
    """Value-table labels where the DBC has one, else the value as cantools prints it."""
    choices = signal.choices or {}
    uniq, first, inverse = np.unique(number, return_index=True, return_inverse=True)
    integer = _integer_valued(signal)
    text = []
    for u, i in zip(uniq.tolist(), first.tolist(), strict=True):
        label = choices.get(int(u)) if np.isfinite(u) else None
        if label is not None:
            text.append(str(label))
            continue
        p = float(phys[i])  # cantools: int for integer conversions, else float
        text.append(str(int(p)) if integer and np.isfinite(p) else str(p))
    table = np.empty(len(text), dtype=object)
    table[:] = text
    return table[inverse.reshape(-1)]


def _mux_numbers(signal: Any, number: np.ndarray) -> np.ndarray:
    """The multiplexer value cantools compares with SG_ mux ids (int64, (N,)).

    cantools uses ``int(decoded value)``: the raw value when it has a label, else the
    scaled value truncated toward zero.
    """
    phys = physical(signal, number)
    out = np.trunc(np.where(np.isfinite(phys), phys, 0.0)).astype(np.int64)
    if signal.choices:
        labelled = np.isin(number, [float(k) for k in signal.choices])
        out = np.where(labelled, number.astype(np.int64), out)
    return out


# -------------------------------------------------------------------------- decoding


@dataclass(frozen=True)
class DecodedSignal:
    """One signal decoded from N frames.

    Attributes:
        values: (N,) float64 physical values in the DBC unit (NaN where masked), or an
            object array of str (value-table labels; numbers as text where the table has
            no label; None where masked) when the signal has a value table.
        mask: (N,) bool, True where the frame carries the signal (long enough, and the
            multiplexer selects it).
        n_short: frames too short for the signal (or for its multiplexer).
        n_other_mux: frames long enough whose multiplexer selects other signals.
    """

    values: np.ndarray
    mask: np.ndarray
    n_short: int = 0
    n_other_mux: int = 0
    labels: bool = False


def _lengths(data: np.ndarray, lengths: np.ndarray | None) -> np.ndarray:
    if lengths is None:
        return np.full(len(data), data.shape[1], dtype=np.int64)
    return np.minimum(np.asarray(lengths, dtype=np.int64), data.shape[1])


def _long_enough(signal: Any, data: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    need = bytes_needed(signal)
    if need > data.shape[1]:
        return np.zeros(len(data), dtype=bool)
    return lengths >= need


def _present(
    message: Any, signal: Any, data: np.ndarray, lengths: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(long enough for the signal and its multiplexers, selected by the multiplexers)."""
    ok = _long_enough(signal, data, lengths)
    selected = np.ones(len(data), dtype=bool)
    if not signal.multiplexer_ids or not signal.multiplexer_signal:
        return ok, selected
    mux = message.get_signal_by_name(signal.multiplexer_signal)
    mux_ok, mux_sel = _present(message, mux, data, lengths)
    ok &= mux_ok
    rows = np.flatnonzero(ok)
    number = _as_number(mux, raw_values(mux, data[rows]))
    selected[rows] = np.isin(_mux_numbers(mux, number), list(signal.multiplexer_ids))
    return ok, selected & mux_sel


def decode_signal(
    message: Any,
    signal: Any,
    data: np.ndarray,
    lengths: np.ndarray | None = None,
    decode_choices: bool = True,
) -> DecodedSignal:
    """Decode one signal of N frames of ``message``, vectorised.

    Args:
        message: the cantools Message (needed for multiplexers).
        signal: one of its cantools Signals.
        data: (N, W) uint8 payloads, zero-padded beyond each frame's length.
        lengths: (N,) payload lengths in bytes; None: all W. A frame shorter than the
            bytes the signal needs is masked out and counted (not an error), as
            cantools' ``decode(..., allow_truncated=True)`` does.
        decode_choices: give value-table labels (object array of str) when the signal
            has a value table; False: numbers.

    Returns:
        DecodedSignal: values (N,), mask (N,), counts of short and other-mux frames.
    """
    data = np.ascontiguousarray(data, dtype=np.uint8)
    if data.ndim != 2:
        raise ValueError(f"data must be (N, W) uint8, got shape {data.shape}")
    n = len(data)
    lens = _lengths(data, lengths)
    ok, selected = _present(message, signal, data, lens)
    mask = ok & selected
    rows = np.flatnonzero(mask)
    number = _as_number(signal, raw_values(signal, data[rows]))
    phys = physical(signal, number)
    if decode_choices and signal.choices:
        values = np.full(n, None, dtype=object)
        values[rows] = _labels(signal, number, phys)
        labels = True
    else:
        values = np.full(n, np.nan)
        values[rows] = phys
        labels = False
    return DecodedSignal(
        values=values,
        mask=mask,
        n_short=int(n - ok.sum()),
        n_other_mux=int((ok & ~selected).sum()),
        labels=labels,
    )


# -------------------------------------------------------------------------- encoding


def raw_range(signal: Any) -> tuple[int, int]:
    """The smallest and largest raw integer the signal's bits hold."""
    if signal.is_signed:
        return -(1 << (signal.length - 1)), (1 << (signal.length - 1)) - 1
    return 0, (1 << signal.length) - 1


def to_raw_numbers(signal: Any, values: np.ndarray) -> np.ndarray:
    """Physical values (numbers, or value-table labels as str) -> raw numbers, float64.

    The inverse of the scaling: ``(value - offset) / scale`` rounded half to even as
    cantools does (not rounded for float signals), clipped to what the bits hold.
    Labels go through the value table; an unknown label is a ValueError.
    """
    v = np.asarray(values)
    conv = signal.conversion
    if v.dtype.kind in "OUS":
        inverse = {str(name): int(raw) for raw, name in (signal.choices or {}).items()}
        uniq, inv = np.unique(v.astype(str), return_inverse=True)
        table = np.empty(len(uniq), dtype=np.float64)
        for k, key in enumerate(uniq.tolist()):
            if key in inverse:
                table[k] = inverse[key]
                continue
            try:
                table[k] = to_raw_numbers(signal, np.array([float(key)]))[0]
            except ValueError:
                raise ValueError(
                    f"signal {signal.name!r}: {key!r} is not in its value table"
                ) from None
        return table[inv.reshape(-1)]
    v = v.astype(np.float64)
    raw = v if conv.scale == 1 and conv.offset == 0 else (v - conv.offset) / conv.scale
    if signal.is_float:
        return raw
    lo, hi = raw_range(signal)
    return np.clip(np.rint(raw), lo, hi)


def encode_signal(signal: Any, raw_numbers: np.ndarray, out: np.ndarray) -> None:
    """OR the signal's raw numbers (N,) into the payloads ``out`` (N, W) uint8, in place."""
    number = np.asarray(raw_numbers, dtype=np.float64)
    if signal.is_float:
        if signal.length == 32:
            bits = number.astype(np.float32).view(np.uint32).astype(np.uint64)
        else:
            bits = number.view(np.uint64)
    elif signal.is_signed:
        bits = number.astype(np.int64).view(np.uint64)
    else:
        bits = number.astype(np.uint64)
    mask = int(_mask(signal.length)) if signal.length < 64 else (1 << 64) - 1
    bits = bits & np.uint64(mask)
    for b, shift in _byte_shifts(signal):
        if shift >= 0:
            part = bits >> np.uint64(shift)
            keep = (mask >> shift) & 0xFF
        else:
            part = bits << np.uint64(-shift)
            keep = (mask << -shift) & 0xFF
        out[:, b] |= (part & np.uint64(keep)).astype(np.uint8)


def clear_dbc_cache() -> None:
    """Forget loaded DBCs (the next :func:`load_dbc` parses and warns again)."""
    _load_cached.cache_clear()
