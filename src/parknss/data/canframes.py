"""Raw CAN frames from bus logs, as one columnar :class:`FrameTable` per file.

Readers (all keep file order, drop error and remote frames, and keep only the frames
whose ``(id, extended)`` is in ``wanted`` so that an hour of log at 2000 frames/s does
not pile up in memory):

* ``.blf`` (Vector binary logging) and ``.asc`` (Vector ASCII): python-can's readers,
  with the truncation checks python-can leaves out.
* ``.trc`` (PCAN-View, versions 1.0, 1.1, 1.3, 2.0 and 2.1): python-can's reader.
* candump ``.log`` (``(1700000000.123456) can0 123#DEADBEEF``): a vectorised reader.
* SavvyCAN "GVRET" ``.csv`` (``Time Stamp,ID,Extended,[Dir,]Bus,LEN,D1,...``, time
  stamps in microseconds, hex ids and bytes): a vectorised reader; recognised by its
  header line (:func:`is_gvret_csv`).
* MDF4 bus logging (``.mf4``, ``.mdf`` with a ``CAN_DataFrame`` channel group, as the
  CANedge and Vector loggers write them; :func:`is_bus_logging_mdf`): asammdf, read in
  chunks of records.

Bus numbers are python-can's: from 0. BLF, ASC and MDF number buses from 1 in the
file (CAN1 is bus 0); GVRET's bus column is taken as is; candump interfaces ``can0``,
``vcan1``... are numbered by their trailing digits (in order of appearance if those
are missing or not distinct). Every malformed input is a one-line
:class:`~parknss.errors.DataError` naming the file and the line or frame.
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from parknss.data.mdf import open_mdf, quiet
from parknss.errors import DataError, one_line

ASC_TAIL_BYTES = 4096  # how much of an .asc file's end is read to find its closing line
TEXT_CHUNK_BYTES = 1 << 24  # text logs are parsed in pieces of about this size
MDF_CHUNK_RECORDS = 1 << 20  # MDF bus-logging records read per asammdf call
FLUSH_FRAMES = 1 << 16  # python-can frames gathered in lists before going to arrays
MDF_SUFFIXES: tuple[str, ...] = (".mf4", ".mdf")
KINDS: dict[str, str] = {
    "blf": ".blf log",
    "asc": ".asc log",
    "candump": "candump .log",
    "gvret": "GVRET .csv log",
    "mdf": "MDF4 bus logging file",
    "trc": "PCAN .trc log",
}
TRC_VERSIONS = ("1.0", "1.1", "1.3", "2.0", "2.1")  # the PCAN-View versions python-can reads
TRC_HEADER_LINES = 200  # how far into a .trc the ;$FILEVERSION line is looked for
CAN_ERR_FLAG = 0x20000000  # candump: error frame
EXT_BIT = 1 << 31  # (id, extended) packed as id | EXT_BIT for lookups
DLC_TO_LEN = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64], dtype=np.uint8)

Wanted = Iterable[tuple[int, bool]] | None



# ------------------------------------------------------------------------ the table


@dataclass(frozen=True)
class FrameTable:
    """CAN data frames of one log, in file order (columns of N frames).

    Attributes:
        t: (N,) float64 time stamps, s, on the logger's clock (absolute for BLF,
            candump; from the start of the measurement for ASC, MDF; GVRET's µs / 1e6).
        id: (N,) uint32 arbitration ids (11 or 29 bits).
        extended: (N,) bool, 29-bit id.
        bus: (N,) int16 bus number, python-can's numbering from 0 (see the module doc).
        dlc: (N,) uint8 payload length in bytes, 0..64 (for CAN FD the length, not the
            4-bit DLC code).
        data: (N, W) uint8 payloads, zero beyond each frame's length; W = 8 when every
            frame has at most 8 bytes, else 64.
        t_first: time stamp of the log's first frame of any kind (any id, any bus,
            error frames too), s, same clock as ``t``; NaN for an empty log.
        n_frames: data frames in the file (every id, before the ``wanted`` filter).
        n_skipped: error and remote frames dropped.
        kind: the reader: one of KINDS.
    """

    t: np.ndarray
    id: np.ndarray
    extended: np.ndarray
    bus: np.ndarray
    dlc: np.ndarray
    data: np.ndarray
    t_first: float = float("nan")
    n_frames: int = 0
    n_skipped: int = 0
    kind: str = ""

    def __len__(self) -> int:
        return len(self.t)

    def take(self, rows: np.ndarray) -> FrameTable:
        """The frames at ``rows`` (indices or a bool mask), in that order."""
        return replace(
            self,
            t=self.t[rows],
            id=self.id[rows],
            extended=self.extended[rows],
            bus=self.bus[rows],
            dlc=self.dlc[rows],
            data=self.data[rows],
        )

    def keys(self) -> np.ndarray:
        """(N,) int64 ``id | 2**31`` for extended ids: one number per (id, extended)."""
        return self.id.astype(np.int64) | (self.extended.astype(np.int64) << 31)


def frame_key(frame_id: int, extended: bool) -> int:
    """The number FrameTable.keys() gives frames of (frame_id, extended)."""
    return int(frame_id) | (EXT_BIT if extended else 0)


def _wanted_keys(wanted: Wanted) -> np.ndarray | None:
    if wanted is None:
        return None
    return np.array(sorted({frame_key(i, e) for i, e in wanted}), dtype=np.int64)


class _Collector:
    """Kept frames gathered chunk by chunk, then one FrameTable."""

    def __init__(self, kind: str, wanted: Wanted) -> None:
        self.kind = kind
        self.keys = _wanted_keys(wanted)
        self.parts: list[tuple[np.ndarray, ...]] = []
        self.t_first = float("nan")
        self.n_frames = 0
        self.n_skipped = 0

    def first(self, t: float) -> None:
        if np.isnan(self.t_first):
            self.t_first = float(t)

    def add(
        self,
        t: np.ndarray,
        ids: np.ndarray,
        ext: np.ndarray,
        bus: np.ndarray,
        dlc: np.ndarray,
        data: np.ndarray,
        filtered: bool = False,
    ) -> None:
        """A chunk of data frames: counted and filtered (unless the caller did), kept."""
        if not filtered:
            self.n_frames += len(t)
            if self.keys is not None:
                k = ids.astype(np.int64) | (ext.astype(np.int64) << 31)
                keep = np.isin(k, self.keys)
                if not keep.all():
                    t, ids, ext, bus, dlc, data = (a[keep] for a in (t, ids, ext, bus, dlc, data))
        if len(t) and data.shape[1] > 8 and int(dlc.max()) <= 8:
            data = data[:, :8]  # classic frames kept from a chunk with CAN FD ones
        if len(t):
            self.parts.append(
                (
                    np.asarray(t, dtype=np.float64),
                    np.asarray(ids, dtype=np.uint32),
                    np.asarray(ext, dtype=bool),
                    np.asarray(bus, dtype=np.int16),
                    np.asarray(dlc, dtype=np.uint8),
                    np.ascontiguousarray(data, dtype=np.uint8),
                )
            )

    def table(self) -> FrameTable:
        longest = max([0, *(int(p[4].max()) for p in self.parts)])
        width = 8 if longest <= 8 else 64  # by the frames kept, not the chunks read
        cols: list[np.ndarray] = []
        for k, dtype in enumerate((np.float64, np.uint32, bool, np.int16, np.uint8)):
            cols.append(
                np.concatenate([p[k] for p in self.parts])
                if self.parts
                else np.zeros(0, dtype=dtype)
            )
        data = np.zeros((len(cols[0]), width), dtype=np.uint8)
        row = 0
        for p in self.parts:
            d = p[5][:, :width]
            data[row : row + len(d), : d.shape[1]] = d
            row += len(d)
        self.parts = []
        return FrameTable(*cols, data, self.t_first, self.n_frames, self.n_skipped, self.kind)


# ------------------------------------------------------------------ python-can readers


def _bus_number(channel: Any) -> int:
    if isinstance(channel, int):
        return channel
    if isinstance(channel, str) and channel.strip().lstrip("-").isdigit():
        return int(channel)
    return 0


def _drain(reader: Iterable[Any], out: _Collector) -> None:
    """python-can messages -> the collector (counted one by one, kept FLUSH_FRAMES at a
    time), so that an error can say after which frame it came."""
    std: set[int] | None = None
    ext: set[int] | None = None
    if out.keys is not None:
        std = {int(k) for k in out.keys if not k & EXT_BIT}
        ext = {int(k) & ~EXT_BIT for k in out.keys if k & EXT_BIT}
    cols: tuple[list, ...] = ([], [], [], [], [], [])

    def flush() -> None:
        t, i, e, b, n, d = cols
        width = 8 if not n or max(n) <= 8 else 64
        buf = b"".join(x.ljust(width, b"\0") for x in d)
        data = np.frombuffer(buf, dtype=np.uint8).reshape(len(d), width)
        arrays = (np.array(t), np.array(i), np.array(e), np.array(b), np.array(n))
        out.add(*arrays, data, filtered=True)
        for c in cols:
            c.clear()

    for msg in reader:
        out.first(msg.timestamp)
        if msg.is_error_frame or msg.is_remote_frame:
            out.n_skipped += 1
            continue
        out.n_frames += 1
        if std is not None and msg.arbitration_id not in (ext if msg.is_extended_id else std):
            continue
        data = bytes(msg.data)
        cols[0].append(msg.timestamp)
        cols[1].append(msg.arbitration_id)
        cols[2].append(msg.is_extended_id)
        cols[3].append(_bus_number(msg.channel))
        cols[4].append(len(data))
        cols[5].append(data)
        if len(cols[0]) >= FLUSH_FRAMES:
            flush()
    flush()


def read_blf(path: Path, wanted: Wanted = None) -> FrameTable:
    """A Vector .blf log through python-can's BLFReader (truncation checked)."""
    import can

    out = _Collector("blf", wanted)
    reader = None
    try:
        reader = can.BLFReader(str(path))
        size = path.stat().st_size
        if reader.file_size > size:
            raise DataError(
                f"{path}: truncated .blf log (header says {reader.file_size} bytes, the file "
                f"has {size})"
            )
        _drain(reader, out)
    except DataError:
        raise
    except Exception as exc:  # python-can raises struct.error, BLFParseError, zlib.error...
        n = out.n_frames + out.n_skipped
        where = f"after frame {n}: " if n else ""
        raise DataError(
            f"{path}: not a readable .blf log, corrupt or truncated ({where}{one_line(exc)})"
        ) from exc
    finally:
        if reader is not None:
            with contextlib.suppress(Exception):
                reader.stop()
    return out.table()


def _check_asc_end(path: Path) -> None:
    """An .asc log closes with 'End TriggerBlock'; without it the file was cut off."""
    with open(path, "rb") as f:
        f.seek(max(0, path.stat().st_size - ASC_TAIL_BYTES))
        tail = f.read().decode("latin-1")
    lines = [ln.strip() for ln in tail.splitlines() if ln.strip()]
    if not lines or not lines[-1].lower().startswith("end triggerblock"):
        raise DataError(f"{path}: truncated .asc log (no closing 'End TriggerBlock' line)")


class _CountingLines:
    """A text file whose lines are counted as python-can's ASCReader reads them."""

    def __init__(self, f: io.TextIOBase) -> None:
        self.f = f
        self.n = 0

    def __iter__(self) -> _CountingLines:
        return self

    def __next__(self) -> str:
        line = next(self.f)
        self.n += 1
        return line

    def close(self) -> None:
        self.f.close()


def read_asc(path: Path, wanted: Wanted = None) -> FrameTable:
    """A Vector .asc log through python-can's ASCReader (closing line checked)."""
    import can

    _check_asc_end(path)
    out = _Collector("asc", wanted)
    lines = _CountingLines(open(path, encoding="latin-1"))  # noqa: SIM115 (closed below)
    try:
        _drain(can.ASCReader(lines), out)
    except Exception as exc:  # python-can raises ValueError, IndexError... on bad lines
        raise DataError(
            f"{path}: not a readable .asc log, corrupt or truncated (line {lines.n}, after "
            f"frame {out.n_frames + out.n_skipped}: {one_line(exc)})"
        ) from exc
    finally:
        lines.close()
    return out.table()


def _trc_version(path: Path) -> str:
    """The ;$FILEVERSION of a .trc (1.0 when it has none); DataError for one python-can
    does not read."""
    with open(path, encoding="latin-1") as f:
        for _, line in zip(range(TRC_HEADER_LINES), f, strict=False):
            text = line.strip()
            if text.upper().startswith(";$FILEVERSION"):
                version = text.split("=", 1)[-1].strip()
                if version not in TRC_VERSIONS:
                    raise DataError(
                        f"{path}: .trc file version {version!r} is not one parknss reads "
                        f"({', '.join(TRC_VERSIONS)}); save the trace as version 2.1 in "
                        "PCAN-View"
                    )
                return version
            if text and not text.startswith(";"):
                break
    return "1.0"


def read_trc(path: Path, wanted: Wanted = None) -> FrameTable:
    """A PCAN-View .trc log (versions 1.0, 1.1, 1.3, 2.0, 2.1) through python-can's
    TRCReader; the file's bus n (from 1) is bus n - 1. Time stamps are the file's start
    time plus each frame's offset (version 1.0: the offset alone)."""
    import can

    _trc_version(path)
    out = _Collector("trc", wanted)
    lines = _CountingLines(open(path, encoding="latin-1"))  # noqa: SIM115 (closed below)

    def messages() -> Iterator[Any]:
        for msg in can.TRCReader(lines):
            if isinstance(msg.channel, int):
                msg.channel = max(msg.channel - 1, 0)
            yield msg

    try:
        _drain(messages(), out)
    except Exception as exc:  # python-can raises ValueError, KeyError... on bad lines
        raise DataError(
            f"{path}: not a readable .trc log, corrupt or truncated (line {lines.n}, after "
            f"frame {out.n_frames + out.n_skipped}: {one_line(exc)})"
        ) from exc
    finally:
        lines.close()
    return out.table()


# ------------------------------------------------------------- vectorised text parsing

_HEX = np.full(256, 255, dtype=np.uint8)
_HEX[np.frombuffer(b"0123456789", np.uint8)] = np.arange(10)
_HEX[np.frombuffer(b"abcdef", np.uint8)] = np.arange(10, 16)
_HEX[np.frombuffer(b"ABCDEF", np.uint8)] = np.arange(10, 16)
_DEC = np.full(256, 255, dtype=np.uint8)
_DEC[np.frombuffer(b"0123456789", np.uint8)] = np.arange(10)
_BIG = 1 << 62  # "no such position" (stays positive when offsets are added)


def _text_chunks(path: Path, chunk_bytes: int = TEXT_CHUNK_BYTES) -> Iterator[tuple[bytes, int]]:
    """(whole lines, number of the first of them), each piece ending with a newline."""
    with open(path, "rb") as f:
        tail, line_no = b"", 1
        while True:
            block = f.read(chunk_bytes)
            if not block:
                if tail:
                    yield tail + b"\n", line_no
                return
            block = tail + block
            cut = block.rfind(b"\n")
            if cut < 0:
                tail = block
                continue
            piece, tail = block[: cut + 1], block[cut + 1 :]
            yield piece, line_no
            line_no += piece.count(b"\n")


class _Text:
    """One piece of a text log: its bytes, non-blank lines and their numbers."""

    def __init__(self, piece: bytes, first_line: int) -> None:
        self.buf = np.frombuffer(piece, dtype=np.uint8)
        nl = np.flatnonzero(self.buf == 10).astype(np.int64)
        starts = np.concatenate(([0], nl[:-1] + 1)).astype(np.int64)
        ends = nl
        while True:  # trailing CR, blanks, tabs
            trim = (ends > starts) & np.isin(self.buf[np.maximum(ends - 1, 0)], (13, 32, 9))
            if not trim.any():
                break
            ends = ends - trim
        used = ends > starts
        self.starts, self.ends = starts[used], ends[used]
        self.lineno = (first_line + np.arange(len(starts)))[used]
        self.problem: tuple[int, int, str] | None = None  # (line number, row, reason)

    def __len__(self) -> int:
        return len(self.starts)

    def positions(self, char: str) -> np.ndarray:
        return np.flatnonzero(self.buf == ord(char)).astype(np.int64)

    def check(self, bad: np.ndarray, reason: str) -> None:
        """Remember the earliest line where ``bad`` holds (one reason per line)."""
        rows = np.flatnonzero(bad)
        if len(rows) and (self.problem is None or self.lineno[rows[0]] < self.problem[0]):
            self.problem = (int(self.lineno[rows[0]]), int(rows[0]), reason)

    def raise_problem(self, path: Path, what: str) -> None:
        if self.problem is None:
            return
        line, row, reason = self.problem
        s, e = self.starts[row], self.ends[row]
        text = bytes(self.buf[s : min(e, s + 80)]).decode("latin-1")
        raise DataError(f"{path}: line {line}: {reason} ({what} line {text!r})")


def _next(pos: np.ndarray, after: np.ndarray) -> np.ndarray:
    """For each value of ``after``, the first of the sorted ``pos`` >= it (_BIG if none)."""
    if not len(pos):
        return np.full(len(after), _BIG, dtype=np.int64)
    k = np.searchsorted(pos, after)
    return np.where(k < len(pos), pos[np.minimum(k, len(pos) - 1)], _BIG)


def _parse_uint(
    buf: np.ndarray, start: np.ndarray, end: np.ndarray, table: np.ndarray, max_width: int
) -> tuple[np.ndarray, np.ndarray]:
    """Unsigned integers written in [start, end): (uint64 (N,), ok (N,)).

    ``table`` maps a character to its digit (255: not a digit); base 16 for _HEX, 10
    for _DEC. Empty or wider than ``max_width`` is not ok.
    """
    base = 16 if table is _HEX else 10
    width = end - start
    ok = (width >= 1) & (width <= max_width)
    acc = np.zeros(len(start), dtype=np.uint64)
    top = int(width[ok].max()) if ok.any() else 0
    for j in range(top):
        inside = ok & (j < width)
        d = table[buf[np.where(inside, start + j, 0)]]
        ok &= ~inside | (d < base)
        acc = np.where(inside & ok, acc * np.uint64(base) + d.astype(np.uint64), acc)
    return acc, ok


def _gather(buf: np.ndarray, start: np.ndarray, end: np.ndarray, width: int) -> np.ndarray:
    """(N, width) uint8: the bytes of [start, end) left-aligned, zero-padded."""
    j = np.arange(width)
    inside = j[None, :] < (end - start)[:, None]
    return np.where(inside, buf[np.where(inside, start[:, None] + j[None, :], 0)], 0).astype(
        np.uint8
    )


def _hex_bytes(buf: np.ndarray, start: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """n[i] bytes written as 2n[i] hex digits from start[i] on (``DEADBEEF``).

    Returns ((N, W) uint8 with W = 8 or 64, ok (N,)).
    """
    top = int(n.max()) if len(n) else 0
    out = np.zeros((len(start), 8 if top <= 8 else 64), dtype=np.uint8)
    ok = np.ones(len(start), dtype=bool)
    for j in range(min(top, 64)):
        inside = j < n
        p = np.where(inside, start + 2 * j, 0)
        hi, lo = _HEX[buf[p]], _HEX[buf[np.where(inside, p + 1, 0)]]
        good = (hi < 16) & (lo < 16)
        ok &= ~inside | good
        out[:, j] = np.where(inside & good, (hi << 4) | lo, 0)
    return out, ok


def _fields(text: _Text, sep: str) -> tuple[np.ndarray, Any]:
    """(fields per line, field(j) -> (start, end) of the j-th field of every line)."""
    cuts = text.positions(sep)
    k0 = np.searchsorted(cuts, text.starts)
    nf = np.searchsorted(cuts, text.ends) - k0 + 1
    last = max(len(cuts) - 1, 0)
    cuts = cuts if len(cuts) else np.zeros(1, dtype=np.int64)

    def field(j: int | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        j = np.asarray(j)
        s = np.where(j == 0, text.starts, cuts[np.clip(k0 + j - 1, 0, last)] + 1)
        e = np.where(j < nf - 1, cuts[np.clip(k0 + j, 0, last)], text.ends)
        inside = j < nf
        return np.where(inside, s, text.ends), np.where(inside, e, text.ends)

    return nf, field


# ----------------------------------------------------------------------- GVRET .csv

GVRET_COLUMNS = ("time stamp", "id", "extended", "bus", "len")


def _header_fields(line: bytes) -> list[str]:
    text = line.decode("utf-8-sig", errors="replace").strip()
    return [f.strip().casefold() for f in text.split(",")]


def is_gvret_csv(path: str | Path) -> bool:
    """Is this a SavvyCAN GVRET CSV (header ``Time Stamp,ID,Extended,[Dir,]Bus,LEN,D1...``)?"""
    try:
        with open(path, "rb") as f:
            first = f.readline(4096)
    except OSError:
        return False
    names = _header_fields(first)
    return names[:3] == ["time stamp", "id", "extended"] and {"bus", "len", "d1"} <= set(names)


def _gvret_layout(path: Path, header: bytes) -> tuple[dict[str, int], int]:
    """({column: field index}, number of fields before D1)."""
    names = _header_fields(header)
    cols = {n: i for i, n in enumerate(names)}
    missing = [c for c in GVRET_COLUMNS if c not in cols]
    fixed = cols.get("len", -2) + 1
    if (
        names[:3] != ["time stamp", "id", "extended"]
        or missing
        or names[fixed : fixed + 1] != ["d1"]
    ):
        got = header[:80].decode("latin-1").strip()
        raise DataError(
            f"{path}: line 1: not a GVRET header (expected 'Time Stamp,ID,Extended,Bus,LEN,"
            f"D1,...', got {got!r})"
        )
    return cols, fixed


def _gvret_chunk(
    text: _Text, path: Path, cols: dict[str, int], fixed: int, out: _Collector
) -> None:
    buf = text.buf
    nf, field = _fields(text, ",")
    text.check(nf < fixed, f"fewer than {fixed} fields")
    stamp, ok = _parse_uint(buf, *field(cols["time stamp"]), _DEC, 19)
    text.check(~ok, "time stamp is not an integer number of µs")
    ids, ok = _parse_uint(buf, *field(cols["id"]), _HEX, 8)
    text.check(~ok | (ids > 0x1FFFFFFF), "ID is not a hex CAN id")
    s, e = field(cols["extended"])
    c, w = buf[np.minimum(s, len(buf) - 1)] | 0x20, e - s  # first character, lower case
    ext = ((c == ord("t")) & (w == 4)) | ((c == ord("1")) & (w == 1))
    std = ((c == ord("f")) & (w == 5)) | ((c == ord("0")) & (w == 1))
    text.check(~(ext | std), "Extended is not true or false")
    bus, ok = _parse_uint(buf, *field(cols["bus"]), _DEC, 4)
    text.check(~ok | (bus > 32767), "Bus is not a bus number")
    n, ok = _parse_uint(buf, *field(cols["len"]), _DEC, 2)
    text.check(~ok | (n > 64), "LEN is not a length of 0..64 bytes")
    n = np.where(ok & (n <= 64), n, 0).astype(np.int64)
    given = nf - fixed
    trailing_comma = (given == n + 1) & (field(nf - 1)[0] == text.ends)
    text.check((given != n) & ~trailing_comma, "LEN differs from the number of data bytes")
    top = int(n.max()) if len(n) else 0
    data = np.zeros((len(text), 8 if top <= 8 else 64), dtype=np.uint8)
    hex_ok = np.ones(len(text), dtype=bool)
    for j in range(top):
        inside = j < n
        byte, ok = _parse_uint(buf, *field(fixed + j), _HEX, 2)
        hex_ok &= ~inside | ok
        data[:, j] = np.where(inside & ok, byte, 0)
    text.check(~hex_ok, "a data byte is not a hex byte")
    text.raise_problem(path, "GVRET")
    out.first(float(stamp[0]) * 1e-6)
    out.add(stamp * 1e-6, ids, ext, bus, n, data)


def read_gvret_csv(path: Path, wanted: Wanted = None) -> FrameTable:
    """A SavvyCAN GVRET CSV: time stamps µs -> s, hex ids and bytes, LEN bytes per row."""
    out = _Collector("gvret", wanted)
    chunks = _text_chunks(path)
    first = next(chunks, None)
    if first is None:
        raise DataError(f"{path}: line 1: empty file (expected a GVRET header line)")
    piece, _ = first
    cut = piece.find(b"\n")
    cols, fixed = _gvret_layout(path, piece[:cut])
    rest = [(piece[cut + 1 :], 2)] if cut + 1 < len(piece) else []
    for body, line in (*rest, *chunks):
        text = _Text(body, line)
        if len(text):
            _gvret_chunk(text, path, cols, fixed, out)
    return out.table()


# --------------------------------------------------------------------- candump .log


class _Interfaces:
    """candump interface names -> bus numbers (trailing digits, else first appearance)."""

    def __init__(self) -> None:
        self.names: dict[bytes, int] = {}

    def codes(self, rows: np.ndarray) -> np.ndarray:
        """(N, W) uint8 names (zero-padded) -> (N,) int16 codes in order of appearance."""
        if not len(rows):
            return np.zeros(0, dtype=np.int16)
        flat = np.ascontiguousarray(rows).view(f"S{rows.shape[1]}").ravel()
        uniq, first, inverse = np.unique(flat, return_index=True, return_inverse=True)
        for k in np.argsort(first):
            self.names.setdefault(bytes(uniq[k]), len(self.names))
        return np.array([self.names[bytes(u)] for u in uniq], dtype=np.int16)[inverse.ravel()]

    def bus_numbers(self) -> np.ndarray:
        """code -> bus number."""
        digits = []
        for name in self.names:
            text = name.decode("latin-1")
            tail = len(text) - len(text.rstrip("0123456789"))
            digits.append(int(text[-tail:]) if tail else None)
        if (
            None not in digits
            and len(set(digits)) == len(digits)
            and max(digits, default=0) < 32768
        ):
            return np.array(digits, dtype=np.int16)
        return np.arange(len(self.names), dtype=np.int16)


def _candump_chunk(text: _Text, path: Path, ifaces: _Interfaces, out: _Collector) -> None:
    buf, starts, ends = text.buf, text.starts, text.ends
    text.check(buf[starts] != ord("("), "no '(time stamp)' at the start")
    close = _next(text.positions(")"), starts)
    text.check(close >= ends, "no ')' after the time stamp")
    close = np.minimum(close, ends)
    dot = _next(text.positions("."), starts)
    has_dot = dot < close
    sec, ok = _parse_uint(buf, starts + 1, np.where(has_dot, dot, close), _DEC, 12)
    frac_end = np.where(has_dot, close, dot)
    frac, ok2 = _parse_uint(buf, dot + 1, frac_end, _DEC, 9)
    ok2 |= ~has_dot | (frac_end == dot + 1)
    text.check(~ok | ~ok2, "time stamp is not a number of seconds")
    t = sec.astype(np.float64) + np.where(
        has_dot & ok2, frac.astype(np.float64) / 10.0 ** np.maximum(frac_end - dot - 1, 0), 0.0
    )
    spaces = text.positions(" ")
    sp1 = np.minimum(close + 1, ends)
    text.check(buf[sp1] != ord(" "), "no space after the time stamp")
    sp2 = _next(spaces, sp1 + 1)
    text.check(sp2 >= ends, "no frame after the interface name")
    sp2 = np.minimum(sp2, ends)
    sp3 = _next(spaces, sp2 + 1)
    frame_end = np.minimum(sp3, ends)
    extra = sp3 < ends  # optional direction flag ' R' / ' T'
    flag = buf[np.minimum(sp3 + 1, len(buf) - 1)] | 0x20
    text.check(
        extra & ((ends - sp3 != 2) | ~np.isin(flag, (ord("r"), ord("t")))),
        "unexpected text after the frame",
    )
    hash_ = _next(text.positions("#"), sp2)
    text.check(hash_ >= frame_end, "no '#' in the frame")
    hash_ = np.minimum(hash_, frame_end)
    ids, ok = _parse_uint(buf, sp2 + 1, hash_, _HEX, 8)
    text.check(~ok, "CAN id is not hex")
    ext = (hash_ - sp2 - 1) > 3
    after = buf[np.minimum(hash_ + 1, len(buf) - 1)]
    body = hash_ + 1 < frame_end
    fd = body & (after == ord("#"))
    remote = body & ((after | 0x20) == ord("r"))
    error = (ids & CAN_ERR_FLAG) != 0
    ds = np.where(fd, hash_ + 3, hash_ + 1)
    nchar = np.maximum(frame_end - ds, 0)
    usable = ~remote & ~error
    text.check(
        usable & fd & (_HEX[buf[np.minimum(hash_ + 2, len(buf) - 1)]] > 15),
        "CAN FD flags are not a hex digit",
    )
    text.check(usable & ((nchar % 2 == 1) | (nchar > 128)), "data is not whole hex bytes")
    n = np.where(usable, np.minimum(nchar // 2, 64), 0)
    data, ok = _hex_bytes(buf, ds, n)
    text.check(usable & ~ok, "data is not hex")
    text.raise_problem(path, "candump")
    iface_w = int((sp2 - sp1 - 1).max())
    names = np.zeros((len(text), max(iface_w, 1)), dtype=np.uint8)
    names[:, :iface_w] = _gather(buf, sp1 + 1, sp2, iface_w)
    codes = ifaces.codes(names)
    out.first(float(t[0]))
    out.n_skipped += int((~usable).sum())
    keep = np.flatnonzero(usable)
    out.add(t[keep], (ids & 0x1FFFFFFF)[keep], ext[keep], codes[keep], n[keep], data[keep])


def read_candump(path: Path, wanted: Wanted = None) -> FrameTable:
    """A can-utils candump log (``candump -L``): ``(s.us) iface id#data`` per line."""
    out = _Collector("candump", wanted)
    ifaces = _Interfaces()
    for piece, line in _text_chunks(path):
        text = _Text(piece, line)
        if len(text):
            _candump_chunk(text, path, ifaces, out)
    table = out.table()
    if len(table):
        table = replace(table, bus=ifaces.bus_numbers()[table.bus])
    return table


# ---------------------------------------------------------------- MDF4 bus logging


def _open_mdf(path: Path) -> Any:
    """The MDF without asammdf's own bus-logging pass (it reads every frame id)."""
    return open_mdf(path, process_bus_logging=False)


def _can_groups(mdf: Any) -> list[tuple[int, str]]:
    """(group index, acquisition kind) of the CAN bus-event channel groups."""
    from asammdf.blocks import v4_constants as v4c

    out = []
    for i, g in enumerate(getattr(mdf, "groups", [])):
        cg = g.channel_group
        src = getattr(cg, "acq_source", None)
        if not getattr(cg, "flags", 0) & v4c.FLAG_CG_BUS_EVENT:
            continue
        if src is not None and getattr(src, "bus_type", v4c.BUS_TYPE_CAN) != v4c.BUS_TYPE_CAN:
            continue
        names = {ch.name for ch in g.channels}
        kind = next(
            (k for k in ("CAN_DataFrame", "CAN_ErrorFrame", "CAN_RemoteFrame") if k in names), None
        )
        if kind is not None:
            out.append((i, kind))
    return out


def is_bus_logging_mdf(path: str | Path) -> bool:
    """Is this an MDF4 file with a CAN bus-logging group (``CAN_DataFrame``)?"""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            head = f.read(16)
    except OSError:
        return False
    if not head.startswith(b"MDF     4"):
        return False
    try:
        mdf = _open_mdf(p)
    except DataError:
        return False
    try:
        return any(kind == "CAN_DataFrame" for _, kind in _can_groups(mdf))
    finally:
        with quiet(), contextlib.suppress(Exception):
            mdf.close()


def _mdf_column(mdf: Any, g: int, index: dict[str, int], name: str, off: int, count: int):
    j = index.get(f"CAN_DataFrame.{name}")
    if j is None:
        return None
    sig = mdf.get(group=g, index=j, record_offset=off, record_count=count, raw=True)
    return np.asarray(sig.samples)


def _mdf_group(mdf: Any, g: int, out: _Collector, path: Path) -> None:
    """One CAN_DataFrame group, MDF_CHUNK_RECORDS records at a time."""
    group = mdf.groups[g]
    index = {ch.name: j for j, ch in enumerate(group.channels)}
    if "CAN_DataFrame.ID" not in index or "CAN_DataFrame.DataBytes" not in index:
        raise DataError(f"{path}: group {g}: CAN_DataFrame without ID or DataBytes channels")
    total = int(group.channel_group.cycles_nr)
    for off in range(0, total, MDF_CHUNK_RECORDS):
        count = min(MDF_CHUNK_RECORDS, total - off)
        t = np.asarray(mdf.get_master(g, record_offset=off, record_count=count), dtype=np.float64)
        raw_id = _mdf_column(mdf, g, index, "ID", off, count).astype(np.uint32)
        ide = _mdf_column(mdf, g, index, "IDE", off, count)
        ext = (raw_id >> 31).astype(bool) if ide is None else ide.astype(bool)
        bus = _mdf_column(mdf, g, index, "BusChannel", off, count)
        bus = np.zeros(count, np.int16) if bus is None else bus.astype(np.int16) - 1
        n = _mdf_column(mdf, g, index, "DataLength", off, count)
        if n is None:
            dlc = _mdf_column(mdf, g, index, "DLC", off, count)
            n = DLC_TO_LEN[np.minimum(dlc.astype(np.int64), 15)] if dlc is not None else None
        data = _mdf_column(mdf, g, index, "DataBytes", off, count)
        if data.ndim != 2 or data.dtype != np.uint8:  # variable-length byte strings
            data = _pad_bytes(list(data))
        if n is None:
            n = np.full(count, data.shape[1])
        n = np.minimum(np.asarray(n, dtype=np.int64), data.shape[1])
        data = np.where(np.arange(data.shape[1])[None, :] < n[:, None], data, 0)
        if len(t) != len(raw_id) or len(data) != len(raw_id):
            raise DataError(f"{path}: group {g}: CAN_DataFrame channels of different lengths")
        out.add(t, raw_id & 0x1FFFFFFF, ext, bus, n, data)


def _pad_bytes(items: list[Any]) -> np.ndarray:
    width = 8 if max((len(bytes(x)) for x in items), default=0) <= 8 else 64
    buf = b"".join(bytes(x)[:width].ljust(width, b"\0") for x in items)
    return np.frombuffer(buf, dtype=np.uint8).reshape(len(items), width)


def read_mdf_bus_logging(path: Path, wanted: Wanted = None) -> FrameTable:
    """The CAN_DataFrame groups of an MDF4 bus-logging file (BusChannel n -> bus n-1).

    Several CAN_DataFrame groups are merged in time order (stable); the error and
    remote frame groups count for the log's first time stamp only.
    """
    mdf = _open_mdf(path)
    try:
        groups = _can_groups(mdf)
        data_groups = [g for g, kind in groups if kind == "CAN_DataFrame"]
        if not data_groups:
            raise DataError(f"{path}: no CAN_DataFrame channel group (not an MDF bus logging file)")
        out = _Collector("mdf", wanted)
        with quiet():
            firsts = [
                float(mdf.get_master(g, record_offset=0, record_count=1)[0])
                for g, _ in groups
                if mdf.groups[g].channel_group.cycles_nr
            ]
            out.t_first = min(firsts) if firsts else float("nan")
            out.n_skipped = sum(
                int(mdf.groups[g].channel_group.cycles_nr)
                for g, k in groups
                if k != "CAN_DataFrame"
            )
            for g in data_groups:
                _mdf_group(mdf, g, out, path)
    except DataError:
        raise
    except Exception as exc:  # asammdf on a damaged file
        raise DataError(
            f"{path}: not a readable MDF bus logging file, corrupt or truncated ({one_line(exc)})"
        ) from exc
    finally:
        with quiet(), contextlib.suppress(Exception):
            mdf.close()
    table = out.table()
    if len(data_groups) > 1 and len(table):
        table = table.take(np.argsort(table.t, kind="stable"))
    return table


# ------------------------------------------------------------------------ dispatch

READERS = {
    "blf": read_blf,
    "asc": read_asc,
    "candump": read_candump,
    "gvret": read_gvret_csv,
    "mdf": read_mdf_bus_logging,
    "trc": read_trc,
}


SUFFIX_KINDS = {
    ".blf": "blf",
    ".asc": "asc",
    ".log": "candump",
    ".csv": "gvret",
    ".mf4": "mdf",
    ".mdf": "mdf",
    ".trc": "trc",
}


def log_kind(path: str | Path) -> str | None:
    """Which frame reader reads this file (a key of KINDS), or None for no bus log.

    By suffix (.blf, .asc, .log), and by content for .csv (a GVRET header) and
    .mf4/.mdf (a CAN bus-logging group); a table CSV or a signal MDF gives None.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in (".blf", ".asc", ".log", ".trc"):
        return SUFFIX_KINDS[suffix]
    if suffix == ".csv":
        return "gvret" if is_gvret_csv(p) else None
    if suffix in MDF_SUFFIXES:
        return "mdf" if is_bus_logging_mdf(p) else None
    return None


def read_frames(path: str | Path, wanted: Wanted = None, kind: str | None = None) -> FrameTable:
    """The data frames of one bus log, in file order, only those ``wanted``.

    Args:
        path: a .blf, .asc, candump .log, GVRET .csv or MDF4 bus-logging file.
        wanted: (frame id, extended) pairs to keep; None keeps every frame.
        kind: the reader (a key of KINDS); None: :func:`log_kind`.

    Raises:
        DataError: one line naming the file and what is wrong (and where).
    """
    p = Path(path)
    # by content first; else by suffix, so that a damaged file gets its reader's error
    kind = kind or log_kind(p) or SUFFIX_KINDS.get(p.suffix.lower())
    if kind not in READERS:
        raise DataError(
            f"{p}: not a CAN bus log parknss reads (.blf, .asc, .trc, candump .log, GVRET "
            ".csv, MDF4 bus logging)"
        )
    if not p.is_file():
        raise DataError(f"{p}: file not found")
    try:
        table = READERS[kind](p, wanted)
    except DataError:
        raise
    except Exception as exc:  # a reader bug or an input nobody foresaw: still one line
        raise DataError(f"{p}: not a readable {KINDS[kind]} ({one_line(exc)})") from exc
    if table.n_frames == 0:
        raise DataError(f"{p}: no CAN frames in the log")
    return table


# ------------------------------------------------------------------ buses, duplicates


@dataclass(frozen=True)
class BusChoice:
    """A message seen on several buses and the one kept.

    Attributes:
        key: frame_key(id, extended).
        counts: {bus: frames of the message on it}.
        kept: the bus kept (most frames, ties to the lowest number).
        dropped: frames of the other buses dropped.
    """

    key: int
    counts: dict[int, int]
    kept: int
    dropped: int


def keep_bus(frames: FrameTable, bus: int) -> FrameTable:
    """Only the frames of one bus."""
    return frames.take(np.flatnonzero(frames.bus == bus))


def buses_by_key(frames: FrameTable) -> dict[int, dict[int, int]]:
    """{frame key: {bus: number of frames}}."""
    keys = frames.keys()
    combo = keys * 65536 + (frames.bus.astype(np.int64) + 32768)
    uniq, counts = np.unique(combo, return_counts=True)
    out: dict[int, dict[int, int]] = {}
    for c, n in zip(uniq.tolist(), counts.tolist(), strict=True):
        out.setdefault(c // 65536, {})[c % 65536 - 32768] = n
    return out


def drop_duplicate_buses(frames: FrameTable) -> tuple[FrameTable, list[BusChoice]]:
    """Per message (id, extended), keep the frames of one bus only.

    The bus with most frames of that message is kept, ties to the lowest bus number;
    returns the frames kept (file order) and one BusChoice per message seen on several
    buses.
    """
    choices = []
    for key, counts in buses_by_key(frames).items():
        if len(counts) < 2:
            continue
        kept = min(counts, key=lambda b: (-counts[b], b))
        choices.append(BusChoice(key, counts, kept, sum(counts.values()) - counts[kept]))
    if not choices:
        return frames, []
    keys = frames.keys()
    drop = np.zeros(len(frames), dtype=bool)
    for c in choices:
        drop |= (keys == c.key) & (frames.bus != c.kept)
    return frames.take(np.flatnonzero(~drop)), choices
