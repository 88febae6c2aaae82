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

from parknss.errors import DataError, ParknssWarning, one_line

DBC_SUFFIXES: tuple[str, ...] = (".dbc",)  # text fixed up before parsing; other formats as is


class DbcWarning(ParknssWarning):
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


def _fix_sections(text: str) -> tuple[str, list[str], int, int]:
    """Add empty ``BS_:``/``BU_:`` sections where a DBC lacks them.

    cantools reads the ``NS_`` symbol list up to the first ``word :``; without a
    ``BS_:`` line right after it, the first message is swallowed and parsing fails.
    Returns the text to parse, the warning lines, the index of the first inserted line
    and how many lines were inserted.
    """
    present = set(_SECTION.findall(text))
    missing = [s for s in ("BS_", "BU_") if s not in present]
    if not missing:
        return text, [], text.count("\n") + 1, 0
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
    at = text[:pos].count("\n")
    return text[:pos] + insert + text[pos:], [f"no {names} {what}"], at, len(missing)


# ------------------------------------------------------------------ lenient repairs

# Statements of a DBC that end with ';' (the others: VERSION, NS_, BS_, BU_, BO_, SG_).
_SEMI_KEYWORDS = (
    "CM_", "VAL_", "VAL_TABLE_", "BA_DEF_", "BA_DEF_DEF_", "BA_", "SIG_VALTYPE_",
    "SG_MUL_VAL_", "BO_TX_BU_", "EV_", "ENVVAR_DATA_", "SIG_GROUP_", "BA_DEF_REL_",
    "BA_REL_", "BA_DEF_DEF_REL_", "SIG_TYPE_REF_", "SGTYPE_", "SGTYPE_VAL_", "CAT_DEF_",
    "CAT_", "FILTER", "BA_DEF_SGTYPE_", "BA_SGTYPE_", "SIG_TYPE_DEF_",
)
_ALL_KEYWORDS = ("VERSION", "NS_", "BS_", "BU_", "BO_", "SG_", *_SEMI_KEYWORDS)
_KEYWORD_LINE = re.compile(r"^[ \t]*(" + "|".join(sorted(_ALL_KEYWORDS, key=len, reverse=True))
                           + r")(?=[\s:]|$)")
_IMPORT = re.compile(r'^[ \t]*CM_[ \t]+"IMPORT[ \t]+([^"]+?)[ \t]*"[ \t]*;?[ \t]*$')
_CM_STRING = re.compile(
    r'^(\s*CM_\s+(?:(?:BU_|EV_)\s+\S+\s+|BO_\s+\d+\s+|SG_\s+\d+\s+\S+\s+)?)"(.*)"(\s*;\s*)$',
    re.DOTALL,
)
_UNESCAPED_QUOTE = re.compile(r'(?<!\\)"')
_BO_LINE = re.compile(r"^[ \t]*BO_[ \t]+(\d+)[ \t]+(\w+)")
_SG_LINE = re.compile(r"^[ \t]*SG_[ \t]+(\w+)")
_VAL_LINE = re.compile(r"^[ \t]*VAL_[ \t]+(\d+)[ \t]+(\w+)")
_ID_REFS = (  # statements that name a message by its id (rewritten with the id)
    re.compile(r"^([ \t]*(?:VAL_|SG_MUL_VAL_|SIG_VALTYPE_|BO_TX_BU_|BO_)[ \t]+)(\d+)\b"),
    re.compile(r"^([ \t]*CM_[ \t]+(?:BO_|SG_)[ \t]+)(\d+)\b"),
    re.compile(r'^([ \t]*BA_[ \t]+"[^"]*"[ \t]+(?:BO_|SG_)[ \t]+)(\d+)\b'),
)
EXTENDED_FLAG = 0x80000000  # DBC: bit 31 of a BO_ id marks an extended (29-bit) frame id


@dataclass
class _Text:
    """A DBC's lines with, for each, the file and line number it comes from."""

    lines: list[str]
    origin: list[tuple[Path, int] | None]

    def where(self, i: int, main: Path) -> str:
        """'line N' (of the main file) or 'line N of other.dbc' for line index i."""
        o = self.origin[i] if 0 <= i < len(self.origin) else None
        if o is None:
            return "an inserted line"
        path, n = o
        return f"line {n}" if path == main else f"line {n} of {path.name}"


def _expand_imports(path: Path, stack: tuple[Path, ...] = ()) -> _Text:
    """The DBC's lines with every ``CM_ "IMPORT file.dbc";`` replaced by that file's
    lines (relative to the importing file's folder, recursively; a cycle or a missing
    file is a DataError naming the line)."""
    real = path.resolve()
    text = path.read_bytes().decode("cp1252", errors="replace")
    out = _Text([], [])
    for n, line in enumerate(text.split("\n"), start=1):
        m = _IMPORT.match(line.rstrip("\r"))
        if m is None:
            out.lines.append(line)
            out.origin.append((path, n))
            continue
        target = path.parent / m.group(1)
        chain = (*stack, real)
        if target.resolve() in chain:
            names = " -> ".join(p.name for p in (*chain, target.resolve()))
            raise DataError(f"DBC file {path}: line {n}: IMPORT cycle ({names}); remove one")
        if not target.is_file():
            raise DataError(
                f"DBC file {path}: line {n}: imported file {m.group(1)!r} not found in "
                f"{path.parent}"
            )
        sub = _expand_imports(target, chain)
        out.lines += sub.lines
        out.origin += sub.origin
    return out


def _drop_repeated_headers(t: _Text) -> None:
    """After imports, keep only the first VERSION, NS_ block, BS_ and BU_ (later ones
    blanked, line numbers kept); BU_ node names of later ones are merged into the first."""
    seen: dict[str, int] = {}
    in_ns = False
    for i, line in enumerate(t.lines):
        m = _KEYWORD_LINE.match(line)
        if in_ns:
            if not line.strip() or line[:1].isspace():
                t.lines[i] = ""
                continue
            in_ns = False
        if m is None or m.group(1) not in ("VERSION", "NS_", "BS_", "BU_"):
            continue
        kw = m.group(1)
        if kw not in seen:
            seen[kw] = i
            continue
        if kw == "BU_":
            nodes = line.split(":", 1)[1].split() if ":" in line else []
            first = seen["BU_"]
            have = t.lines[first].split(":", 1)[1].split() if ":" in t.lines[first] else []
            add = [x for x in nodes if x not in have]
            if add:
                t.lines[first] = t.lines[first].rstrip("\r") + " " + " ".join(add)
        t.lines[i] = ""
        in_ns = kw == "NS_"


def _statements(t: _Text) -> Iterator[tuple[str, int, int]]:
    """(keyword, first line index, end index) of every ';'-terminated statement: from its
    keyword to its ';' or to the line before the next keyword line."""
    n = len(t.lines)
    i = 0
    while i < n:
        m = _KEYWORD_LINE.match(t.lines[i])
        if m is None or m.group(1) not in _SEMI_KEYWORDS or not t.lines[i][m.end():].strip():
            i += 1
            continue
        j = i
        while True:
            if t.lines[j].rstrip().endswith(";"):
                j += 1
                break
            j += 1
            if j >= n or _KEYWORD_LINE.match(t.lines[j]):
                break
        yield m.group(1), i, j
        i = j


def _repair_statements(t: _Text, main: Path, notes: list[str]) -> None:
    """A missing closing ';' added; unescaped quotes inside a CM_ comment escaped."""
    for kw, i, j in list(_statements(t)):
        last = max((k for k in range(i, j) if t.lines[k].strip()), default=i)
        if not t.lines[last].rstrip().endswith(";"):
            t.lines[last] = t.lines[last].rstrip() + " ;"
            notes.append(f"{t.where(last, main)}: {kw} statement has no closing ';' (added)")
        if kw != "CM_":
            continue
        body = "\n".join(t.lines[i:j])
        m = _CM_STRING.match(body)
        if m is None or not _UNESCAPED_QUOTE.search(m.group(2)):
            continue
        fixed = m.group(1) + '"' + _UNESCAPED_QUOTE.sub(r"\\\"", m.group(2)) + '"' + m.group(3)
        t.lines[i:j] = fixed.split("\n")
        notes.append(f"{t.where(i, main)}: CM_ comment has unescaped quotes (read as text)")


def _repair_references(t: _Text, main: Path, notes: list[str]) -> None:
    """Standard ids beyond 11 bits read as extended ids; VAL_ tables of signals that do
    not exist dropped (each one warning line)."""
    signals: dict[int, set[str]] = {}
    current: int | None = None
    promote: dict[int, int] = {}
    for i, line in enumerate(t.lines):
        bo = _BO_LINE.match(line)
        if bo is not None:
            current = int(bo.group(1))
            signals.setdefault(current, set())
            if 0x7FF < current < EXTENDED_FLAG:
                promote[current] = current | EXTENDED_FLAG
                notes.append(
                    f"{t.where(i, main)}: message {bo.group(2)!r}: standard frame id "
                    f"0x{current:X} is more than 11 bits (read as an extended id)"
                )
            continue
        sg = _SG_LINE.match(line)
        if sg is not None and current is not None:
            signals[current].add(sg.group(1))
    for kw, i, j in list(_statements(t)):
        if kw != "VAL_":
            continue
        m = _VAL_LINE.match(t.lines[i])
        if m is None:
            continue
        mid, sig = int(m.group(1)), m.group(2)
        if mid in signals and sig in signals[mid]:
            continue
        what = f"message id {mid} has no signal {sig!r}" if mid in signals else (
            f"no message has id {mid}")
        notes.append(f"{t.where(i, main)}: VAL_ table for {sig!r} unused ({what}; ignored)")
        for k in range(i, j):
            t.lines[k] = ""
    if promote:
        for i, line in enumerate(t.lines):
            for rx in _ID_REFS:
                m = rx.match(line)
                if m is not None and int(m.group(2)) in promote:
                    new = str(promote[int(m.group(2))])
                    t.lines[i] = m.group(1) + new + line[m.end():]
                    break


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


class _UnreadableError(Exception):
    """cantools refused the text; the message names the line of the file it came from."""


_AT_LINE = re.compile(r"at line (\d+)(?:, column \d+)?")


def _cantools_error(exc: Exception, t: _Text, main: Path, at: int, added: int) -> _UnreadableError:
    """cantools' error with its line number turned into the file's own line."""

    def back(m: re.Match) -> str:
        i = int(m.group(1)) - 1  # index in the text parsed
        if i >= at:
            i -= added  # the inserted BS_:/BU_: lines
        return "at " + t.where(i, main)

    text = " ".join(str(exc).split()).replace(">>!<<", "")
    text = re.sub(r'^DBC: "(.*)"$', r"\1", text)
    return _UnreadableError(_AT_LINE.sub(back, text))


def _parse(path: Path, strict: bool) -> tuple[Any, list[str]]:
    """(cantools Database, warning lines); exceptions of cantools pass through.

    A .dbc is read as text first: ``CM_ "IMPORT file.dbc";`` lines are replaced by that
    file (relative to the importing file's folder; repeated headers dropped); leniently,
    a missing closing ';', unescaped quotes in a CM_ comment, a VAL_ table of a signal
    that does not exist and a standard id beyond 11 bits (read as extended) are repaired,
    each one warning line with the file's own line number.
    """
    import cantools

    notes: list[str] = []
    with _captured_log(notes):
        if path.suffix.lower() in DBC_SUFFIXES:
            t = _expand_imports(path)
            if len({o[0] for o in t.origin if o is not None}) > 1:
                _drop_repeated_headers(t)
            if not strict:
                _repair_statements(t, path, notes)
                _repair_references(t, path, notes)
            text = "\n".join(t.lines)
            fixed, missing, at, added = _fix_sections(text)
            notes[:0] = missing
            if strict:
                fixed, at, added = text, len(t.lines), 0
            try:
                db = cantools.database.load_string(fixed, database_format="dbc", strict=strict)
            except Exception as exc:  # cantools raises many types for bad files
                raise _cantools_error(exc, t, path, at, added) from exc
            where = {}
            for i, line in enumerate(t.lines):
                bo = _BO_LINE.match(line)
                if bo is not None:
                    where.setdefault(bo.group(2), t.where(i, path))
        else:
            db = cantools.database.load_file(path, strict=strict)
            where = {}
    if not hasattr(db, "get_message_by_name"):
        raise TypeError("not a CAN database")
    for message in db.messages:
        at_line = f"{where[message.name]}: " if message.name in where else ""
        notes += [at_line + line for line in lint_message(message)]
    return db, notes


@lru_cache(maxsize=16)
def _load_cached(path: Path, stamp: tuple[int, int], strict: bool) -> LoadedDbc:
    del stamp  # part of the cache key only: a changed file is loaded again
    try:
        db, notes = _parse(path, strict)
    except DataError:
        raise
    except Exception as exc:  # cantools raises many types for bad files
        why = str(exc) if isinstance(exc, _UnreadableError) else one_line(exc)
        if strict:
            raise DataError(
                f"DBC file {path}: refused in strict mode ({why}); set "
                "can.strict_dbc: false to load it leniently"
            ) from exc
        raise DataError(f"DBC file {path}: not readable ({why})") from exc
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
    return _load_cached(p, _stamp(p), bool(strict))


def _stamp(path: Path, seen: frozenset[Path] = frozenset()) -> tuple:
    """(size, mtime) of the file and of every file it IMPORTs (the cache key)."""
    st = path.stat()
    out: tuple = ((str(path), st.st_size, st.st_mtime_ns),)
    if path.suffix.lower() not in DBC_SUFFIXES or path.resolve() in seen:
        return out
    text = path.read_bytes().decode("cp1252", errors="replace")
    for line in text.split("\n"):
        m = _IMPORT.match(line.rstrip("\r"))
        target = path.parent / m.group(1) if m is not None else None
        if target is not None and target.is_file():
            out += _stamp(target, seen | {path.resolve()})
    return out


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
